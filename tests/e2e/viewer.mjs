// End-to-end test of the viewer in a real headless browser: load the page, wait for the controller to
// spin the ellipse, drag the ellipse against its spin with the mouse, release, and wait for the spin to
// resume. Usage: node viewer.mjs URL SCREENSHOT.png. Prints one JSON line with what it measured; exits
// non-zero if a check fails.
import { run } from "./common.mjs";

const [url, screenshot] = process.argv.slice(2);

await run(url, async ({ page, frame, waitFor, fail, result }) => {
  await page.click("input[name=policy][value=mpc]");
  const spinning = await waitFor((f) => f.policy === "mpc" && f.spin_rate > 0.2, 40, "the controller spins the ellipse");
  result.spin_before = spinning.spin_rate;

  // Grab the ellipse off its hinge and pull that point clockwise, against the spin. The grabbed point
  // lies inside the circle of the ellipse's minor semi-axis, so it is still on the ellipse however far
  // the ellipse turns between this frame and the mouse press (a loaded machine once let it turn off a
  // point near the end of the long axis, and the press grabbed nothing).
  const theta = spinning.x[2];
  const centre = spinning.bodies[2].centre;
  const minor = Math.min(...(await page.evaluate(() => shapes[2].semi_axes)));
  const lever = 0.8 * minor;
  const grab = [centre[0] + lever * Math.cos(theta), centre[1] + lever * Math.sin(theta)];
  const target = [grab[0] + 1.2 * Math.sin(theta), grab[1] - 1.2 * Math.cos(theta)];
  const [gx, gy] = await page.evaluate((p) => window.viewerToClient(p), grab);
  const [tx, ty] = await page.evaluate((p) => window.viewerToClient(p), target);
  await page.mouse.move(gx, gy);
  await page.mouse.down();
  await page.mouse.move(tx, ty, { steps: 8 });
  // Waits are in simulated seconds, which a loaded machine stretches unevenly against the mouse's real
  // ones: the press and the release get a few seconds each to reach the server.
  const held = await waitFor((f) => f.spring !== null && f.spring.body === 2, 5, "the server holds the ellipse on a spring");
  result.perturbations = held.perturbations;
  const holdStart = held;
  const heldEnd = await waitFor((f) => f.t >= holdStart.t + 3, 10, "three seconds of holding");
  result.spin_while_held = heldEnd.spin_rate;
  result.turned_while_held = heldEnd.x[2] - holdStart.x[2];
  if (!(result.turned_while_held < 0.5)) {
    fail(`the drag did not hold the ellipse back (turned ${result.turned_while_held} rad in 3 s)`);
  }
  await page.screenshot({ path: screenshot.replace(/\.png$/, "-dragging.png") });
  await page.mouse.up();
  const released = await waitFor((f) => f.spring === null, 5, "the release reaches the server");
  // The spin resumes: a further quarter turn forward and a positive 2 s spin rate.
  const resumed = await waitFor(
    (f) => f.x[2] > released.x[2] + Math.PI / 2 && f.spin_rate > 0.1,
    40,
    "the spin resumes after the release",
  );
  result.resume_seconds = resumed.t - released.t;
  result.spin_after = resumed.spin_rate;
  await page.screenshot({ path: screenshot });
});

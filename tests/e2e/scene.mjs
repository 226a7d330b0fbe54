// End-to-end test of the viewer on a scene other than the finger (the pushing scene: a free block on a
// ground half-plane) in a real headless browser: the page draws the ground and the block where the
// server says they are, and a mouse drag lifts the block (a free body) off the ground. Usage: node
// scene.mjs URL SCREENSHOT.png. Prints one JSON line with what it measured; exits non-zero if a check
// fails.
import { run } from "./common.mjs";

const [url, screenshot] = process.argv.slice(2);

await run(url, async ({ page, frame, waitFor, fail, result }) => {
  // The colour the canvas shows at a world point (after the next animation frame).
  const colourAt = (p) =>
    page.evaluate((p) => {
      const [x, y] = toScreen(p);
      return Array.from(ctx.getImageData(Math.round(x), Math.round(y), 1, 1).data.slice(0, 3));
    }, p);
  await page.waitForTimeout(200);
  result.planes = await page.evaluate(() => planes.length);
  result.watched = await page.evaluate(() => watched.name);
  result.ground = await colourAt([-1.0, -0.2]);
  result.sky = await colourAt([-1.0, 2.5]);
  if (result.planes !== 1) {
    fail(`the page knows ${result.planes} half-planes, not the ground alone`);
  }
  if (result.ground.join() !== "200,200,200") {
    fail(`under the ground the canvas is ${result.ground}, not the ground's grey`);
  }
  if (result.sky.join() === "200,200,200") {
    fail("the ground's grey is drawn above the ground too");
  }
  // Grab the block at its centre and pull it up: the block (body 2 of 3; the scene has 5 coordinates)
  // leaves the ground.
  const start = await frame();
  const centre = start.bodies[2].centre;
  const [gx, gy] = await page.evaluate((p) => window.viewerToClient(p), centre);
  const [tx, ty] = await page.evaluate((p) => window.viewerToClient(p), [centre[0], centre[1] + 1.5]);
  await page.mouse.move(gx, gy);
  await page.mouse.down();
  await page.mouse.move(tx, ty, { steps: 8 });
  const lifted = await waitFor(
    (f) => f.spring !== null && f.spring.body === 2 && f.x[3] > start.x[3] + 0.3,
    6,
    "the drag lifts the block",
  );
  result.lifted = lifted.x[3] - start.x[3];
  await page.screenshot({ path: screenshot });
  await page.mouse.up();
  await waitFor((f) => f.spring === null, 2, "the release reaches the server");
});

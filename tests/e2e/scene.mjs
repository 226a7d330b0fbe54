// End-to-end test of the viewer on a scene other than the finger (the pushing scene: a free block on a
// ground half-plane) in a real headless browser: the page draws the ground and the block where the
// server says they are, and a mouse drag lifts the block (a free body) off the ground. Usage: node
// scene.mjs URL SCREENSHOT.png. Prints one JSON line with what it measured; exits non-zero if a check
// fails.
import { chromium } from "playwright-core";

const [url, screenshot] = process.argv.slice(2);
const executablePath = process.env.CHROMIUM || "/usr/bin/chromium";
const browser = await chromium.launch({
  executablePath,
  args: [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
  ],
});
const result = { ok: false };
const fail = (why) => {
  result.error = why;
  throw new Error(why);
};
try {
  const page = await browser.newPage({ viewport: { width: 1100, height: 820 } });
  const errors = [];
  page.on("pageerror", (e) => errors.push(String(e)));
  await page.goto(url);
  const frame = () => page.evaluate(() => window.lastFrame);
  const waitFor = async (test, simSeconds, what) => {
    const start = (await frame()).t;
    for (;;) {
      const f = await frame();
      if (f && test(f)) {
        return f;
      }
      if (f && f.t > start + simSeconds) {
        fail(`${what}: not within ${simSeconds} simulated seconds (t = ${f.t})`);
      }
      await page.waitForTimeout(100);
    }
  };
  await page.waitForFunction(() => window.lastFrame !== undefined, null, { timeout: 10000 });
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
  result.block_colour = await colourAt(centre.map((v, i) => v + (i === 1 ? 0.1 : 0.1)));
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
  if (errors.length) {
    fail(`page errors: ${errors.join("; ")}`);
  }
  result.ok = true;
} catch (e) {
  result.error = result.error || String(e);
} finally {
  await browser.close();
  console.log(JSON.stringify(result));
  process.exitCode = result.ok ? 0 : 1;
}

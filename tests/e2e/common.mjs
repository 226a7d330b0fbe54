// What the viewer's end-to-end scripts share: launch Debian's Chromium through playwright-core, open
// the page, poll its frames in simulated time, and print one JSON line with what the script measured
// (exit code 1 if a check failed).
import { chromium } from "playwright-core";

// Run `body({ page, frame, waitFor, fail, result })` against the page at `url`; `result` collects what
// the body measures and is printed as one JSON line at the end, with `ok` and any `error`.
export async function run(url, body) {
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
    // Wait (in simulated time) for a frame satisfying `test`, polling every 100 ms of real time.
    const waitFor = async (test, simSeconds, what) => {
      const start = (await frame()).t;
      for (;;) {
        const f = await frame();
        if (f && test(f)) {
          return f;
        }
        if (f && f.t > start + simSeconds) {
          fail(`${what}: not within ${simSeconds} simulated seconds (t = ${f.t}, spin ${f.spin_rate})`);
        }
        await page.waitForTimeout(100);
      }
    };
    await page.waitForFunction(() => window.lastFrame !== undefined, null, { timeout: 10000 });
    await body({ page, frame, waitFor, fail, result });
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
}

// Drive the studio page in headless Chromium (Debian's `chromium`, through puppeteer-core, which never downloads a
// browser): `node drive.mjs CHROMIUM URL STEPS.json` runs the steps in order with real input (keyboard on sliders,
// mouse clicks on thumbnails and buttons) and prints one JSON object: {"results": [one per step], "console":
// [messages of type error/warning], "page_errors": [uncaught exceptions], "failed_requests": [...]}.
//
// Steps ({"do": ..., ...}):
//   load                        open URL, wait until the page is usable; {usable_ms}
//   keys {selector, key, n}     focus the element and press `key` n times (each press is one input event)
//   click {selector}            click the element, then wait for the page's pending requests
//   eval {expr}                 the value of an expression evaluated in the page (awaited)
//   screenshot {path, selector?}  a PNG of the page or of one element
//   redraws {selector, n}       n slider key presses, one frame apart, with the page's redraw timer on; {redraw_ms, draw_ms}
import puppeteer from "puppeteer-core";
import { readFileSync } from "node:fs";
import { mkdtempSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";

const [chromium, url, stepsPath] = process.argv.slice(2);
const steps = JSON.parse(readFileSync(stepsPath, "utf8"));
const profile = mkdtempSync(join(tmpdir(), "darthand-chromium-"));
const out = { results: [], console: [], page_errors: [], failed_requests: [] };

const browser = await puppeteer.launch({
  executablePath: chromium, headless: true, userDataDir: profile, defaultViewport: { width: 1500, height: 1000 },
  args: ["--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync", "--disable-extensions",
    "--disable-dev-shm-usage"],
});
try {
  const page = await browser.newPage();
  page.on("console", (m) => { if (m.type() === "error" || m.type() === "warn") out.console.push(`${m.type()}: ${m.text()}`); });
  page.on("pageerror", (e) => out.page_errors.push(e.message));
  page.on("requestfailed", (r) => out.failed_requests.push(`${r.url()}: ${r.failure()?.errorText}`));
  const idle = () => page.evaluate(() => window.studio.idle());
  for (const step of steps) {
    let result = null;
    if (step.do === "load") {
      await page.goto(url, { waitUntil: "load" });
      await page.evaluate(() => window.studio.ready);
      await idle();
      result = { usable_ms: await page.evaluate(() => window.studio.metrics.usable_ms) };
    } else if (step.do === "keys") {
      await page.$eval(step.selector, (el) => { el.closest("details")?.setAttribute("open", ""); el.scrollIntoView(); });
      await page.focus(step.selector);
      for (let i = 0; i < (step.n ?? 1); i++) await page.keyboard.press(step.key);
      await idle();
    } else if (step.do === "click") {
      await page.$eval(step.selector, (el) => { el.closest("details")?.setAttribute("open", ""); el.scrollIntoView(); });
      await page.click(step.selector);
      await new Promise((r) => setTimeout(r, 50));
      await idle();
    } else if (step.do === "eval") {
      result = await page.evaluate(`(async () => (${step.expr}))()`);
    } else if (step.do === "screenshot") {
      const target = step.selector ? await page.$(step.selector) : page;
      await target.screenshot({ path: step.path });
    } else if (step.do === "redraws") {
      await page.evaluate(() => { Object.assign(window.studio, { measure: true }); Object.assign(window.studio.metrics, { redraw_ms: [], draw_ms: [] }); });
      await page.focus(step.selector);
      for (let i = 0; i < step.n; i++) {
        await page.keyboard.press(i % 2 ? "ArrowLeft" : "ArrowRight");
        await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
      }
      result = await page.evaluate(() => {
        window.studio.measure = false;
        return { redraw_ms: window.studio.metrics.redraw_ms, draw_ms: window.studio.metrics.draw_ms };
      });
    } else {
      throw new Error(`unknown step ${JSON.stringify(step)}`);
    }
    out.results.push(result);
  }
} catch (e) {
  out.error = String(e?.message || e).split("\n")[0];
} finally {
  await browser.close();
  rmSync(profile, { recursive: true, force: true });
}
process.stdout.write(JSON.stringify(out));

// End-to-end test of `edrnr serve` in headless Chromium (playwright-core):
// load the page, orbit, check that the frame changes and its time is shown,
// switch model, run a quick simulation of a procedural scene comparing two
// chip presets and wait for the charts; a screenshot is saved as an artefact.
//
// node e2e.mjs --edrnr BIN --web DIST --out DIR [--chromium PATH]
// Exit 0: passed; 1: failed; 77: skipped (no Chromium or no playwright-core).
import { spawn } from "node:child_process";
import { existsSync, mkdirSync, mkdtempSync, rmSync } from "node:fs";
import { createRequire } from "node:module";
import { tmpdir } from "node:os";
import { join, resolve } from "node:path";

const args = Object.fromEntries(
  process.argv.slice(2).reduce((acc, a, i, all) => (a.startsWith("--") ? [...acc, [a.slice(2), all[i + 1]]] : acc), []),
);
const SKIP = 77;

function skip(why) {
  console.log(`SKIPPED: ${why}`);
  process.exit(SKIP);
}

const chromium = args.chromium || process.env.CHROMIUM || ["/usr/bin/chromium", "/usr/bin/chromium-browser"].find(existsSync);
if (!chromium || !existsSync(chromium)) skip("no Chromium (scripts/setup.sh installs the Debian 'chromium' package)");
let playwright;
try {
  playwright = createRequire(resolve(args.web, "..", "package.json"))("playwright-core");
} catch {
  skip("playwright-core is not installed in web/node_modules (scripts/build-web.sh installs it)");
}
if (!existsSync(join(args.web, "index.html"))) skip(`the front end is not built (${args.web}/index.html missing)`);

const work = mkdtempSync(join(tmpdir(), "edrnr-e2e-"));
mkdirSync(join(work, "models"));
mkdirSync(join(work, "data"));
mkdirSync(args.out, { recursive: true });

// The server, on a free port: procedural models only, so the test needs no data.
const server = spawn(resolve(args.edrnr), ["serve", "--port", "0", "--models", join(work, "models"), "--data", join(work, "data"), "--web", args.web], {
  stdio: ["ignore", "pipe", "inherit"],
});
const url = await new Promise((resolve, reject) => {
  let out = "";
  server.stdout.on("data", (d) => {
    out += d;
    const m = out.match(/listening on (http:\/\/[^ ]+\/)/);
    if (m) resolve(m[1]);
  });
  server.on("error", reject);
  server.on("exit", (code) => reject(new Error(`edrnr serve exited (${code}) before listening:\n${out}`)));
  setTimeout(() => reject(new Error(`edrnr serve did not start within 20 s:\n${out}`)), 20000);
});

let browser;
let failed = false;
function check(cond, what) {
  if (!cond) throw new Error(`check failed: ${what}`);
  console.log(`ok: ${what}`);
}

try {
  browser = await playwright.chromium.launch({ executablePath: chromium, args: ["--no-sandbox", "--disable-gpu"] });
  const page = await browser.newPage({ viewport: { width: 1280, height: 1800 }, hasTouch: true });
  const pageErrors = [];
  page.on("pageerror", (e) => pageErrors.push(String(e)));
  await page.goto(url);

  const frames = async () => Number((await page.locator("#render").getAttribute("data-frames")) ?? 0);
  const pixels = () => page.locator("#render").evaluate((c) => c.toDataURL());
  await page.waitForFunction(() => Number(document.querySelector("#render")?.dataset.frames ?? 0) >= 1, null, { timeout: 30000 });
  check(/ms delivered \(render \d+ ms, \w+\)/.test(await page.locator("#frame-time").innerText()), "the frame time is shown");
  const model0 = await page.locator("#model").inputValue();
  check(model0.startsWith("procedural-"), `a model is selected (${model0})`);

  // Orbit: drag across the canvas; frames arrive while dragging and at full size after.
  const before = await pixels();
  const n0 = await frames();
  const box = await page.locator("#render").boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  for (let i = 1; i <= 10; i++) {
    await page.mouse.move(box.x + box.width / 2 + 12 * i, box.y + box.height / 2 + 3 * i);
    await page.waitForTimeout(40);
  }
  await page.mouse.up();
  await page.waitForFunction((n) => Number(document.querySelector("#render").dataset.frames) >= n + 2, n0, { timeout: 30000 });
  await page.waitForTimeout(800); // the full-size frame after the pointer stops
  check((await frames()) > n0, `frames arrived while orbiting (${(await frames()) - n0})`);
  check((await pixels()) !== before, "the frame changed after orbiting");

  // Orbit by touch: a one-finger drag (real touch events through the DevTools protocol).
  const cdp = await page.context().newCDPSession(page);
  const beforeTouch = await pixels();
  const n2 = await frames();
  const cx = box.x + box.width / 2;
  const cy = box.y + box.height / 2;
  await cdp.send("Input.dispatchTouchEvent", { type: "touchStart", touchPoints: [{ x: cx, y: cy }] });
  for (let i = 1; i <= 8; i++) {
    await cdp.send("Input.dispatchTouchEvent", { type: "touchMove", touchPoints: [{ x: cx - 15 * i, y: cy }] });
    await page.waitForTimeout(40);
  }
  await cdp.send("Input.dispatchTouchEvent", { type: "touchEnd", touchPoints: [] });
  await page.waitForFunction((n) => Number(document.querySelector("#render").dataset.frames) >= n + 2, n2, { timeout: 30000 });
  await page.waitForTimeout(800);
  check((await pixels()) !== beforeTouch, `a touch drag orbits the view (${(await frames()) - n2} frames)`);

  // Switch model.
  const other = await page.locator("#model option").evaluateAll((os, cur) => os.map((o) => o.value).find((v) => v !== cur), model0);
  const beforeSwitch = await pixels();
  const n1 = await frames();
  await page.selectOption("#model", other);
  await page.waitForFunction((n) => Number(document.querySelector("#render").dataset.frames) > n, n1, { timeout: 30000 });
  await page.waitForTimeout(300);
  check((await pixels()) !== beforeSwitch, `switching to ${other} changed the frame`);

  // A quick simulation of a procedural scene, two presets side by side.
  const presets = await page.locator("#preset-a option").count();
  await page.selectOption("#sim-size", "50");
  if (presets > 1) await page.locator("#compare").check();
  await page.click("#simulate");
  await page.waitForSelector(".result [data-chart='sram-budget'] canvas", { timeout: 120000 });
  const cards = await page.locator(".result").count();
  check(cards === (presets > 1 ? 2 : 1), `${cards} simulation report(s) shown side by side`);
  const charts = await page.locator(".result [data-chart] canvas").count();
  check(charts === 4 * cards, `${charts} charts drawn (hit rates, DRAM traffic, unit breakdown, SRAM budget)`);
  const fps = await page.locator(".result .kpi b").first().innerText();
  check(Number(fps) > 0, `the simulated frame rate is shown (${fps} FPS)`);
  const trace = await page.locator(".result a[download]").first().getAttribute("href");
  const traceRes = await page.request.get(new URL(trace, url).toString());
  check(traceRes.ok() && (await traceRes.json()).traceEvents !== undefined, "the Chrome trace downloads");
  check((await page.locator("#sim-status").innerText()).includes("done"), "the progress line reports done");
  check(pageErrors.length === 0, `no script errors on the page${pageErrors.length ? ": " + pageErrors.join("; ") : ""}`);
  await page.screenshot({ path: join(args.out, "web-e2e.png"), fullPage: true });
  console.log(`screenshot: ${join(args.out, "web-e2e.png")}`);
} catch (e) {
  failed = true;
  console.error(`FAILED: ${e.message}`);
  try {
    const pages = browser ? browser.contexts().flatMap((c) => c.pages()) : [];
    if (pages[0]) await pages[0].screenshot({ path: join(args.out, "web-e2e-failure.png"), fullPage: true });
  } catch {}
} finally {
  if (browser) await browser.close();
  server.kill("SIGTERM");
  rmSync(work, { recursive: true, force: true });
}
process.exit(failed ? 1 : 0);

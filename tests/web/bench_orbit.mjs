// Frame rate of orbiting in the browser, against a running `edrnr serve`
// (headless Chromium through playwright-core). Not part of ctest: its figures
// go into docs/web.md.
//
// node tests/web/bench_orbit.mjs --url http://127.0.0.1:PORT/ [--model lego] [--size 400] [--seconds 10]
//
// fixed: frames of --size x --size requested one after the other while the
//   azimuth steps on, each decoded and drawn on a canvas, as the page does;
// drag: the page itself while the mouse drags across the view (its lower
//   resolution while dragging included).
import { existsSync } from "node:fs";
import { createRequire } from "node:module";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";

const args = Object.fromEntries(
  process.argv.slice(2).reduce((acc, a, i, all) => (a.startsWith("--") ? [...acc, [a.slice(2), all[i + 1]]] : acc), []),
);
const url = args.url ?? "http://127.0.0.1:8080/";
const model = args.model ?? "lego";
const size = Number(args.size ?? 400);
const seconds = Number(args.seconds ?? 10);
const here = dirname(fileURLToPath(import.meta.url));
const { chromium } = createRequire(join(here, "..", "..", "web", "package.json"))("playwright-core");
const executablePath = args.chromium ?? ["/usr/bin/chromium", "/usr/bin/chromium-browser"].find(existsSync);

const browser = await chromium.launch({ executablePath, args: ["--no-sandbox", "--disable-gpu"] });
const page = await browser.newPage({ viewport: { width: 1280, height: 1000 } });
await page.goto(url);
await page.waitForFunction(() => Number(document.querySelector("#render")?.dataset.frames ?? 0) >= 1, null, { timeout: 60000 });

const fixed = await page.evaluate(
  async ({ model, size, seconds }) => {
    const canvas = document.createElement("canvas");
    canvas.width = size;
    canvas.height = size;
    const ctx = canvas.getContext("2d");
    const renderMs = [];
    const t0 = performance.now();
    let az = 0;
    while (performance.now() - t0 < seconds * 1000) {
      az += 3;
      const res = await fetch(`/api/render?model=${model}&w=${size}&az=${az}&el=30&radius=4&fov=40`);
      const bytes = new Uint8ClampedArray(await res.arrayBuffer());
      ctx.putImageData(new ImageData(bytes, size, size), 0, 0);
      renderMs.push(Number(res.headers.get("X-Render-Ms")));
    }
    const elapsed = (performance.now() - t0) / 1000;
    renderMs.sort((a, b) => a - b);
    return {
      frames: renderMs.length,
      frames_per_second: renderMs.length / elapsed,
      render_ms_median: renderMs[Math.floor(renderMs.length / 2)],
      engine: (await fetch("/api/catalog").then((r) => r.json())).engine,
    };
  },
  { model, size, seconds },
);

// Drag: orbit view of the model at --size.
await page.selectOption("#model", model);
await page.selectOption("#view", "orbit");
await page.selectOption("#size", String(size));
await page.waitForTimeout(2000);
const box = await page.locator("#render").boundingBox();
const frames0 = Number(await page.locator("#render").getAttribute("data-frames"));
const widths = [];
await page.mouse.move(box.x + 20, box.y + box.height / 2);
await page.mouse.down();
const t0 = Date.now();
let i = 0;
while (Date.now() - t0 < seconds * 1000) {
  i++;
  await page.mouse.move(box.x + 20 + ((i * 4) % (box.width - 40)), box.y + box.height / 2 + 20 * Math.sin(i / 10));
  await page.waitForTimeout(16);
  widths.push(Number(await page.locator("#render").getAttribute("data-width")));
}
const dragSeconds = (Date.now() - t0) / 1000;
const frames1 = Number(await page.locator("#render").getAttribute("data-frames"));
await page.mouse.up();
const drag = {
  frames: frames1 - frames0,
  frames_per_second: (frames1 - frames0) / dragSeconds,
  drag_width_median: widths.sort((a, b) => a - b)[Math.floor(widths.length / 2)],
  frame_time_text: await page.locator("#frame-time").innerText(),
};
console.log(JSON.stringify({ model, size, seconds, fixed, drag }, null, 1));
await browser.close();

// The simulation panel: submits the current view, polls its progress and
// shows each preset's report (figures, charts, image, trace) side by side.
import {
  BarController,
  BarElement,
  CategoryScale,
  Chart,
  Legend,
  LinearScale,
  LineController,
  LineElement,
  PointElement,
  Tooltip,
} from "chart.js";
import { ApiError, type Pose, type SimReport, type SimStatus, getJson } from "./api";

Chart.register(BarController, BarElement, CategoryScale, LinearScale, LineController, LineElement, PointElement, Legend, Tooltip);

const kUnits = ["front_end", "ctu", "ftu", "ooo_si", "cfiu", "tme", "vru"];
const kDataTypes = ["bitmaps", "micro_grid", "features", "mlp_weights", "rp_output"];
const kColors = ["#3b6fd8", "#e0833a", "#3aa76d", "#c94f6d", "#8a63c9", "#7a8699"];

function clientId(): string {
  const key = "edrnr-client-id";
  let id = sessionStorage.getItem(key);
  if (!id) {
    id = Array.from(crypto.getRandomValues(new Uint8Array(12)), (b) => b.toString(16).padStart(2, "0")).join("");
    sessionStorage.setItem(key, id);
  }
  return id;
}

function stat(r: SimReport, name: string): number {
  return r.stats[name]?.value ?? 0;
}

function el<K extends keyof HTMLElementTagNameMap>(tag: K, props: Partial<HTMLElementTagNameMap[K]> = {}, ...children: (Node | string)[]): HTMLElementTagNameMap[K] {
  const e = Object.assign(document.createElement(tag), props);
  e.append(...children);
  return e;
}

function kpi(label: string, value: string): HTMLElement {
  return el("div", { className: "kpi" }, el("b", {}, value), el("span", {}, label));
}

function chartBox(name: string): { box: HTMLElement; canvas: HTMLCanvasElement } {
  const canvas = el("canvas");
  const box = el("div", { className: "chart" }, canvas);
  box.dataset.chart = name;
  return { box, canvas };
}

export class SimPanel {
  private job: number | null = null;
  private timer: number | undefined;
  private charts: Chart[] = [];
  private readonly client = clientId();

  constructor(
    private readonly ui: {
      presetA: HTMLSelectElement;
      presetB: HTMLSelectElement;
      compare: HTMLInputElement;
      size: HTMLSelectElement;
      simulate: HTMLButtonElement;
      cancel: HTMLButtonElement;
      progress: HTMLProgressElement;
      status: HTMLElement;
      results: HTMLElement;
    },
    private readonly currentPose: () => Pose | null,
    private readonly testViewFullWidth: () => number,
  ) {
    ui.simulate.addEventListener("click", () => void this.start());
    ui.cancel.addEventListener("click", () => void this.cancel());
  }

  private setStatus(text: string, error = false): void {
    this.ui.status.textContent = text;
    this.ui.status.classList.toggle("error", error);
  }

  async start(): Promise<void> {
    const pose = this.currentPose();
    if (!pose) return;
    const body: Record<string, string | number> = {
      client: this.client,
      model: pose.model,
      preset: this.ui.presetA.value,
      w: Number(this.ui.size.value),
    };
    if (this.ui.compare.checked) body.compare = this.ui.presetB.value;
    if (pose.view !== null) {
      body.view = pose.view;
      body.w = this.testViewWidth(Number(this.ui.size.value));
    } else {
      Object.assign(body, { az: +pose.az.toFixed(3), el: +pose.el.toFixed(3), radius: +pose.radius.toFixed(4), fov: +pose.fov.toFixed(3) });
    }
    try {
      const r = await getJson<{ id: number }>("/api/sim", {
        method: "POST",
        headers: { "Content-Type": "application/json" },
        body: JSON.stringify(body),
      });
      this.job = r.id;
      this.ui.simulate.disabled = true;
      this.ui.cancel.disabled = false;
      this.ui.progress.value = 0;
      this.setStatus(`simulation ${r.id} queued`);
      this.poll();
    } catch (err) {
      this.setStatus(err instanceof ApiError ? err.message : String(err), true);
    }
  }

  // A test view (800 wide) scales down by whole factors: the nearest one to the chosen size.
  private testViewWidth(size: number): number {
    const full = this.testViewFullWidth();
    let best = full;
    for (let f = 1; f <= full; f++)
      if (full % f === 0 && Math.abs(full / f - size) < Math.abs(best - size)) best = full / f;
    return best;
  }

  async cancel(): Promise<void> {
    if (this.job === null) return;
    try {
      await getJson(`/api/sim/${this.job}?client=${this.client}`, { method: "DELETE" });
    } catch (err) {
      this.setStatus(err instanceof ApiError ? err.message : String(err), true);
    }
  }

  private poll(): void {
    window.clearTimeout(this.timer);
    this.timer = window.setTimeout(() => void this.check(), 250);
  }

  private async check(): Promise<void> {
    if (this.job === null) return;
    let s: SimStatus;
    try {
      s = await getJson<SimStatus>(`/api/sim/${this.job}`);
    } catch (err) {
      this.finish(err instanceof ApiError ? err.message : String(err), true);
      return;
    }
    this.ui.progress.value = s.progress.fraction;
    const presetLabel = s.presets.length > 1 ? ` (preset ${s.progress.preset_index + 1} of ${s.presets.length})` : "";
    switch (s.state) {
      case "queued":
        this.setStatus(`simulation ${s.id}: waiting, position ${s.queue_position ?? "?"} in the queue`);
        this.poll();
        return;
      case "running":
        this.setStatus(
          `simulation ${s.id}: ${(100 * s.progress.fraction).toFixed(0)} %${presetLabel}, ` +
            `${s.progress.rps_done}/${s.progress.rps_total} ray packets, ${s.progress.cycle.toLocaleString()} cycles`,
        );
        this.poll();
        return;
      case "done":
        this.show(s);
        this.finish(`simulation ${s.id}: done`);
        return;
      default:
        this.finish(`simulation ${s.id}: ${s.state}${s.error ? `: ${s.error}` : ""}`, s.state === "failed");
    }
  }

  private finish(text: string, error = false): void {
    this.job = null;
    this.ui.simulate.disabled = false;
    this.ui.cancel.disabled = true;
    this.setStatus(text, error);
  }

  private show(s: SimStatus): void {
    for (const c of this.charts) c.destroy();
    this.charts = [];
    this.ui.results.replaceChildren();
    for (const r of s.results) this.ui.results.append(this.resultCard(r.report, r.image_url, r.trace_url));
  }

  private resultCard(r: SimReport, imageUrl: string, traceUrl: string): HTMLElement {
    const s = r.summary;
    const kpis = el(
      "div",
      { className: "kpis" },
      kpi("frames per second", s.fps.toFixed(1)),
      kpi("nJ per pixel", s.nJ_per_pixel !== undefined ? s.nJ_per_pixel.toFixed(2) : "–"),
      kpi("power (mW)", s.power_mW !== undefined ? s.power_mW.toFixed(0) : "–"),
      kpi("cycles", s.cycles.toLocaleString()),
      kpi("clock (MHz)", s.clock_MHz.toFixed(0)),
      kpi("PSNR vs ground truth (dB)", s.psnr_vs_ground_truth_dB !== undefined ? s.psnr_vs_ground_truth_dB.toFixed(2) : "–"),
    );
    const img = el("img", { src: imageUrl, alt: `simulated image (${r.preset})` });
    const trace = el("a", { href: traceUrl, download: `edrnr-${r.preset}-trace.json` }, "Download the Chrome / Perfetto trace");
    const media = el("p", {}, img, el("br"), trace, " (open it in ui.perfetto.dev)");
    const card = el("div", { className: "result" }, el("h3", {}, `${r.preset} · ${r.model} · ${r.image.width}×${r.image.height}`), kpis, media);
    card.dataset.preset = r.preset;

    const hit = chartBox("hit-rates");
    const dram = chartBox("dram-traffic");
    const units = chartBox("unit-breakdown");
    const sram = chartBox("sram-budget");
    card.append(el("h4", {}, "Hit rates over time"), hit.box, el("h4", {}, "DRAM traffic by data type"), dram.box);
    card.append(el("h4", {}, "Units: busy and stalled (% of cycles)"), units.box, el("h4", {}, `SRAM budget${r.sram_budget.over_budget ? " (over budget)" : ""}`), sram.box);
    card.append(el("details", {}, el("summary", {}, "Text report"), el("pre", {}, r.text)));

    const series = Object.entries(r.hit_rate_series).filter(([name]) => name !== "mlp_weight_lines");
    this.charts.push(
      new Chart(hit.canvas, {
        type: "line",
        data: {
          datasets: series.map(([name, sr], i) => ({
            label: name,
            data: sr.windows.map((w) => ({ x: w.start_cycle, y: 100 * w.hit_rate })),
            borderColor: kColors[i % kColors.length],
            backgroundColor: kColors[i % kColors.length],
            pointRadius: sr.windows.length > 40 ? 0 : 2,
          })),
        },
        options: {
          animation: false,
          maintainAspectRatio: false,
          scales: { x: { type: "linear", title: { display: true, text: "cycle" } }, y: { min: 0, max: 100, title: { display: true, text: "hit rate (%)" } } },
        },
      }),
    );
    this.charts.push(
      new Chart(dram.canvas, {
        type: "bar",
        data: {
          labels: kDataTypes,
          datasets: [
            { label: "read (KB)", data: kDataTypes.map((t) => stat(r, `mem.${t}.read_bytes`) / 1024), backgroundColor: kColors[0] },
            { label: "written (KB)", data: kDataTypes.map((t) => stat(r, `mem.${t}.write_bytes`) / 1024), backgroundColor: kColors[1] },
          ],
        },
        options: { animation: false, maintainAspectRatio: false, scales: { y: { title: { display: true, text: "KB" } } } },
      }),
    );
    const parts = [
      ["busy", "busy_cycles"],
      ["stall (output full)", "stall_output_cycles"],
      ["stall (memory)", "stall_memory_cycles"],
      ["idle", "idle_cycles"],
    ];
    this.charts.push(
      new Chart(units.canvas, {
        type: "bar",
        data: {
          labels: kUnits,
          datasets: parts.map(([label, key], i) => ({
            label,
            data: kUnits.map((u) => (100 * stat(r, `sim.unit.${u}.${key}`)) / Math.max(1, s.cycles)),
            backgroundColor: kColors[i],
          })),
        },
        options: {
          animation: false,
          maintainAspectRatio: false,
          indexAxis: "y",
          scales: { x: { stacked: true, max: 100 }, y: { stacked: true } },
        },
      }),
    );
    const classes = Object.entries(r.sram_budget.classes);
    this.charts.push(
      new Chart(sram.canvas, {
        type: "bar",
        data: {
          labels: classes.map(([name]) => name),
          datasets: [
            { label: "used (KB)", data: classes.map(([, c]) => c.bytes / 1024), backgroundColor: kColors[2] },
            { label: "Table I budget (KB)", data: classes.map(([, c]) => c.budget_bytes / 1024), backgroundColor: kColors[5] },
          ],
        },
        options: { animation: false, maintainAspectRatio: false },
      }),
    );
    return card;
  }
}

// The JSON API of `edrnr serve` (docs/web.md), typed for the page.

export interface TestView {
  width: number;
  height: number;
  azimuth_deg: number;
  elevation_deg: number;
  radius: number;
  fov_deg: number;
}

export interface Catalog {
  models: { name: string; kind: "file" | "procedural"; file_bytes: number; dataset: string }[];
  datasets: { name: string; test_views: TestView[] }[];
  presets: string[];
  engine: string;
  limits: {
    min_side: number;
    max_side: number;
    max_sim_side: number;
    min_radius: number;
    max_radius: number;
    min_fov_deg: number;
    max_fov_deg: number;
    max_elevation_deg: number;
  };
}

// An orbit around the origin, or a dataset's test view.
export interface Pose {
  model: string;
  az: number;
  el: number;
  radius: number;
  fov: number;
  view: number | null; // a test view index: its exact camera (the orbit fields are only the start of an orbit)
}

export interface Frame {
  pixels: ImageData;
  renderMs: number;
  engine: string;
  psnr: number | null;
}

export class ApiError extends Error {
  constructor(
    readonly status: number,
    message: string,
  ) {
    super(message);
  }
}

async function check(res: Response): Promise<Response> {
  if (res.ok) return res;
  let message = `${res.status} ${res.statusText}`;
  try {
    const body = await res.json();
    if (body && typeof body.error === "string") message = body.error;
  } catch {
    // not JSON: keep the status line
  }
  throw new ApiError(res.status, message);
}

export async function getJson<T>(url: string, init?: RequestInit): Promise<T> {
  const res = await check(await fetch(url, init));
  return (await res.json()) as T;
}

export function viewParams(pose: Pose, width: number): URLSearchParams {
  const p = new URLSearchParams({ model: pose.model, w: String(width) });
  if (pose.view !== null) {
    p.set("view", String(pose.view));
  } else {
    p.set("az", pose.az.toFixed(3));
    p.set("el", pose.el.toFixed(3));
    p.set("radius", pose.radius.toFixed(4));
    p.set("fov", pose.fov.toFixed(3));
  }
  return p;
}

// One rendered frame as 8-bit RGBA pixels.
export async function renderFrame(pose: Pose, width: number, signal?: AbortSignal): Promise<Frame> {
  const res = await check(await fetch(`/api/render?${viewParams(pose, width)}`, { signal }));
  const w = Number(res.headers.get("X-Width"));
  const h = Number(res.headers.get("X-Height"));
  const bytes = new Uint8ClampedArray(await res.arrayBuffer());
  if (bytes.length !== w * h * 4) throw new ApiError(500, `frame of ${bytes.length} bytes for ${w}x${h}`);
  const psnr = res.headers.get("X-PSNR-dB");
  return {
    pixels: new ImageData(bytes, w, h),
    renderMs: Number(res.headers.get("X-Render-Ms")),
    engine: res.headers.get("X-Engine") ?? "",
    psnr: psnr === null ? null : Number(psnr),
  };
}

export interface StatEntry {
  unit: string;
  description: string;
  value?: number;
}

export interface SimReport {
  model: string;
  preset: string;
  image: { width: number; height: number };
  summary: {
    cycles: number;
    clock_MHz: number;
    fps: number;
    nJ_per_pixel?: number;
    power_mW?: number;
    psnr_vs_ground_truth_dB?: number;
    host_seconds: number;
    feature_hit_rate: number;
    micro_grid_hit_rate: number;
    mlp_hit_rate: number;
  };
  stats: Record<string, StatEntry>;
  hit_rate_series: Record<string, { window_cycles: number; windows: { start_cycle: number; hit_rate: number }[] }>;
  sram_budget: {
    over_budget: boolean;
    classes: Record<string, { bytes: number; budget_bytes: number }>;
  };
  text: string;
}

export interface SimStatus {
  id: number;
  state: "queued" | "running" | "done" | "failed" | "cancelled";
  queue_position?: number;
  error?: string;
  progress: { fraction: number; cycle: number; rps_done: number; rps_total: number; preset_index: number };
  presets: string[];
  results: { preset: string; report: SimReport; image_url: string; trace_url: string }[];
}

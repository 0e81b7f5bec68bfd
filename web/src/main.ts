// The page of `edrnr serve`: model and view pickers, the render pane with the
// ground truth beside it, and the simulation panel.
import "./style.css";
import { type Catalog, type Pose, getJson, viewParams } from "./api";
import { SimPanel } from "./sim";
import { Viewer } from "./viewer";

function $<T extends HTMLElement>(id: string): T {
  const e = document.getElementById(id);
  if (!e) throw new Error(`page element #${id} missing`);
  return e as T;
}

function option(value: string, label: string): HTMLOptionElement {
  const o = document.createElement("option");
  o.value = value;
  o.textContent = label;
  return o;
}

async function main(): Promise<void> {
  const status = $<HTMLElement>("status");
  const setStatus = (text: string, error = false) => {
    status.textContent = text;
    status.classList.toggle("error", error);
  };
  let catalog: Catalog;
  try {
    catalog = await getJson<Catalog>("/api/catalog");
  } catch (err) {
    setStatus(`cannot reach the server: ${err instanceof Error ? err.message : String(err)}`, true);
    return;
  }

  const modelSel = $<HTMLSelectElement>("model");
  const viewSel = $<HTMLSelectElement>("view");
  const sizeSel = $<HTMLSelectElement>("size");
  const frameTime = $<HTMLElement>("frame-time");
  const frameCount = $<HTMLElement>("frame-count");
  const gt = $<HTMLImageElement>("gt");
  const gtFigure = $<HTMLElement>("gt-figure");
  const psnr = $<HTMLElement>("psnr");
  $<HTMLElement>("engine").textContent = `renderer: ${catalog.engine}`;

  for (const m of catalog.models) modelSel.append(option(m.name, m.kind === "procedural" ? `${m.name} (procedural)` : m.name));
  for (const s of [100, 200, 400, 800]) sizeSel.append(option(String(s), `${s}×${s}`));
  sizeSel.value = "400";

  const datasetOf = (model: string) => catalog.datasets.find((d) => d.name === catalog.models.find((m) => m.name === model)?.dataset);

  let draggedFps = 0;
  const viewer = new Viewer(
    $<HTMLCanvasElement>("render"),
    { minRadius: catalog.limits.min_radius, maxRadius: catalog.limits.max_radius, maxElevation: catalog.limits.max_elevation_deg },
    {
      onFrame(frame, deliveredMs, dragging) {
        const size = `${frame.pixels.width}×${frame.pixels.height}`;
        draggedFps = dragging ? 0.8 * draggedFps + 0.2 * (1000 / deliveredMs) : draggedFps;
        frameTime.textContent =
          `${size}: ${deliveredMs.toFixed(0)} ms delivered (render ${frame.renderMs.toFixed(0)} ms, ${frame.engine})` +
          (dragging ? `, ${draggedFps.toFixed(1)} frames/s while dragging` : "");
        frameCount.textContent = `frame ${viewer.frames}`;
        if (frame.psnr !== null) psnr.textContent = `PSNR ${frame.psnr.toFixed(2)} dB`;
        setStatus("");
      },
      onError(message) {
        setStatus(message, true);
      },
      onOrbit() {
        viewSel.value = "orbit";
        psnr.textContent = "(orbiting: pick a test view to compare)";
        gtFigure.classList.add("muted");
      },
    },
  );

  const fillViews = () => {
    viewSel.replaceChildren(option("orbit", "orbit"));
    const d = datasetOf(modelSel.value);
    d?.test_views.forEach((_, i) => viewSel.append(option(String(i), `test view ${i} (${d.name})`)));
    gtFigure.hidden = !d;
  };

  const apply = () => {
    const d = datasetOf(modelSel.value);
    const width = Number(sizeSel.value);
    const previous = viewer.currentPose();
    const pose: Pose = previous
      ? { ...previous, model: modelSel.value, view: null }
      : { model: modelSel.value, az: 30, el: 30, radius: 4, fov: 40, view: null };
    if (viewSel.value !== "orbit" && d) {
      const v = d.test_views[Number(viewSel.value)];
      Object.assign(pose, { az: v.azimuth_deg, el: v.elevation_deg, radius: v.radius, fov: v.fov_deg, view: Number(viewSel.value) });
      // A test view scales down by whole factors: the nearest to the chosen size.
      let w = v.width;
      for (let f = 1; f <= v.width; f++) if (v.width % f === 0 && Math.abs(v.width / f - width) < Math.abs(w - width)) w = v.width / f;
      gt.src = `/api/groundtruth?${new URLSearchParams({ dataset: d.name, view: viewSel.value, w: String(w) })}`;
      gtFigure.classList.remove("muted");
      psnr.textContent = "";
      viewer.setPose(pose, w);
    } else {
      psnr.textContent = d ? "(orbiting: pick a test view to compare)" : "";
      gtFigure.classList.add("muted");
      viewer.setPose(pose, width);
    }
    history.replaceState(null, "", `#${viewParams(pose, width)}`);
  };

  modelSel.addEventListener("change", () => {
    fillViews();
    viewSel.value = datasetOf(modelSel.value) ? "0" : "orbit";
    apply();
  });
  viewSel.addEventListener("change", apply);
  sizeSel.addEventListener("change", apply);

  const presetA = $<HTMLSelectElement>("preset-a");
  const presetB = $<HTMLSelectElement>("preset-b");
  for (const p of catalog.presets) {
    presetA.append(option(p, p));
    presetB.append(option(p, p));
  }
  if (catalog.presets.includes("edr_nr_40nm")) presetA.value = "edr_nr_40nm";
  presetB.value = catalog.presets.find((p) => p !== presetA.value) ?? presetA.value;
  const simSize = $<HTMLSelectElement>("sim-size");
  for (const s of [50, 100, 200, 400, 800].filter((s) => s <= catalog.limits.max_sim_side)) simSize.append(option(String(s), `${s}×${s}`));
  simSize.value = "100";
  new SimPanel(
    {
      presetA,
      presetB,
      compare: $<HTMLInputElement>("compare"),
      size: simSize,
      simulate: $<HTMLButtonElement>("simulate"),
      cancel: $<HTMLButtonElement>("cancel"),
      progress: $<HTMLProgressElement>("sim-progress"),
      status: $<HTMLElement>("sim-status"),
      results: $<HTMLElement>("sim-results"),
    },
    () => viewer.currentPose(),
    () => datasetOf(modelSel.value)?.test_views[0]?.width ?? 800,
  );

  // lego (the demo's model) or the first model with a dataset starts on its first test view.
  const first = catalog.models.find((m) => m.name === "lego" && m.dataset) ?? catalog.models.find((m) => m.dataset) ?? catalog.models[0];
  if (!first) {
    setStatus("no models served", true);
    return;
  }
  modelSel.value = first.name;
  fillViews();
  viewSel.value = first.dataset ? "0" : "orbit";
  apply();
}

void main();

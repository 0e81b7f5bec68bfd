// The render pane: orbiting with mouse or touch (pointer events), one frame
// request in flight at a time (the newest pose wins), a lower resolution
// while dragging and the full size once the pointer is still.
import { ApiError, type Frame, type Pose, renderFrame } from "./api";

export interface ViewerEvents {
  onFrame(frame: Frame, deliveredMs: number, dragging: boolean): void;
  onError(message: string): void;
  onOrbit(): void; // the user moved away from a test view
}

export interface Limits {
  minRadius: number;
  maxRadius: number;
  maxElevation: number;
}

const kStillDelayMs = 150; // pointer still this long: render at full size

export class Viewer {
  private pose: Pose | null = null;
  private fullWidth = 400;
  private dragging = false;
  private lastPointer = new Map<number, { x: number; y: number }>();
  private pinchDistance = 0;
  private inFlight = false;
  private pending: { pose: Pose; width: number } | null = null;
  private stillTimer: number | undefined;
  private dragRenderMs = 60; // the last render time of a dragging frame
  private dragWidth = 200;
  frames = 0;

  constructor(
    private readonly canvas: HTMLCanvasElement,
    private readonly limits: Limits,
    private readonly events: ViewerEvents,
  ) {
    canvas.addEventListener("pointerdown", (e) => this.pointerDown(e));
    canvas.addEventListener("pointermove", (e) => this.pointerMove(e));
    canvas.addEventListener("pointerup", (e) => this.pointerUp(e));
    canvas.addEventListener("pointercancel", (e) => this.pointerUp(e));
    canvas.addEventListener("wheel", (e) => this.wheel(e), { passive: false });
  }

  setPose(pose: Pose, fullWidth: number): void {
    this.pose = { ...pose };
    this.fullWidth = fullWidth;
    this.dragWidth = Math.max(50, Math.round(fullWidth / 2));
    this.request(this.fullWidth);
  }

  currentPose(): Pose | null {
    return this.pose ? { ...this.pose } : null;
  }

  private pointerDown(e: PointerEvent): void {
    if (!this.pose) return;
    try {
      this.canvas.setPointerCapture(e.pointerId);
    } catch {
      // a pointer the browser no longer tracks: follow it without capture
    }
    this.lastPointer.set(e.pointerId, { x: e.clientX, y: e.clientY });
    this.dragging = true;
    this.canvas.classList.add("dragging");
  }

  private pointerMove(e: PointerEvent): void {
    const last = this.lastPointer.get(e.pointerId);
    if (!last || !this.pose) return;
    const dx = e.clientX - last.x;
    const dy = e.clientY - last.y;
    this.lastPointer.set(e.pointerId, { x: e.clientX, y: e.clientY });
    if (this.lastPointer.size >= 2) {
      // Two fingers: pinch to change the radius.
      const [a, b] = [...this.lastPointer.values()];
      const d = Math.hypot(a.x - b.x, a.y - b.y);
      if (this.pinchDistance > 0 && d > 0) this.zoom(this.pinchDistance / d);
      this.pinchDistance = d;
      return;
    }
    if (dx === 0 && dy === 0) return;
    this.leaveTestView();
    this.pose.az = (this.pose.az - dx * 0.4) % 360;
    this.pose.el = Math.max(-this.limits.maxElevation, Math.min(this.limits.maxElevation, this.pose.el + dy * 0.4));
    this.moved();
  }

  private pointerUp(e: PointerEvent): void {
    this.lastPointer.delete(e.pointerId);
    if (this.lastPointer.size < 2) this.pinchDistance = 0;
    if (this.lastPointer.size === 0) {
      this.dragging = false;
      this.canvas.classList.remove("dragging");
      this.scheduleStill();
    }
  }

  private wheel(e: WheelEvent): void {
    if (!this.pose) return;
    e.preventDefault();
    this.zoom(Math.exp(e.deltaY * 0.001));
    this.scheduleStill();
  }

  private zoom(factor: number): void {
    if (!this.pose) return;
    this.leaveTestView();
    this.pose.radius = Math.max(this.limits.minRadius, Math.min(this.limits.maxRadius, this.pose.radius * factor));
    this.moved();
  }

  private leaveTestView(): void {
    if (this.pose && this.pose.view !== null) {
      this.pose.view = null;
      this.events.onOrbit();
    }
  }

  private moved(): void {
    this.request(this.dragWidth);
    this.scheduleStill();
  }

  private scheduleStill(): void {
    window.clearTimeout(this.stillTimer);
    this.stillTimer = window.setTimeout(() => {
      if (!this.dragging || this.lastPointer.size === 0) this.request(this.fullWidth);
      else this.scheduleStill();
    }, kStillDelayMs);
  }

  // The newest request replaces any that has not started yet.
  private request(width: number): void {
    if (!this.pose) return;
    this.pending = { pose: { ...this.pose }, width };
    if (!this.inFlight) void this.pump();
  }

  private async pump(): Promise<void> {
    while (this.pending) {
      const { pose, width } = this.pending;
      this.pending = null;
      this.inFlight = true;
      const t0 = performance.now();
      const dragging = width !== this.fullWidth;
      try {
        const frame = await renderFrame(pose, width);
        const delivered = performance.now() - t0;
        this.draw(frame);
        this.frames++;
        if (dragging) this.adaptDragWidth(frame.renderMs);
        this.events.onFrame(frame, delivered, dragging);
      } catch (err) {
        this.events.onError(err instanceof ApiError || err instanceof Error ? err.message : String(err));
      } finally {
        this.inFlight = false;
      }
    }
  }

  // Keep dragging frames near 15 per second: the render time grows with the pixel count.
  private adaptDragWidth(renderMs: number): void {
    this.dragRenderMs = renderMs;
    const targetMs = 40;
    const scale = Math.sqrt(targetMs / Math.max(1, this.dragRenderMs));
    const w = Math.round(Math.max(48, Math.min(this.fullWidth, this.dragWidth * Math.min(1.25, Math.max(0.5, scale)))));
    this.dragWidth = w;
  }

  private draw(frame: Frame): void {
    const { width, height } = frame.pixels;
    const off = document.createElement("canvas");
    off.width = width;
    off.height = height;
    off.getContext("2d")!.putImageData(frame.pixels, 0, 0);
    const ctx = this.canvas.getContext("2d")!;
    if (this.canvas.width !== this.fullWidth || this.canvas.height !== this.fullWidth * (height / width)) {
      this.canvas.width = this.fullWidth;
      this.canvas.height = Math.round(this.fullWidth * (height / width));
    }
    ctx.imageSmoothingEnabled = true;
    ctx.drawImage(off, 0, 0, this.canvas.width, this.canvas.height);
    this.canvas.dataset.frames = String(this.frames + 1);
    this.canvas.dataset.width = String(width);
  }
}

// Canvas drawings: the to-scale top view of the work area and the commanded-vs-actual speed plot.

const COLORS = {
  grid: "#26313b",
  text: "#9aa7b2",
  envelope: "#4fb3ff",
  keepout: "rgba(255, 90, 90, 0.28)",
  keepoutLine: "#ff5a5a",
  machine: "#e9eef2",
  stop: "#ffb347",
  cmd: "#ffb347",
  act: "#4fb3ff",
};

/** Size the canvas backing store to its CSS box at the device pixel ratio; returns the 2-D ctx. */
function fit(canvas) {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth;
  const h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
  }
  const ctx = canvas.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  return { ctx, w, h };
}

/** A tidy grid spacing (1, 2 or 5 times a power of ten) giving about `count` lines over span. */
function niceStep(span, count) {
  const raw = span / count;
  const p = 10 ** Math.floor(Math.log10(raw));
  for (const m of [1, 2, 5, 10]) if (m * p >= raw) return m * p;
  return 10 * p;
}

/** The smallest tidy value (1, 1.5, 2, 2.5, 3, 4, 5, 6, 8 times a power of ten) at least v. */
function niceCeil(v) {
  const p = 10 ** Math.floor(Math.log10(v));
  for (const m of [1, 1.5, 2, 2.5, 3, 4, 5, 6, 8, 10]) if (m * p >= v) return m * p;
  return 10 * p;
}

export class TopView {
  constructor(canvas) {
    this.canvas = canvas;
    this.zoom = 1; // 1 = the whole work area
    this.follow = true; // when zoomed, keep the machine in the middle
    this.center = null; // the middle of the drawing in mm when zoomed and not following
    this.last = null;
    this.scale = 1;
    let drag = null;
    canvas.addEventListener("pointerdown", (e) => {
      if (this.zoom <= 1) return;
      drag = { x: e.clientX, y: e.clientY };
      canvas.setPointerCapture(e.pointerId);
    });
    canvas.addEventListener("pointermove", (e) => {
      if (!drag || !this.center) return;
      // Dragging pans the drawing (and stops following the machine).
      this.follow = false;
      this.onFollowChange?.(false);
      this.center = [
        this.center[0] - (e.clientX - drag.x) / this.scale,
        this.center[1] + (e.clientY - drag.y) / this.scale,
      ];
      drag = { x: e.clientX, y: e.clientY };
      this.redraw();
    });
    const end = () => {
      drag = null;
    };
    canvas.addEventListener("pointerup", end);
    canvas.addEventListener("pointercancel", end);
    canvas.addEventListener(
      "wheel",
      (e) => {
        e.preventDefault();
        this.setZoom(this.zoom * (e.deltaY < 0 ? 1.5 : 1 / 1.5));
      },
      { passive: false },
    );
  }

  setZoom(z) {
    this.zoom = Math.min(64, Math.max(1, z));
    if (this.zoom === 1) this.center = null;
    this.redraw();
  }

  redraw() {
    if (this.last) this.draw(...this.last);
  }

  /** fmtLen formats mm in the display unit; unitMm is that unit in mm (1 or 25.4). */
  draw(view, fmtLen, unitMm = 1) {
    this.last = [view, fmtLen, unitMm];
    const { ctx, w, h } = fit(this.canvas);
    if (!view || !Array.isArray(view.mpos) || view.mpos.length < 2) return;
    const pos = view.mpos;
    const env = view.envelope;
    let x0, y0, x1, y1;
    if (env && env.min_mm && env.max_mm) {
      [x0, y0] = env.min_mm;
      [x1, y1] = env.max_mm;
    } else {
      // No soft limits: frame the machine and the keep-outs with some room around them.
      x0 = pos[0] - 50;
      x1 = pos[0] + 50;
      y0 = pos[1] - 50;
      y1 = pos[1] + 50;
      for (const k of view.keepouts || []) {
        x0 = Math.min(x0, k.min_mm[0]);
        y0 = Math.min(y0, k.min_mm[1]);
        x1 = Math.max(x1, k.max_mm[0]);
        y1 = Math.max(y1, k.max_mm[1]);
      }
    }
    const pad = 18;
    const fitScale = Math.min((w - 2 * pad) / Math.max(x1 - x0, 1e-6), (h - 2 * pad) / Math.max(y1 - y0, 1e-6));
    const scale = fitScale * this.zoom;
    this.scale = scale;
    // One scale for both axes keeps the drawing true to shape. Whole: the work area centred;
    // zoomed: the machine in the middle (follow) or wherever the user panned to.
    if (this.zoom > 1 && (this.follow || !this.center)) this.center = [pos[0], pos[1]];
    const cx = this.zoom > 1 ? this.center[0] : (x0 + x1) / 2;
    const cy = this.zoom > 1 ? this.center[1] : (y0 + y1) / 2;
    const sx = (x) => w / 2 + (x - cx) * scale;
    const sy = (y) => h / 2 - (y - cy) * scale;
    // The visible box in mm, for the grid.
    const vx0 = Math.max(x0, cx - w / 2 / scale);
    const vx1 = Math.min(x1, cx + w / 2 / scale);
    const vy0 = Math.max(y0, cy - h / 2 / scale);
    const vy1 = Math.min(y1, cy + h / 2 / scale);

    // Grid lines at round numbers of the display unit (10 mm, or 0.5 in), not of mm.
    const step = niceStep(Math.max(vx1 - vx0, vy1 - vy0) / unitMm, 6) * unitMm;
    ctx.strokeStyle = COLORS.grid;
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (let x = Math.ceil(vx0 / step) * step; x <= vx1; x += step) {
      ctx.moveTo(sx(x), sy(vy0));
      ctx.lineTo(sx(x), sy(vy1));
    }
    for (let y = Math.ceil(vy0 / step) * step; y <= vy1; y += step) {
      ctx.moveTo(sx(vx0), sy(y));
      ctx.lineTo(sx(vx1), sy(y));
    }
    ctx.stroke();

    for (const k of view.keepouts || []) {
      const kx = sx(k.min_mm[0]);
      const ky = sy(k.max_mm[1]);
      const kw = (k.max_mm[0] - k.min_mm[0]) * scale;
      const kh = (k.max_mm[1] - k.min_mm[1]) * scale;
      ctx.fillStyle = COLORS.keepout;
      ctx.fillRect(kx, ky, kw, kh);
      ctx.strokeStyle = COLORS.keepoutLine;
      ctx.strokeRect(kx, ky, kw, kh);
      ctx.fillStyle = COLORS.keepoutLine;
      ctx.font = "11px system-ui, sans-serif";
      ctx.fillText(k.name || "keep-out", kx + 3, ky + 12);
    }

    if (env) {
      ctx.strokeStyle = COLORS.envelope;
      ctx.lineWidth = 2;
      ctx.setLineDash([6, 4]);
      ctx.strokeRect(sx(x0), sy(y1), (x1 - x0) * scale, (y1 - y0) * scale);
      ctx.setLineDash([]);
    }

    const stop = view.stop_point_mpos;
    if (Array.isArray(stop) && stop.length >= 2) {
      ctx.strokeStyle = COLORS.stop;
      ctx.lineWidth = 2;
      ctx.beginPath();
      ctx.moveTo(sx(pos[0]), sy(pos[1]));
      ctx.lineTo(sx(stop[0]), sy(stop[1]));
      ctx.stroke();
      ctx.beginPath();
      ctx.arc(sx(stop[0]), sy(stop[1]), 7, 0, 2 * Math.PI);
      ctx.stroke();
    }

    ctx.fillStyle = COLORS.machine;
    ctx.beginPath();
    ctx.arc(sx(pos[0]), sy(pos[1]), 5, 0, 2 * Math.PI);
    ctx.fill();
    ctx.strokeStyle = COLORS.machine;
    ctx.lineWidth = 1;
    ctx.beginPath();
    ctx.moveTo(sx(pos[0]) - 11, sy(pos[1]));
    ctx.lineTo(sx(pos[0]) + 11, sy(pos[1]));
    ctx.moveTo(sx(pos[0]), sy(pos[1]) - 11);
    ctx.lineTo(sx(pos[0]), sy(pos[1]) + 11);
    ctx.stroke();

    ctx.fillStyle = COLORS.text;
    ctx.font = "11px system-ui, sans-serif";
    ctx.fillText(this.gridLabel ? this.gridLabel(fmtLen(step)) : fmtLen(step), 4, h - 4);
    ctx.fillText("X →  Y ↑", w - 58, h - 4);
  }
}

export class SpeedPlot {
  /** windowS: how much history is shown. */
  constructor(canvas, { windowS = 10 } = {}) {
    this.canvas = canvas;
    this.windowS = windowS;
    this.samples = [];
  }

  /** One sample; null speeds are gaps (nothing known), drawn as gaps rather than ramps. */
  add(tS, commanded, actual) {
    if (!Number.isFinite(tS)) return;
    const last = this.samples[this.samples.length - 1];
    if (last && tS < last[0]) this.samples = []; // the clock restarted (a new session)
    // The view is sent only while something changes: a long pause between samples is a gap.
    if (last && tS - last[0] > 0.5) this.samples.push([tS, null, null]);
    this.samples.push([tS, commanded, actual]);
    while (this.samples.length && tS - this.samples[0][0] > this.windowS + 1) this.samples.shift();
  }

  /** unitScale converts mm/s to the unit shown; unitLabel names it; topMmS is the axis top. */
  draw(unitScale, unitLabel, topMmS, windowLabel) {
    const { ctx, w, h } = fit(this.canvas);
    const left = 48;
    const bottom = h - 16;
    const top = 6;
    const right = w - 6;
    const tEnd = this.samples.length ? this.samples[this.samples.length - 1][0] : 0;
    // The scale comes from the machine's top speed, so a jog at full speed fills the plot.
    let vmax = Number.isFinite(topMmS) && topMmS > 0 ? topMmS * unitScale : 1;
    for (const [, c, a] of this.samples) vmax = Math.max(vmax, (c ?? 0) * unitScale, (a ?? 0) * unitScale);
    vmax = niceCeil(vmax);
    const px = (t) => left + ((t - (tEnd - this.windowS)) / this.windowS) * (right - left);
    const py = (v) => bottom - (v / vmax) * (bottom - top);

    ctx.strokeStyle = COLORS.grid;
    ctx.fillStyle = COLORS.text;
    ctx.font = "11px system-ui, sans-serif";
    ctx.lineWidth = 1;
    ctx.beginPath();
    const tick = niceStep(vmax, 4);
    for (let v = 0; v <= vmax + 1e-9; v += tick) {
      ctx.moveTo(left, py(v));
      ctx.lineTo(right, py(v));
      ctx.fillText(String(+v.toPrecision(4)), 2, py(v) + 4);
    }
    ctx.stroke();
    ctx.fillText(windowLabel ? windowLabel(unitLabel, this.windowS) : unitLabel, left + 4, h - 3);

    for (const [index, color, dash] of [
      [1, COLORS.cmd, [5, 3]],
      [2, COLORS.act, []],
    ]) {
      ctx.strokeStyle = color;
      ctx.lineWidth = 2;
      ctx.setLineDash(dash);
      ctx.beginPath();
      let started = false;
      for (const s of this.samples) {
        if (s[0] < tEnd - this.windowS) continue;
        if (s[index] === null || !Number.isFinite(s[index])) {
          started = false; // a gap: lift the pen
          continue;
        }
        const x = px(s[0]);
        const y = py(s[index] * unitScale);
        if (started) ctx.lineTo(x, y);
        else ctx.moveTo(x, y);
        started = true;
      }
      ctx.stroke();
    }
    ctx.setLineDash([]);
  }
}

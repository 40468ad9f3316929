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
  }

  draw(view, fmtLen) {
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
    const scale = Math.min((w - 2 * pad) / Math.max(x1 - x0, 1e-6), (h - 2 * pad) / Math.max(y1 - y0, 1e-6));
    // Centre the drawing; one scale for both axes keeps it true to shape.
    const ox = (w - (x1 - x0) * scale) / 2;
    const oy = (h - (y1 - y0) * scale) / 2;
    const sx = (x) => ox + (x - x0) * scale;
    const sy = (y) => h - oy - (y - y0) * scale;

    const step = niceStep(Math.max(x1 - x0, y1 - y0), 6);
    ctx.strokeStyle = COLORS.grid;
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (let x = Math.ceil(x0 / step) * step; x <= x1; x += step) {
      ctx.moveTo(sx(x), sy(y0));
      ctx.lineTo(sx(x), sy(y1));
    }
    for (let y = Math.ceil(y0 / step) * step; y <= y1; y += step) {
      ctx.moveTo(sx(x0), sy(y));
      ctx.lineTo(sx(x1), sy(y));
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
    ctx.fillText(`grid ${fmtLen(step)}`, 4, h - 4);
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

  add(tS, commanded, actual) {
    if (!Number.isFinite(tS)) return;
    const last = this.samples[this.samples.length - 1];
    if (last && tS < last[0]) this.samples = []; // the clock restarted (a new session)
    this.samples.push([tS, commanded ?? 0, actual ?? 0]);
    while (this.samples.length && tS - this.samples[0][0] > this.windowS + 1) this.samples.shift();
  }

  /** unitScale converts mm/s to the unit shown; unitLabel names it. */
  draw(unitScale, unitLabel) {
    const { ctx, w, h } = fit(this.canvas);
    const left = 44;
    const bottom = h - 16;
    const top = 6;
    const right = w - 6;
    const tEnd = this.samples.length ? this.samples[this.samples.length - 1][0] : 0;
    let vmax = 1;
    for (const [, c, a] of this.samples) vmax = Math.max(vmax, c * unitScale, a * unitScale);
    vmax = niceCeil(vmax * 1.05);
    const px = (t) => left + ((t - (tEnd - this.windowS)) / this.windowS) * (right - left);
    const py = (v) => bottom - (v / vmax) * (bottom - top);

    ctx.strokeStyle = COLORS.grid;
    ctx.fillStyle = COLORS.text;
    ctx.font = "11px system-ui, sans-serif";
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (let i = 0; i <= 4; i++) {
      const v = (vmax * i) / 4;
      ctx.moveTo(left, py(v));
      ctx.lineTo(right, py(v));
      ctx.fillText(String(Math.round(v * 10) / 10), 2, py(v) + 4);
    }
    ctx.stroke();
    ctx.fillText(`${unitLabel} · last ${this.windowS} s`, left + 4, h - 3);

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

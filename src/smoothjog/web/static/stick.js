// A virtual joystick driven by pointer events, with an optional inertial (flick-to-coast) mode.
//
// The stick's origin is where the finger lands, so touching never moves the machine: only
// dragging does. Each stick tracks its own pointer id, so the XY and Z sticks work together
// under two fingers. Lifting the finger reports zero at once (the mixer then sends a stop).

import { clamp, round3, shapeAxis, shapeRadial } from "./shaping.js";

/** Pointer speed (px/s) above which a release counts as a flick in inertial mode. */
const FLICK_PX_S = 500;
/** Pointer speed (px/s) that coasts at full deflection. */
const FLICK_FULL_PX_S = 2000;
/** Coasting decays like exp(-t / tau): about 2 s from full speed to rest. */
const COAST_TAU_S = 0.7;
const COAST_MIN = 0.03;
const COAST_TICK_MS = 40;
/** Only the last 100 ms of motion decide the flick's direction and speed. */
const FLICK_WINDOW_MS = 100;

export class Stick {
  /**
   * el: the stick element; axes: ["X", "Y"] or ["Z"] (vertical); onChange(contribution);
   * shape(): {deadzone, expo}; inertial(): whether flicks coast.
   */
  constructor(el, { axes, onChange, shape, inertial }) {
    this.el = el;
    this.knob = el.querySelector(".knob");
    this.axes = axes;
    this.vertical = axes.length === 1;
    this.onChange = onChange;
    this.shape = shape;
    this.inertial = inertial;
    this.pointerId = null;
    this.origin = null;
    this.samples = [];
    this.deflection = [0, 0];
    this.coastTimer = null;
    this.disabled = true;
    el.addEventListener("pointerdown", (e) => this._down(e));
    el.addEventListener("pointermove", (e) => this._move(e));
    el.addEventListener("pointerup", (e) => this._up(e, true));
    el.addEventListener("pointercancel", (e) => this._up(e, false));
    el.addEventListener("lostpointercapture", (e) => this._up(e, false));
    // A long press must not open a context menu on a phone.
    el.addEventListener("contextmenu", (e) => e.preventDefault());
  }

  setDisabled(disabled) {
    this.disabled = disabled;
    this.el.setAttribute("aria-disabled", String(disabled));
    if (disabled) this.reset();
  }

  /** Forget the finger and any coasting; the user must touch again to move. */
  reset() {
    this._stopCoast();
    if (this.pointerId !== null && this.el.hasPointerCapture?.(this.pointerId)) {
      this.el.releasePointerCapture(this.pointerId);
    }
    this.pointerId = null;
    this._render(0, 0);
    this.el.classList.remove("active");
    this._emit(0, 0);
  }

  _radiusPx() {
    const r = this.el.getBoundingClientRect();
    // The knob may travel this far from the origin for a full deflection.
    return this.vertical ? r.height * 0.4 : Math.min(r.width, r.height) * 0.38;
  }

  _down(e) {
    if (this.disabled) return;
    e.preventDefault();
    if (this.coastTimer !== null) {
      // A tap on a coasting stick stops it, like catching a scrolling list.
      this._stopCoast();
      this._emit(0, 0);
    }
    if (this.pointerId !== null) return;
    this.pointerId = e.pointerId;
    this.el.setPointerCapture(e.pointerId);
    this.origin = [e.clientX, e.clientY];
    this.samples = [[performance.now(), e.clientX, e.clientY]];
    this.el.classList.add("active");
  }

  _move(e) {
    if (e.pointerId !== this.pointerId || this.disabled) return;
    e.preventDefault();
    const now = performance.now();
    this.samples.push([now, e.clientX, e.clientY]);
    while (this.samples.length > 2 && now - this.samples[0][0] > FLICK_WINDOW_MS) {
      this.samples.shift();
    }
    const radius = this._radiusPx();
    let nx = this.vertical ? 0 : (e.clientX - this.origin[0]) / radius;
    let ny = -(e.clientY - this.origin[1]) / radius; // screen down is machine minus
    const r = Math.hypot(nx, ny);
    if (r > 1) {
      nx /= r;
      ny /= r;
    }
    this._render(nx * radius, -ny * radius);
    this._emitShaped(nx, ny);
  }

  _up(e, lifted) {
    if (e.pointerId !== this.pointerId) return;
    this.pointerId = null;
    this.el.classList.remove("active");
    this._render(0, 0);
    const flick = lifted && this.inertial() ? this._flickVector() : null;
    if (flick) this._startCoast(flick);
    else this._emit(0, 0);
  }

  _flickVector() {
    if (this.samples.length < 2) return null;
    const first = this.samples[0];
    const last = this.samples[this.samples.length - 1];
    const dtS = (last[0] - first[0]) / 1000;
    // A finger that paused before lifting is a release, not a flick.
    if (dtS <= 0 || performance.now() - last[0] > FLICK_WINDOW_MS) return null;
    const vx = this.vertical ? 0 : (last[1] - first[1]) / dtS;
    const vy = -(last[2] - first[2]) / dtS;
    const speed = Math.hypot(vx, vy);
    if (speed < FLICK_PX_S) return null;
    const m = clamp(speed / FLICK_FULL_PX_S, 0.15, 1);
    return [(vx / speed) * m, (vy / speed) * m];
  }

  _startCoast(v0) {
    const start = performance.now();
    this.el.classList.add("coasting");
    const tick = () => {
      const k = Math.exp(-(performance.now() - start) / 1000 / COAST_TAU_S);
      const m = Math.hypot(v0[0], v0[1]) * k;
      if (m < COAST_MIN || this.disabled) {
        this._stopCoast();
        this._emit(0, 0);
        return;
      }
      this._emit(round3(v0[0] * k), round3(v0[1] * k));
    };
    tick();
    this.coastTimer = setInterval(tick, COAST_TICK_MS);
  }

  _stopCoast() {
    if (this.coastTimer !== null) {
      clearInterval(this.coastTimer);
      this.coastTimer = null;
    }
    this.el.classList.remove("coasting");
  }

  _render(dxPx, dyPx) {
    this.knob.style.transform = `translate(${dxPx}px, ${dyPx}px)`;
  }

  _emitShaped(nx, ny) {
    const { deadzone, expo } = this.shape();
    if (this.vertical) this._emit(0, shapeAxis(ny, deadzone, expo));
    else {
      const [x, y] = shapeRadial(nx, ny, deadzone, expo);
      this._emit(x, y);
    }
  }

  _emit(x, y) {
    this.deflection = [x, y];
    if (this.vertical) this.onChange({ [this.axes[0]]: y });
    else this.onChange({ [this.axes[0]]: x, [this.axes[1]]: y });
  }
}

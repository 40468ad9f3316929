// Gamepad jogging through the browser Gamepad API (standard mapping).
//
// Left stick: X and Y; right stick vertical: Z; LB / RB (buttons 4 / 5): speed down / up.
// With the dead-man option on, nothing moves unless the chosen button is held. After any reset
// (stop, blur, alarm) the sticks must come back to centre before they can move the machine again,
// so a stick left deflected never restarts a jog by itself.

import { shapeAxis, shapeRadial } from "./shaping.js";

const POLL_MS = 30;
const SPEED_DOWN_BUTTON = 4;
const SPEED_UP_BUTTON = 5;

function pressed(pad, index) {
  const b = pad.buttons?.[index];
  if (!b) return false;
  return typeof b === "number" ? b > 0.5 : Boolean(b.pressed || b.value > 0.5);
}

export class GamepadJog {
  /** settings(): {deadzone, expo, gpDeadman, gpDeadmanButton}; onSpeedStep(+1 | -1). */
  constructor({ settings, onChange, onSpeedStep, onStatus }) {
    this.settings = settings;
    this.onChange = onChange;
    this.onSpeedStep = onSpeedStep;
    this.onStatus = onStatus;
    this.latched = false;
    this.last = { X: 0, Y: 0, Z: 0 };
    this.prevButtons = new Set();
    this.padId = null;
    setInterval(() => this.poll(), POLL_MS);
  }

  /** Zero the contribution and wait for the sticks to return to centre. */
  reset() {
    this.latched = true;
    this._emit({ X: 0, Y: 0, Z: 0 });
  }

  _pad() {
    const pads = navigator.getGamepads ? navigator.getGamepads() : [];
    for (const p of pads || []) if (p && p.connected !== false) return p;
    return null;
  }

  poll() {
    const pad = document.visibilityState === "visible" ? this._pad() : null;
    if (!pad) {
      if (this.padId !== null) {
        this.padId = null;
        this.onStatus(null);
      }
      this._emit({ X: 0, Y: 0, Z: 0 });
      return;
    }
    if (pad.id !== this.padId) {
      this.padId = pad.id;
      this.onStatus(pad.id);
    }
    const s = this.settings();
    const ax = pad.axes || [];
    // Gamepad Y axes point down; the machine's +Y and +Z are up.
    const [x, y] = shapeRadial(ax[0] || 0, -(ax[1] || 0), s.deadzone, s.expo);
    const z = shapeAxis(-(ax[3] || 0), s.deadzone, s.expo);
    let out = { X: x, Y: y, Z: z };
    const centred = x === 0 && y === 0 && z === 0;
    if (this.latched) {
      if (centred) this.latched = false;
      else out = { X: 0, Y: 0, Z: 0 };
    }
    if (s.gpDeadman && !pressed(pad, s.gpDeadmanButton)) out = { X: 0, Y: 0, Z: 0 };
    this._buttons(pad);
    this._emit(out);
  }

  _buttons(pad) {
    const now = new Set();
    for (const i of [SPEED_DOWN_BUTTON, SPEED_UP_BUTTON]) if (pressed(pad, i)) now.add(i);
    // Act on the press, not while held.
    if (now.has(SPEED_UP_BUTTON) && !this.prevButtons.has(SPEED_UP_BUTTON)) this.onSpeedStep(1);
    if (now.has(SPEED_DOWN_BUTTON) && !this.prevButtons.has(SPEED_DOWN_BUTTON)) {
      this.onSpeedStep(-1);
    }
    this.prevButtons = now;
  }

  _emit(out) {
    if (out.X === this.last.X && out.Y === this.last.Y && out.Z === this.last.Z) return;
    this.last = out;
    this.onChange(out);
  }
}

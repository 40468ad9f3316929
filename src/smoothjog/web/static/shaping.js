// Stick shaping: radial deadzone and expo curve, shared by the touch sticks and the gamepad.

/** Clamp v into [lo, hi]. */
export function clamp(v, lo, hi) {
  return Math.min(hi, Math.max(lo, v));
}

/** Round to 3 decimals: finer than any hand can aim, and keeps messages short. */
export function round3(v) {
  const r = Math.round(v * 1000) / 1000;
  return Object.is(r, -0) ? 0 : r;
}

/** Expo curve on a magnitude t in [0, 1]: blend of linear and cubic, fine near centre. */
export function expoCurve(t, expo) {
  return (1 - expo) * t + expo * t * t * t;
}

/**
 * Radial deadzone then expo on a 2-D deflection (x right, y up), each in [-1, 1].
 * The direction is kept; only the length is reshaped, so diagonals stay diagonal.
 */
export function shapeRadial(x, y, deadzone, expo) {
  const r = Math.hypot(x, y);
  if (r <= deadzone || r === 0) return [0, 0];
  const rc = Math.min(r, 1);
  const t = (rc - deadzone) / (1 - deadzone);
  const m = expoCurve(t, expo);
  return [round3((x / r) * m), round3((y / r) * m)];
}

/** Deadzone then expo on a single axis in [-1, 1]. */
export function shapeAxis(v, deadzone, expo) {
  const a = Math.abs(v);
  if (a <= deadzone) return 0;
  const t = (Math.min(a, 1) - deadzone) / (1 - deadzone);
  return round3(Math.sign(v) * expoCurve(t, expo));
}

// Pendant settings kept in this browser's localStorage (keys, stick shaping, gamepad, language).

import { DEFAULT_KEYS } from "./keys.js";

const STORAGE_KEY = "smoothjog.pendant.v1";

export const DEFAULTS = {
  keys: { ...DEFAULT_KEYS },
  deadzone: 0.08,
  expo: 0.4,
  gpDeadman: false,
  gpDeadmanButton: 6,
  speedPercent: 25,
  stepIndex: 2,
  inertial: false,
  language: "",
};

function num(v, lo, hi, fallback) {
  const n = Number(v);
  return Number.isFinite(n) && n >= lo && n <= hi ? n : fallback;
}

/** Read the stored settings; anything missing or out of range falls back to its default. */
export function loadSettings() {
  let raw = {};
  try {
    raw = JSON.parse(localStorage.getItem(STORAGE_KEY) || "{}") || {};
  } catch {
    raw = {};
  }
  const keys = { ...DEFAULT_KEYS };
  for (const action of Object.keys(DEFAULT_KEYS)) {
    if (typeof raw.keys?.[action] === "string") keys[action] = raw.keys[action];
  }
  return {
    keys,
    deadzone: num(raw.deadzone, 0, 0.5, DEFAULTS.deadzone),
    expo: num(raw.expo, 0, 1, DEFAULTS.expo),
    gpDeadman: Boolean(raw.gpDeadman),
    gpDeadmanButton: num(raw.gpDeadmanButton, 0, 31, DEFAULTS.gpDeadmanButton),
    speedPercent: num(raw.speedPercent, 1, 100, DEFAULTS.speedPercent),
    // Until the user picks a speed here, the server's [jog] default_speed is used.
    speedChosen: num(raw.speedPercent, 1, 100, null) !== null,
    stepIndex: num(raw.stepIndex, 0, 3, DEFAULTS.stepIndex),
    inertial: Boolean(raw.inertial),
    language: typeof raw.language === "string" ? raw.language : "",
  };
}

export function saveSettings(settings) {
  // A speed the user never picked is not stored, so the server's default keeps applying.
  const { speedChosen, ...kept } = settings;
  if (!speedChosen) delete kept.speedPercent;
  try {
    localStorage.setItem(STORAGE_KEY, JSON.stringify(kept));
  } catch {
    // Private browsing may refuse storage; the settings then last for this page only.
  }
}

// The pendant page: wires the inputs to the mixer and the connection, and renders the view.

import { Connection } from "./conn.js";
import { SpeedPlot, TopView } from "./draw.js";
import { GamepadJog } from "./gamepad.js";
import { DEFAULT_KEYS, KEY_ACTIONS, KeyJog } from "./keys.js";
import { JogMixer } from "./mixer.js";
import { loadSettings, saveSettings } from "./settings.js";
import { Stick } from "./stick.js";

const $ = (id) => document.getElementById(id);
const MM_PER_INCH = 25.4;
const STEP_SIZES = { mm: [0.01, 0.1, 1, 10], inch: [0.001, 0.01, 0.1, 1] };
const SPEED_PRESETS = [1, 2, 5, 10, 25, 50, 75, 100];
const CONTROLLER_FLAG = "smoothjog.pendant.controller";

const settings = loadSettings();
let view = null;
let role = null;
let controlled = false;
let connected = false;
let canJog = false;
let units = "mm";
let droAxes = "";
let stepUnits = "";
let noticeTimer = null;

const conn = new Connection({ onMessage, onOpen, onClose });
const mixer = new JogMixer((m) => conn.send(m));
mixer.setSpeed(settings.speedPercent / 100);

const shape = () => ({ deadzone: settings.deadzone, expo: settings.expo });
const inertial = () => settings.inertial;
const sticks = [
  new Stick($("stick-xy"), { axes: ["X", "Y"], onChange: (c) => mixer.set("xy", c), shape, inertial }),
  new Stick($("stick-z"), { axes: ["Z"], onChange: (c) => mixer.set("z", c), shape, inertial }),
];
const keys = new KeyJog({
  bindings: () => settings.keys,
  onChange: (c) => mixer.set("keys", c),
  onStop: () => stopAll(),
});
const gamepad = new GamepadJog({
  settings: () => settings,
  onChange: (c) => mixer.set("pad", c),
  onSpeedStep: (dir) => stepSpeed(dir),
  onStatus: (text) => {
    $("gamepad-status").textContent = text;
  },
});
const topView = new TopView($("topview"));
const plot = new SpeedPlot($("plot"));

mixer.onActivity = (on) => {
  document.body.classList.toggle("jogging", on);
};

/** Stop now (STOP button, Escape): a stop message even if nothing was held. */
function stopAll() {
  mixer.stopAll();
  resetInputs();
}

/** Release every input; a stop is sent only if a jog was held. */
function releaseAll() {
  if (mixer.active) mixer.stopAll();
  resetInputs();
}

function resetInputs() {
  for (const s of sticks) s.reset();
  keys.reset();
  gamepad.reset();
}

// Leaving the page in any way ends every hold: the key-up or finger-lift may never arrive.
window.addEventListener("blur", releaseAll);
window.addEventListener("pagehide", releaseAll);
document.addEventListener("visibilitychange", () => {
  if (document.visibilityState !== "visible") releaseAll();
});

// -- connection -------------------------------------------------------------------------------

function onOpen() {
  connected = true;
  const pill = $("conn");
  pill.textContent = "connected";
  pill.className = "pill conn-up";
  refresh();
}

function onClose() {
  connected = false;
  role = null;
  const pill = $("conn");
  pill.textContent = "reconnecting";
  pill.className = "pill conn-down";
  refresh();
}

function onMessage(msg) {
  if (msg.type === "view") {
    view = msg;
    render();
    refresh();
  } else if (msg.type === "role") {
    onRole(msg);
  } else if (msg.type === "error") {
    showNotice(String(msg.text));
  }
}

function onRole(msg) {
  const previous = role;
  role = msg.role === "controller" ? "controller" : "watcher";
  controlled = Boolean(msg.controlled);
  if (Number.isFinite(msg.deadman_s) && msg.deadman_s > 0) {
    // Several heartbeats fit in one dead-man window, so one late timer does not stop the jog.
    mixer.heartbeatMs = Math.min(40, (msg.deadman_s * 1000) / 4);
  }
  if (role === "controller") sessionStorage.setItem(CONTROLLER_FLAG, "1");
  else if (previous === "controller") sessionStorage.removeItem(CONTROLLER_FLAG);
  else if (!controlled && sessionStorage.getItem(CONTROLLER_FLAG)) {
    // This tab was in control before a reload; take it back once the old socket is gone.
    conn.send({ type: "take_control" });
  }
  const pill = $("role");
  pill.textContent = role === "controller" ? "in control" : "watching";
  $("take-control").hidden = role === "controller";
  refresh();
}

function showNotice(text) {
  const el = $("notice");
  el.textContent = text;
  el.hidden = false;
  clearTimeout(noticeTimer);
  noticeTimer = setTimeout(() => {
    el.hidden = true;
  }, 5000);
}

// -- enabling ---------------------------------------------------------------------------------

function refresh() {
  const isController = connected && role === "controller";
  const allowed = isController && view !== null && view.can_jog === true;
  if (allowed !== canJog) {
    canJog = allowed;
    if (!allowed) releaseAll();
    mixer.setEnabled(allowed);
    for (const s of sticks) s.setDisabled(!allowed);
    for (const b of document.querySelectorAll("[data-jog]")) b.disabled = !allowed;
    document.body.classList.toggle("jog-disabled", !allowed);
  }
  $("stop").disabled = !isController;
  let reason = "";
  if (!connected) reason = "Not connected to smoothjog; reconnecting…";
  else if (role === "watcher") {
    reason = controlled
      ? "Watching only: another pendant is in control."
      : "Watching only: nobody is in control. Press Take control to jog.";
  } else if (view === null) reason = "Waiting for the machine…";
  else if (view.can_jog !== true) {
    reason = view.reason ? String(view.reason) : `Jogging is disabled while the machine is in ${view.state}.`;
  }
  const el = $("reason");
  el.textContent = reason;
  el.hidden = reason === "";
}

// -- rendering --------------------------------------------------------------------------------

function fmtLen(mm) {
  if (!Number.isFinite(mm)) return "—";
  return units === "inch" ? (mm / MM_PER_INCH).toFixed(4) : mm.toFixed(3);
}

function fmtLenUnit(mm) {
  return units === "inch" ? `${+(mm / MM_PER_INCH).toFixed(4)} in` : `${+mm.toFixed(3)} mm`;
}

function render() {
  units = view.units === "inch" ? "inch" : "mm";
  const axes = Array.isArray(view.axes) ? view.axes.map(String) : ["X", "Y", "Z"];
  mixer.axes = axes;

  const state = String(view.state ?? "?");
  const st = $("state");
  st.textContent = view.substate !== null && view.substate !== undefined && view.substate !== ""
    ? `${state}:${view.substate}`
    : state;
  st.className = `state s-${state.toLowerCase()}`;

  if (axes.join() !== droAxes) {
    droAxes = axes.join();
    const body = $("dro-body");
    body.replaceChildren();
    for (const a of axes) {
      const tr = document.createElement("tr");
      tr.innerHTML = `<td class="ax"></td><td class="w"></td><td class="m"></td><td class="sp"></td>`;
      tr.children[0].textContent = a;
      tr.children[1].setAttribute("aria-label", `${a} work position`);
      tr.children[2].setAttribute("aria-label", `${a} machine position`);
      tr.children[3].setAttribute("aria-label", `${a} predicted stop point`);
      body.append(tr);
    }
  }
  const rows = $("dro-body").children;
  axes.forEach((a, i) => {
    const cells = rows[i].children;
    cells[1].textContent = fmtLen(view.wpos?.[i]);
    cells[2].textContent = fmtLen(view.mpos?.[i]);
    cells[3].textContent = view.stop_point_mpos ? fmtLen(view.stop_point_mpos[i]) : "—";
  });

  const perMin = units === "inch" ? "in/min" : "mm/min";
  const scale = units === "inch" ? 60 / MM_PER_INCH : 60;
  $("units").textContent = units === "inch" ? "inch" : "mm";
  for (const u of document.querySelectorAll(".dro .u")) u.textContent = units === "inch" ? "in" : "mm";
  $("feed").textContent = Number.isFinite(view.feed_mm_min)
    ? `${Math.round((view.feed_mm_min / 60) * scale)} ${perMin}`
    : "—";
  const q = view.queue;
  $("queue").textContent = q ? `${q.blocks ?? 0} blk, ${fmtLenUnit(q.queued_mm ?? 0)}` : "—";
  $("firmware").textContent = String(view.firmware ?? "");

  const fault = view.fault;
  $("fault").hidden = !fault;
  if (fault) {
    $("fault-text").textContent = String(fault.text ?? "");
    $("fault-hint").textContent = fault.hint ? String(fault.hint) : "";
  }

  if (view.speed_ratios) {
    for (const a of ["X", "Y", "Z"]) {
      const input = $(`ratio-${a}`);
      const v = view.speed_ratios[a];
      if (input && document.activeElement !== input && Number.isFinite(v)) input.value = String(v);
    }
  }
  if (units !== stepUnits) buildStepSizes();

  topView.draw(view, fmtLenUnit);
  plot.add(view.t_s, view.commanded_speed_mm_s, view.actual_speed_mm_s);
  plot.draw(scale, perMin);
}

// -- controls ---------------------------------------------------------------------------------

function setSpeedPercent(p) {
  settings.speedPercent = Math.min(100, Math.max(1, Math.round(p)));
  $("speed").value = String(settings.speedPercent);
  $("speed-out").textContent = `${settings.speedPercent} %`;
  mixer.setSpeed(settings.speedPercent / 100);
  saveSettings(settings);
}

function stepSpeed(dir) {
  const cur = settings.speedPercent;
  const next = dir > 0 ? SPEED_PRESETS.find((p) => p > cur) : [...SPEED_PRESETS].reverse().find((p) => p < cur);
  if (next !== undefined) setSpeedPercent(next);
}

function buildStepSizes() {
  stepUnits = units;
  const box = $("step-sizes");
  box.replaceChildren();
  STEP_SIZES[units].forEach((size, i) => {
    const b = document.createElement("button");
    b.type = "button";
    b.setAttribute("role", "radio");
    b.setAttribute("aria-checked", String(i === settings.stepIndex));
    const label = units === "inch" ? `${size} in` : `${size} mm`;
    b.setAttribute("aria-label", `Step size ${label}`);
    b.textContent = String(size);
    b.addEventListener("click", () => {
      settings.stepIndex = i;
      saveSettings(settings);
      buildStepSizes();
    });
    box.append(b);
  });
  const size = STEP_SIZES[units][settings.stepIndex];
  $("step-size-out").textContent = units === "inch" ? `${size} in` : `${size} mm`;
}

for (const b of document.querySelectorAll("button.step")) {
  b.addEventListener("click", () => {
    if (!canJog) return;
    const size = STEP_SIZES[units][settings.stepIndex];
    const distMm = (units === "inch" ? size * MM_PER_INCH : size) * Number(b.dataset.sign);
    conn.send({ type: "step", axis: b.dataset.axis, dist_mm: Math.round(distMm * 1e4) / 1e4 });
  });
}

$("stop").addEventListener("click", stopAll);
$("take-control").addEventListener("click", () => conn.send({ type: "take_control" }));
$("speed").addEventListener("input", (e) => setSpeedPercent(Number(e.target.value)));
$("inertial").checked = settings.inertial;
$("inertial").addEventListener("change", (e) => {
  settings.inertial = e.target.checked;
  saveSettings(settings);
});

for (const a of ["X", "Y", "Z"]) {
  $(`ratio-${a}`).addEventListener("change", () => {
    const ratios = {};
    for (const b of ["X", "Y", "Z"]) {
      const v = Number($(`ratio-${b}`).value);
      if (!(v > 0 && v <= 1)) {
        showNotice(`Speed ratio ${b} must be above 0 and at most 1.`);
        return;
      }
      ratios[b] = v;
    }
    conn.send({ type: "ratios", ratios });
  });
}

// -- settings panel ---------------------------------------------------------------------------

function buildKeyBindings() {
  const box = $("key-bindings");
  box.replaceChildren();
  for (const [action] of KEY_ACTIONS) {
    const b = document.createElement("button");
    b.type = "button";
    const code = settings.keys[action];
    b.textContent = `${action}: ${code}`;
    b.setAttribute("aria-label", `Key for ${action.replace("+", " plus").replace("-", " minus")}: ${code}. Press to change.`);
    b.addEventListener("click", () => {
      b.textContent = `${action}: press a key…`;
      b.classList.add("listening");
      keys.captureNext((newCode) => {
        if (newCode) settings.keys[action] = newCode;
        saveSettings(settings);
        buildKeyBindings();
      });
    });
    box.append(b);
  }
}

$("keys-reset").addEventListener("click", () => {
  settings.keys = { ...DEFAULT_KEYS };
  saveSettings(settings);
  buildKeyBindings();
});

function bindNumber(id, key, lo, hi) {
  const input = $(id);
  input.value = String(settings[key]);
  input.addEventListener("change", () => {
    const v = Number(input.value);
    if (Number.isFinite(v) && v >= lo && v <= hi) {
      settings[key] = v;
      saveSettings(settings);
    } else {
      input.value = String(settings[key]);
      showNotice(`${id.replace("set-", "")} must be between ${lo} and ${hi}.`);
    }
  });
}

bindNumber("set-deadzone", "deadzone", 0, 0.5);
bindNumber("set-expo", "expo", 0, 1);
bindNumber("set-gp-deadman-button", "gpDeadmanButton", 0, 31);
$("set-gp-deadman").checked = settings.gpDeadman;
$("set-gp-deadman").addEventListener("change", (e) => {
  settings.gpDeadman = e.target.checked;
  saveSettings(settings);
});

buildKeyBindings();
buildStepSizes();
setSpeedPercent(settings.speedPercent);
for (const s of sticks) s.setDisabled(true);
for (const b of document.querySelectorAll("[data-jog]")) b.disabled = true;
refresh();
conn.connect();

// The pendant page: wires the inputs to the mixer and the connection, and renders the view.

import { Connection } from "./conn.js";
import { SpeedPlot, TopView } from "./draw.js";
import { GamepadJog } from "./gamepad.js";
import { LANGUAGES, applyStrings, language, pickLanguage, setLanguage, t, translateServer } from "./i18n.js";
import { DEFAULT_KEYS, KEY_ACTIONS, KeyJog } from "./keys.js";
import { JogMixer } from "./mixer.js";
import { loadSettings, saveSettings } from "./settings.js";
import { Stick } from "./stick.js";

const $ = (id) => document.getElementById(id);
const MM_PER_INCH = 25.4;
const STEP_SIZES = { mm: [0.01, 0.1, 1, 10], inch: [0.001, 0.01, 0.1, 1] };
const SPEED_PRESETS = [1, 2, 5, 10, 25, 50, 75, 100];
const CONTROLLER_FLAG = "smoothjog.pendant.controller";
const CONSOLE_HISTORY = 50;
const CONSOLE_LOG_LINES = 200;
const FEED_STEPS = ["-10", "-1", "reset", "+1", "+10"];
const RAPID_STEPS = ["25", "50", "100"];
/** How long the status line tells who stopped the machine (s, by the view's clock). */
const STOP_SHOWN_S = 10;

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
let everOpen = false;
/** performance.now() when the current view arrived: the server's time now is view.t_s plus
 * what passed since (an idle view is not resent when only its t_s changes). */
let viewAtMs = 0;
let stopTimer = null;
let commandId = 0;
let zeroAxes = "";
let wcsList = "";
const pending = new Map();
const history = [];
let historyAt = 0;

const conn = new Connection({ onMessage, onOpen, onClose, onFrozen, onLink });
const mixer = new JogMixer(
  (m) => conn.send(m),
  () => conn.drop(),
);
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
  onStatus: (id) => {
    gamepadId = id;
    showGamepad();
  },
});
let gamepadId = null;
function showGamepad() {
  $("gamepad-status").textContent = gamepadId ? t("gamepad.some", { id: gamepadId }) : t("gamepad.none");
}
const topView = new TopView($("topview"));
topView.gridLabel = (len) => t("top.grid", { len });
topView.onFollowChange = (on) => {
  $("follow").checked = on;
};
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
  everOpen = true;
  refresh();
}

function onClose() {
  connected = false;
  role = null;
  for (const [id, entry] of pending) {
    logConsole(entry.text, "err", t("result.failed", { command: entry.text, error: t("reason.offline") }));
    pending.delete(id);
  }
  refresh();
}

/** The link worker stopped a held jog because this page's own thread stalled past its gate. */
function onFrozen(silentMs) {
  mixer.trip();
  showNotice(t("notice.frozen", { ms: Math.round(silentMs) }));
}

/** The link's figures, once a second: the round trip, and this page's longest pause. */
function onLink(figures) {
  const pill = $("link");
  if (!figures.connected || figures.rttMs === null) {
    pill.textContent = "—";
    pill.className = "pill link";
    return;
  }
  const ms = Math.round(figures.rttMs);
  pill.textContent = t("link.rtt", { ms });
  // Good while a round trip fits in a heartbeat period, bad beyond half the dead-man window.
  const quality = ms <= 40 ? "good" : ms <= 75 ? "slow" : "bad";
  pill.className = `pill link link-${quality}`;
  pill.title = t("link.detail", {
    ms,
    max: Math.round(figures.rttMaxMs),
    page: Math.round(figures.worstPageGapMs),
  });
  pill.dataset.rttMs = String(ms);
  pill.dataset.pageGapMs = String(Math.round(figures.worstPageGapMs));
  pill.dataset.beatGapMs = String(Math.round(figures.worstBeatGapMs));
  pill.dataset.pageStalls = String(figures.pageStallsOverWindow);
}

function onMessage(msg) {
  if (msg.type === "view") {
    if (!settings.speedChosen && Number.isFinite(msg.default_speed) && msg.default_speed > 0) {
      // No speed picked in this browser yet: start at the machine's [jog] default_speed.
      const percent = Math.round(msg.default_speed * 100);
      if (percent !== settings.speedPercent) setSpeedPercent(percent, { byUser: false });
    }
    view = msg;
    viewAtMs = performance.now();
    render();
    refresh();
    scheduleStopExpiry();
  } else if (msg.type === "role") {
    onRole(msg);
  } else if (msg.type === "error") {
    // The server's dead-man stopped the held jog: it must not restart under the finger.
    if (msg.code === "deadman") mixer.trip();
    // Some page (this one too) stopped the machine: a jog held here must be pressed again.
    if (msg.code === "stopped") mixer.trip({ byOther: true });
    showNotice(translateServer(String(msg.text)));
  } else if (msg.type === "result") {
    onResult(msg);
  }
}

function onRole(msg) {
  const previous = role;
  role = msg.role === "controller" ? "controller" : "watcher";
  controlled = Boolean(msg.controlled);
  if (Number.isFinite(msg.deadman_s) && msg.deadman_s > 0) {
    // Several heartbeats fit in one dead-man window, so one late timer does not stop the jog.
    conn.setWindow(msg.deadman_s * 1000);
  }
  if (role === "controller") sessionStorage.setItem(CONTROLLER_FLAG, "1");
  else if (previous === "controller") sessionStorage.removeItem(CONTROLLER_FLAG);
  else if (!controlled && sessionStorage.getItem(CONTROLLER_FLAG)) {
    // This tab was in control before a reload; take it back once the old socket is gone.
    conn.send({ type: "take_control" });
  }
  const pill = $("role");
  pill.dataset.i18n = role === "controller" ? "role.controller" : "role.watcher";
  pill.textContent = t(pill.dataset.i18n);
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

/** The controller's link is lost (smoothjog runs, the machine does not answer it). */
function linkLost() {
  return view !== null && (view.link === "lost" || view.state === "Lost");
}

function refresh() {
  const isController = connected && role === "controller";
  refreshJog(isController && view !== null && view.can_jog === true && !linkLost());
  // STOP works from every page, watcher or not: stopping is never unsafe.
  $("stop").disabled = !connected;
  document.body.classList.toggle("watcher", connected && role === "watcher");
  refreshCommands();
  for (const el of document.querySelectorAll("#speed, .ratio, #inertial, #step-sizes button")) {
    el.disabled = !isController;
  }
  showConn();
  $("dro-table").classList.toggle("stale", !connected || linkLost());
  const [text, kind] = statusLine();
  const status = $("status");
  status.className = `status status-${kind}`;
  $("status-text").textContent = text;
  status.title = text;
  showOffer();
}

function refreshJog(allowed) {
  if (allowed === canJog) return;
  canJog = allowed;
  if (!allowed) releaseAll();
  mixer.setEnabled(allowed);
  for (const s of sticks) s.setDisabled(!allowed);
  for (const b of document.querySelectorAll("[data-jog]")) b.disabled = !allowed;
  document.body.classList.toggle("jog-disabled", !allowed);
}

/** The connection pill: this page's WebSocket, and the controller's link behind smoothjog. */
function showConn() {
  const lost = connected && linkLost();
  let key = everOpen ? "conn.down" : "conn.connecting";
  if (connected) key = lost ? "conn.lost" : "conn.up";
  const pill = $("conn");
  pill.dataset.i18n = key;
  pill.textContent = t(key);
  pill.className = `pill ${connected ? (lost ? "conn-lost" : "conn-up") : "conn-down"}`;
  if (lost) pill.title = t("conn.lost.title");
  else pill.removeAttribute("title");
}

/**
 * Why a machine command cannot run now, in words, or null when it may.
 *
 * The server says it per command (control.commands: name -> null or a reason); an older one
 * sends only can_command, one rule for all (and home only with homing on).
 */
function commandBlock(name) {
  if (!connected) return t("reason.offline");
  if (role !== "controller") return controlled ? t("reason.watch.other") : t("reason.watch.nobody");
  const control = view?.control;
  if (!control) return t("reason.waiting");
  const commands = control.commands;
  if (commands && typeof commands === "object" && Object.hasOwn(commands, name)) {
    return commands[name] === null ? null : translateServer(String(commands[name]));
  }
  if (control.can_command !== true) {
    return control.reason ? translateServer(String(control.reason)) : t("cmd.unavailable");
  }
  if (name === "home" && control.homing !== true) return t("cmd.nohoming");
  return null;
}

/** Enable each machine control by its own command; a disabled one says why in its tooltip. */
function refreshCommands() {
  for (const el of document.querySelectorAll("[data-cmd], [data-offer]")) {
    const why = commandBlock(el.dataset.cmd || el.dataset.offer);
    el.disabled = why !== null;
    if (why !== null) el.title = why;
    else el.removeAttribute("title");
  }
}

/** The commands the status line offers beside its message, in the server's order. */
function offered() {
  if (!connected || view === null) return [];
  const offer = view.control?.offer;
  if (Array.isArray(offer)) return offer.map(String);
  // An older server offers nothing itself: in Alarm, home (with homing on) and unlock.
  if (view.state !== "Alarm") return [];
  return view.control?.homing === true ? ["home", "unlock"] : ["unlock"];
}

function showOffer() {
  const offer = offered();
  let shown = 0;
  for (const b of document.querySelectorAll("#status-actions [data-offer]")) {
    const at = offer.indexOf(b.dataset.offer);
    b.hidden = at < 0;
    b.style.order = String(at);
    if (at >= 0) shown += 1;
  }
  $("status-actions").hidden = shown === 0;
}

/** The stop of the view while it is recent (STOP_SHOWN_S), else null. */
function recentStop() {
  const stop = view?.stop;
  if (!stop || typeof stop !== "object" || !stop.text) return null;
  return stopAgeS(stop) < STOP_SHOWN_S ? stop : null;
}

function stopAgeS(stop) {
  const at = Number(stop.t_s);
  if (!Number.isFinite(at) || !Number.isFinite(view.t_s)) return 0;
  return view.t_s + (performance.now() - viewAtMs) / 1000 - at;
}

/** An idle machine sends no new view when the stop grows old: look again when it does. */
function scheduleStopExpiry() {
  clearTimeout(stopTimer);
  const stop = recentStop();
  if (stop === null) return;
  stopTimer = setTimeout(refresh, (STOP_SHOWN_S - stopAgeS(stop)) * 1000 + 50);
}

/** The one status line: [text, kind]; a fault, who stopped, watching, why not, or ready. */
function statusLine() {
  if (!connected) return [t("reason.offline"), "warn"];
  if (view === null) {
    return role === "watcher" ? [watchingText(), "warn"] : [t("reason.waiting"), "warn"];
  }
  if (view.fault) {
    const hint = view.fault.hint ? ` ${translateServer(String(view.fault.hint))}` : "";
    return [translateServer(String(view.fault.text ?? "")) + hint, "bad"];
  }
  const stop = recentStop();
  if (stop !== null) return [translateServer(String(stop.text)), "warn"];
  if (role === "watcher") return [watchingText(), "warn"];
  if (linkLost()) return [view.reason ? translateServer(String(view.reason)) : t("reason.lost"), "bad"];
  if (view.can_jog !== true) {
    const shownState = t(`st.${view.state}`);
    const text = view.reason ? translateServer(String(view.reason)) : t("reason.state", { state: shownState });
    return [text, "warn"];
  }
  // Jogging may go, but with care (an unhomed machine after an unlock).
  if (view.warning) return [translateServer(String(view.warning)), "warn"];
  return [t("status.ready"), "ok"];
}

function watchingText() {
  return controlled ? t("reason.watch.other") : t("reason.watch.nobody");
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
  renderControl(view.control);
  const axes = Array.isArray(view.axes) ? view.axes.map(String) : ["X", "Y", "Z"];
  mixer.axes = axes;

  const state = String(view.state ?? "?");
  const st = $("state");
  const shown = t(`st.${state}`) === `st.${state}` ? state : t(`st.${state}`);
  st.textContent = view.substate !== null && view.substate !== undefined && view.substate !== ""
    ? `${shown}:${view.substate}`
    : shown;
  st.className = `state s-${state.toLowerCase()}`;

  if (axes.join() !== droAxes) {
    droAxes = axes.join();
    const body = $("dro-body");
    body.replaceChildren();
    for (const a of axes) {
      const tr = document.createElement("tr");
      tr.innerHTML = `<td class="ax"></td><td class="w"></td><td class="m"></td><td class="sp"></td>`;
      tr.children[0].textContent = a;
      tr.children[1].setAttribute("aria-label", t("dro.work.aria", { axis: a }));
      tr.children[2].setAttribute("aria-label", t("dro.machine.aria", { axis: a }));
      tr.children[3].setAttribute("aria-label", t("dro.stop.aria", { axis: a }));
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
  for (const u of document.querySelectorAll(".dro .u")) u.textContent = units === "inch" ? "in" : "mm";
  $("feed").textContent = Number.isFinite(view.feed_mm_min)
    ? `${Math.round((view.feed_mm_min / 60) * scale)} ${perMin}`
    : "—";
  const q = view.queue;
  $("queue").textContent = q ? t("meta.queue.value", { blocks: q.blocks ?? 0, len: fmtLenUnit(q.queued_mm ?? 0) }) : "—";
  $("firmware").textContent = String(view.firmware ?? "");

  if (view.speed_ratios) {
    for (const a of ["X", "Y", "Z"]) {
      const input = $(`ratio-${a}`);
      const v = view.speed_ratios[a];
      if (input && document.activeElement !== input && Number.isFinite(v)) input.value = String(v);
    }
  }
  const stepKey = `${units}|${settings.stepIndex}|${JSON.stringify(view.control?.steps_per_mm ?? null)}`;
  if (stepKey !== stepNoteFor) buildStepSizes();

  topView.draw(view, fmtLenUnit, units === "inch" ? MM_PER_INCH : 1);
  // Reported speed is the controller's own FS feed, not a difference of positions (which jumps
  // with the report's timing); commanded is the jog's speed after the machine's caps.
  const moving = view.moving === true;
  const reported = Number.isFinite(view.feed_mm_min) ? view.feed_mm_min / 60 : null;
  plot.add(view.t_s, moving ? view.commanded_speed_mm_s : 0, moving ? reported : 0);
  const rates = Array.isArray(view.max_rate_mm_min) ? view.max_rate_mm_min.filter(Number.isFinite) : [];
  const topMmS = rates.length ? Math.max(...rates) / 60 : null;
  plot.draw(scale, perMin, topMmS, (unit, s) => t("plot.window", { unit, s }));
}

// -- controls ---------------------------------------------------------------------------------

/** Set the speed; chosen by the user (kept in this browser) unless byUser is false. */
function setSpeedPercent(p, { byUser = true } = {}) {
  settings.speedPercent = Math.min(100, Math.max(1, Math.round(p)));
  $("speed").value = String(settings.speedPercent);
  $("speed-out").textContent = `${settings.speedPercent} %`;
  mixer.setSpeed(settings.speedPercent / 100);
  if (byUser) {
    settings.speedChosen = true;
    saveSettings(settings);
  }
}

function stepSpeed(dir) {
  const cur = settings.speedPercent;
  const next = dir > 0 ? SPEED_PRESETS.find((p) => p > cur) : [...SPEED_PRESETS].reverse().find((p) => p < cur);
  if (next !== undefined) setSpeedPercent(next);
}

let stepNoteFor = "";

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
    b.setAttribute("aria-label", t("steps.size.item", { size: label }));
    b.textContent = String(size);
    b.disabled = !(connected && role === "controller");
    b.addEventListener("click", () => {
      settings.stepIndex = i;
      saveSettings(settings);
      buildStepSizes();
    });
    box.append(b);
  });
  const size = STEP_SIZES[units][settings.stepIndex];
  $("step-size-out").textContent = units === "inch" ? `${size} in` : `${size} mm`;
  for (const b of document.querySelectorAll("button.step")) {
    const sign = Number(b.dataset.sign) > 0 ? t("sign.plus") : t("sign.minus");
    b.setAttribute("aria-label", t("step.aria", { axis: b.dataset.axis, sign }));
  }
  // Say when the machine's resolution rounds the step (0.01 mm at 80 steps/mm moves 0.0125).
  const spm = view?.control?.steps_per_mm;
  const axes = Array.isArray(view?.axes) ? view.axes : [];
  const sizeMm = units === "inch" ? size * MM_PER_INCH : size;
  const notes = [];
  if (Array.isArray(spm)) {
    axes.forEach((a, i) => {
      const perMm = Number(spm[i]);
      if (!(perMm > 0)) return;
      const moved = Math.max(1, Math.round(sizeMm * perMm)) / perMm;
      if (Math.abs(moved - sizeMm) > 1e-9) {
        notes.push(`${a}: ${t("steps.rounded", { size: fmtLenUnit(moved), res: fmtLenUnit(1 / perMm) })}`);
      }
    });
  }
  $("step-note").textContent = notes.join(" · ");
  stepNoteFor = `${units}|${settings.stepIndex}|${JSON.stringify(spm ?? null)}`;
}

for (const b of document.querySelectorAll("button.step")) {
  b.addEventListener("click", () => {
    if (!canJog) return;
    const size = STEP_SIZES[units][settings.stepIndex];
    const distMm = (units === "inch" ? size * MM_PER_INCH : size) * Number(b.dataset.sign);
    conn.send({ type: "step", axis: b.dataset.axis, dist_mm: Math.round(distMm * 1e4) / 1e4 });
  });
}

$("zoom-in").addEventListener("click", () => topView.setZoom(topView.zoom * 2));
$("zoom-out").addEventListener("click", () => topView.setZoom(topView.zoom / 2));
$("zoom-fit").addEventListener("click", () => topView.setZoom(1));
$("follow").addEventListener("change", (e) => {
  topView.follow = e.target.checked;
  topView.redraw();
});

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
        showNotice(t("ratio.bad", { axis: b }));
        // The server keeps the old value: show it again rather than the refused one.
        const kept = view?.speed_ratios?.[b];
        if (Number.isFinite(kept)) $(`ratio-${b}`).value = String(kept);
        return;
      }
      ratios[b] = v;
    }
    conn.send({ type: "ratios", ratios });
  });
}

// -- machine control --------------------------------------------------------------------------

/** Send a machine command; its result comes back as a "result" message with the same id. */
function command(name, args = {}, label = name) {
  commandId += 1;
  pending.set(commandId, { text: label });
  if (!conn.send({ type: "command", name, id: commandId, ...args })) {
    pending.delete(commandId);
    showNotice(t("reason.offline"));
    return;
  }
  logConsole(label, "sent");
}

function onResult(msg) {
  const entry = pending.get(msg.id);
  pending.delete(msg.id);
  for (const line of msg.lines || []) logConsole(String(line), "out");
  if (msg.ok) {
    logConsole(t("console.ok"), "ok");
  } else {
    const what = entry ? entry.text : String(msg.command);
    const error = translateServer(String(msg.error ?? ""));
    logConsole(error, "err");
    showNotice(t("result.failed", { command: what, error }));
  }
}

function logConsole(text, kind) {
  const log = $("console-log");
  const li = document.createElement("li");
  li.className = `c-${kind}`;
  li.textContent = kind === "sent" ? `> ${text}` : text;
  log.append(li);
  while (log.children.length > CONSOLE_LOG_LINES) log.firstElementChild.remove();
  log.scrollTop = log.scrollHeight;
}

function renderControl(control) {
  if (!control) return;
  const axes = Array.isArray(view.axes) ? view.axes.map(String) : ["X", "Y", "Z"];
  if (axes.join() !== zeroAxes) {
    zeroAxes = axes.join();
    const row = $("zero-row");
    row.replaceChildren();
    for (const a of axes) {
      row.append(
        commandButton({ cmd: "zero", i18nDyn: "zero", axis: a }, () =>
          command("zero", { axes: [a] }, t("machine.zero", { axis: a })),
        ),
      );
    }
    row.append(
      commandButton({ cmd: "zero", i18n: "machine.zero.all", i18nAria: "machine.zero.all.aria" }, () =>
        command("zero", { axes }, t("machine.zero.all")),
      ),
      commandButton({ cmd: "goto_zero", i18n: "machine.goto", i18nAria: "machine.goto.aria" }, () =>
        command("goto_zero", {}, t("machine.goto")),
      ),
    );
    labelDynamic();
  }
  const list = Array.isArray(control.wcs_list) ? control.wcs_list.map(String) : [];
  if (list.join() !== wcsList) {
    wcsList = list.join();
    const select = $("wcs");
    select.replaceChildren(...list.map((w) => new Option(w, w)));
  }
  const wcs = String(control.wcs ?? "");
  if (document.activeElement !== $("wcs")) $("wcs").value = wcs;
  $("wcs-now").textContent = wcs;
  const offset = control.offsets?.[wcs];
  $("wcs-offset").textContent = Array.isArray(offset)
    ? t("machine.offset", { values: offset.map((v) => fmtLen(Number(v))).join(", ") })
    : "";
  $("modal").textContent = control.modal ? String(control.modal) : "—";
  const ov = control.overrides ?? {};
  $("ov-feed").textContent = `${ov.feed ?? 100} %`;
  $("ov-rapid").textContent = `${ov.rapid ?? 100} %`;
  $("m-running").textContent = control.running ? t("machine.running", { what: translateServer(String(control.running)) }) : "";
}

/** A machine-command button (enabled only when data.cmd may run); data becomes its data-*. */
function commandButton(data, onClick) {
  const b = document.createElement("button");
  b.type = "button";
  Object.assign(b.dataset, data);
  b.addEventListener("click", onClick);
  return b;
}

/** Labels built from data (axis names): filled again when the language changes. */
function labelDynamic() {
  for (const b of document.querySelectorAll("[data-i18n-dyn=zero]")) {
    b.textContent = t("machine.zero", { axis: b.dataset.axis });
    b.setAttribute("aria-label", t("machine.zero.aria", { axis: b.dataset.axis }));
  }
  for (const b of document.querySelectorAll("[data-ov]")) {
    const kind = t(`machine.ov.${b.dataset.ov}`);
    const step = b.dataset.step === "reset" ? "100 %" : `${b.dataset.step} %`;
    b.textContent = b.dataset.step === "reset" ? "100 %" : b.dataset.step;
    b.setAttribute("aria-label", t("machine.ov.aria", { kind, step }));
  }
  for (const a of ["X", "Y", "Z"]) $(`ratio-${a}`).setAttribute("aria-label", t("ratio.aria", { axis: a }));
  applyStrings($("zero-row"));
}

function buildOverrides() {
  for (const [kind, steps] of [["feed", FEED_STEPS], ["rapid", RAPID_STEPS]]) {
    const box = $(`ov-${kind}-buttons`);
    box.replaceChildren();
    for (const step of steps) {
      const b = commandButton({ cmd: "override", ov: kind, step }, () =>
        command("override", { kind, step }, `${t(`machine.ov.${kind}`)} ${step}`),
      );
      b.className = "tool";
      box.append(b);
    }
  }
}

$("m-home").addEventListener("click", () => command("home", {}, "$H"));
$("alarm-home").addEventListener("click", () => command("home", {}, "$H"));
for (const id of ["m-unlock", "alarm-unlock"]) {
  $(id).addEventListener("click", () => {
    showNotice(t("machine.unlock.warn"));
    command("unlock", {}, "$X");
  });
}
for (const id of ["m-reset", "offer-reset"]) $(id).addEventListener("click", () => command("reset", {}, "Ctrl-X"));
$("m-hold").addEventListener("click", () => command("hold", {}, "!"));
for (const id of ["m-resume", "offer-resume"]) $(id).addEventListener("click", () => command("resume", {}, "~"));
$("wcs").addEventListener("change", (e) => command("wcs", { wcs: e.target.value }, e.target.value));

$("console-form").addEventListener("submit", (e) => {
  e.preventDefault();
  const input = $("console-input");
  const line = input.value.trim();
  if (!line || commandBlock("console") !== null) return;
  if (history[history.length - 1] !== line) history.push(line);
  while (history.length > CONSOLE_HISTORY) history.shift();
  historyAt = history.length;
  input.value = "";
  command("console", { line }, line);
});
$("console-input").addEventListener("keydown", (e) => {
  if (e.key !== "ArrowUp" && e.key !== "ArrowDown") return;
  e.preventDefault();
  historyAt = Math.max(0, Math.min(history.length, historyAt + (e.key === "ArrowUp" ? -1 : 1)));
  e.target.value = history[historyAt] ?? "";
});

// -- language ---------------------------------------------------------------------------------

function applyLanguage(l) {
  setLanguage(l);
  applyStrings();
  labelDynamic();
  buildKeyBindings();
  buildStepSizes();
  showGamepad();
  droAxes = "";
  if (view !== null) render();
  refresh();
}

for (const [code, name] of Object.entries(LANGUAGES)) $("lang").append(new Option(name, code));
$("lang").addEventListener("change", (e) => {
  settings.language = e.target.value;
  saveSettings(settings);
  applyLanguage(e.target.value);
});

// -- settings panel ---------------------------------------------------------------------------

function buildKeyBindings() {
  const box = $("key-bindings");
  box.replaceChildren();
  for (const [action] of KEY_ACTIONS) {
    const b = document.createElement("button");
    b.type = "button";
    const code = settings.keys[action];
    b.textContent = t("settings.key", { action, code });
    b.setAttribute("aria-label", t("settings.key.aria", { action, code }));
    b.addEventListener("click", () => {
      b.textContent = t("settings.key.listen", { action });
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
      showNotice(t("settings.range", { name: id.replace("set-", ""), lo, hi }));
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

buildOverrides();
setLanguage(pickLanguage(settings.language));
$("lang").value = language();
applyLanguage(language());
setSpeedPercent(settings.speedPercent, { byUser: false });
for (const s of sticks) s.setDisabled(true);
for (const b of document.querySelectorAll("[data-jog]")) b.disabled = true;
refresh();
conn.connect();

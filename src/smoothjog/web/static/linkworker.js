// The pendant's link to the server, on a thread of its own: the WebSocket, the heartbeat of a
// held jog, and the link's quality.
//
// Why a worker: on a busy machine the page's own thread stalls (layout, drawing, garbage
// collection, other programs) for 150-300 ms at a time, longer than the server's 150 ms dead-man
// window; a heartbeat timed from that thread then stops a jog the user is still holding. This
// thread has no drawing to do, so its timer keeps time. But a page whose own thread is frozen
// must still stop: the page pings this worker every PING_MS (and every message it sends is a
// ping too); when no ping came for gateMs while a jog is held, the worker sends the stop itself
// and holds nothing more until the page releases (a "frozen" event tells it so). A closed tab
// ends the worker and its socket with it, and the server stops at once; a lost network stops
// the heartbeats, and the server's dead-man does the rest.
//
// Messages from the page: {op: "connect", url}, {op: "send", msg}, {op: "alive"},
// {op: "drop"} (forget the held jog: it was stopped from outside),
// {op: "config", heartbeatMs, gateMs, windowMs}. To the page: {ev: "open"}, {ev: "close"},
// {ev: "message", msg}, {ev: "frozen", silentMs}, {ev: "link", ...figures}.

const LINK_REPORT_MS = 1000;
const PING_EVERY_MS = 1000;
/** Round-trip times kept for the link figure (about the last ten seconds). */
const RTT_KEEP = 10;

let url = null;
let ws = null;
let retryMs = 500;
let heartbeatMs = 30;
let gateMs = 350;
let held = null;
let frozen = false;
let beatTimer = null;
let lastAliveAt = performance.now();
let lastBeatAt = 0;
let pingId = 0;
const pingsSent = new Map();
const rtts = [];
let worstBeatGapMs = 0;
let worstPageGapMs = 0;
/** Pauses of the page's thread longer than the server's window: each would have stopped a jog
 * whose heartbeat came from that thread. */
let pageStallsOverWindow = 0;
let windowMs = 150;

function post(message) {
  self.postMessage(message);
}

function connect() {
  const socket = new WebSocket(url);
  ws = socket;
  socket.addEventListener("open", () => {
    retryMs = 500;
    post({ ev: "open" });
  });
  socket.addEventListener("message", (e) => {
    let msg;
    try {
      msg = JSON.parse(e.data);
    } catch {
      return;
    }
    if (msg && msg.type === "pong") {
      const sentAt = pingsSent.get(msg.id);
      pingsSent.delete(msg.id);
      if (sentAt !== undefined) {
        rtts.push(performance.now() - sentAt);
        if (rtts.length > RTT_KEEP) rtts.shift();
      }
      return;
    }
    post({ ev: "message", msg });
  });
  socket.addEventListener("close", () => {
    if (ws !== socket) return;
    ws = null;
    held = null;
    pingsSent.clear();
    post({ ev: "close" });
    setTimeout(connect, retryMs);
    retryMs = Math.min(retryMs * 2, 4000);
  });
}

function raw(message) {
  if (ws === null || ws.readyState !== WebSocket.OPEN) return false;
  ws.send(JSON.stringify(message));
  return true;
}

function isNeutral(msg) {
  return Object.values(msg.axes || {}).every((v) => v === 0);
}

function alive() {
  const now = performance.now();
  const gapMs = now - lastAliveAt;
  worstPageGapMs = Math.max(worstPageGapMs, gapMs);
  if (gapMs > windowMs) pageStallsOverWindow += 1;
  lastAliveAt = now;
}

function send(msg) {
  alive();
  if (msg.type === "jog") {
    if (frozen && !isNeutral(msg)) return; // the page has not released since the worker stopped
    if (isNeutral(msg)) frozen = false; // a neutral jog is a release too
    held = isNeutral(msg) ? null : msg;
    if (held) lastBeatAt = performance.now();
  } else if (msg.type === "stop") {
    held = null;
    frozen = false;
  }
  raw(msg);
}

function beat() {
  if (held === null) return;
  const now = performance.now();
  const silentMs = now - lastAliveAt;
  if (silentMs > gateMs) {
    // The page's own thread is frozen: stop now rather than hold its jog for it. A neutral jog
    // ends it as a release does (`stop` is the STOP button's, told to every page).
    const axes = Object.fromEntries(Object.keys(held.axes || {}).map((a) => [a, 0]));
    const speed = held.speed;
    held = null;
    frozen = true;
    raw({ type: "jog", axes, speed });
    post({ ev: "frozen", silentMs });
    return;
  }
  if (now - lastBeatAt < heartbeatMs * 0.5) return; // the page just sent one
  worstBeatGapMs = Math.max(worstBeatGapMs, now - lastBeatAt);
  lastBeatAt = now;
  raw(held);
}

function startBeats() {
  if (beatTimer !== null) clearInterval(beatTimer);
  beatTimer = setInterval(beat, heartbeatMs);
}

setInterval(() => {
  if (ws === null || ws.readyState !== WebSocket.OPEN) return;
  pingId = (pingId + 1) % 2 ** 31;
  pingsSent.set(pingId, performance.now());
  // A ping nobody answered within ten seconds is forgotten, so the map cannot grow.
  for (const [id, at] of pingsSent) if (performance.now() - at > 10000) pingsSent.delete(id);
  raw({ type: "ping", id: pingId });
}, PING_EVERY_MS);

setInterval(() => {
  const sorted = [...rtts].sort((a, b) => a - b);
  post({
    ev: "link",
    connected: ws !== null && ws.readyState === WebSocket.OPEN,
    rttMs: sorted.length ? sorted[Math.floor(sorted.length / 2)] : null,
    rttMaxMs: sorted.length ? sorted[sorted.length - 1] : null,
    worstBeatGapMs,
    worstPageGapMs,
    pageStallsOverWindow,
    heartbeatMs,
    gateMs,
  });
}, LINK_REPORT_MS);

self.onmessage = (e) => {
  const m = e.data;
  if (m.op === "connect") {
    url = m.url;
    connect();
  } else if (m.op === "send") {
    send(m.msg);
  } else if (m.op === "alive") {
    alive();
  } else if (m.op === "drop") {
    held = null;
  } else if (m.op === "config") {
    if (Number.isFinite(m.heartbeatMs) && m.heartbeatMs > 0) heartbeatMs = m.heartbeatMs;
    if (Number.isFinite(m.gateMs) && m.gateMs > 0) gateMs = m.gateMs;
    if (Number.isFinite(m.windowMs) && m.windowMs > 0) windowMs = m.windowMs;
    startBeats();
  }
};

startBeats();

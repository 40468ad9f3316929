// The page's side of the link: the WebSocket lives in linkworker.js, this object talks to it.
//
// The page pings the worker every PING_MS from its own thread; the worker holds a jog's
// heartbeat only while those pings come (see linkworker.js for why).

/** How often the page's thread tells the worker it is alive (a stall's gap is it plus this). */
const PING_MS = 20;
/** A held jog stops when the page's thread was silent this long (the worker then stops it):
 * above the 150-300 ms stalls of a busy device, short enough that a frozen page stops soon. */
export const PAGE_GATE_MS = 350;

export class Connection {
  constructor({ onMessage, onOpen, onClose, onFrozen = () => {}, onLink = () => {} }) {
    this.onMessage = onMessage;
    this.onOpen = onOpen;
    this.onClose = onClose;
    this.onFrozen = onFrozen;
    this.onLink = onLink;
    this.isOpen = false;
    this.worker = null;
  }

  connect() {
    const scheme = location.protocol === "https:" ? "wss:" : "ws:";
    // Same host as the page: the server checks the Origin, and the pairing cookie goes along.
    const url = `${scheme}//${location.host}/ws`;
    const worker = new Worker(new URL("./linkworker.js", import.meta.url), { type: "module" });
    this.worker = worker;
    worker.onmessage = (e) => {
      const m = e.data;
      if (m.ev === "open") {
        this.isOpen = true;
        this.onOpen();
      } else if (m.ev === "close") {
        this.isOpen = false;
        this.onClose();
      } else if (m.ev === "message") {
        this.onMessage(m.msg);
      } else if (m.ev === "frozen") {
        this.onFrozen(m.silentMs);
      } else if (m.ev === "link") {
        this.onLink(m);
      }
    };
    worker.postMessage({ op: "config", gateMs: PAGE_GATE_MS });
    worker.postMessage({ op: "connect", url });
    setInterval(() => worker.postMessage({ op: "alive" }), PING_MS);
  }

  /** The server's dead-man window: the worker repeats a held jog five times within it. */
  setWindow(windowMs) {
    const heartbeatMs = Math.min(30, windowMs / 5);
    if (this.worker) {
      this.worker.postMessage({ op: "config", heartbeatMs, gateMs: PAGE_GATE_MS, windowMs });
    }
  }

  get open() {
    return this.isOpen;
  }

  /** Stop repeating the held jog without sending anything (the machine was stopped already). */
  drop() {
    if (this.worker) this.worker.postMessage({ op: "drop" });
  }

  /** Send one message; false when not connected (the caller's intent is then simply lost). */
  send(message) {
    if (!this.isOpen || this.worker === null) return false;
    this.worker.postMessage({ op: "send", msg: message });
    return true;
  }
}

// The jog mixer: sums every input's deflection into one intent and owns the heartbeat and stop.
//
// Each input (XY stick, Z stick, keys, gamepad) sets its own contribution; the mixer sends a jog
// when the sum changes and a neutral jog the moment the sum returns to zero (`stop` is for STOP
// and Escape). The link worker repeats the held jog as the heartbeat (linkworker.js). After a
// trip (the server's dead-man, the worker's stop for a frozen page, a stop from any page)
// nothing moves until every input is released: a jog never restarts by itself under the user's
// finger. A stop is never blocked: stopAll() sends one whether or not this page may jog.

import { clamp, round3 } from "./shaping.js";

/** Never send two jogs closer than this; a pointer can move at 120 Hz. */
const MIN_GAP_MS = 20;

export class JogMixer {
  /** send(message) delivers one JSON message; drop() makes the link forget the held jog. */
  constructor(send, drop = () => {}) {
    this.send = send;
    this.drop = drop;
    this.tripped = false;
    /** What the release after a trip sends: "stop" or "neutral" (see trip). */
    this.releaseWith = "stop";
    this.axes = ["X", "Y", "Z"];
    this.sources = new Map();
    this.enabled = false;
    this.speed = 0.25;
    this.active = false;
    this.last = null;
    this.lastSentAt = 0;
    this.timer = null;
    this.onActivity = () => {};
  }

  /** Allow or forbid motion; forbidding drops every contribution and stops at once. */
  setEnabled(on) {
    if (this.enabled === on) return;
    this.enabled = on;
    if (!on) {
      this.sources.clear();
      this._update();
    }
  }

  /** Set the global speed fraction in (0, 1]; a held jog is resent with it. */
  setSpeed(fraction) {
    this.speed = clamp(fraction, 0.01, 1);
    if (this.active) this._sendJog();
  }

  /** One input's contribution, e.g. set("keys", {X: 1, Y: 0}). */
  set(source, axes) {
    if (!this.enabled) return;
    this.sources.set(source, axes);
    this._update();
  }

  /** Remove one input's contribution (its finger lifted, its key released). */
  clear(source) {
    if (this.sources.delete(source)) this._update();
  }

  /**
   * The jog was stopped from outside the page: hold nothing until every input is released.
   *
   * The link stops repeating the held jog at once (the machine already stopped). The release
   * then tells the server and the worker the trip is over: a stop after the dead-man or the
   * worker's own stop (sent at once when nothing is held). After a stop someone gave (byOther)
   * it is a neutral jog, which ends the server's latch without being a new stop every page is
   * told of; with nothing held nothing is sent, else every page would answer every stop.
   */
  trip({ byOther = false } = {}) {
    this._cancelTimer();
    this.drop();
    const was = this.active;
    this.active = false;
    this.last = null;
    if (was) this.onActivity(false);
    if (this._moving()) {
      // A dead-man trip still pending keeps its stop.
      if (!this.tripped || !byOther) this.releaseWith = byOther ? "neutral" : "stop";
      this.tripped = true;
    } else if (!byOther) {
      this.tripped = false;
      this.send({ type: "stop" });
    }
  }

  /** Drop every contribution and send a stop even if nothing was held (the STOP button). */
  stopAll() {
    this.sources.clear();
    this._cancelTimer();
    this.active = false;
    this.last = null;
    // This stop also ends a trip: the next press jogs again.
    this.tripped = false;
    this.send({ type: "stop" });
    this.onActivity(false);
  }

  total() {
    const out = {};
    for (const axis of this.axes) out[axis] = 0;
    for (const contribution of this.sources.values()) {
      for (const [axis, v] of Object.entries(contribution)) {
        if (axis in out && Number.isFinite(v)) out[axis] += v;
      }
    }
    for (const axis of this.axes) out[axis] = round3(clamp(out[axis], -1, 1));
    return out;
  }

  _moving() {
    return this.enabled && Object.values(this.total()).some((v) => v !== 0);
  }

  _update() {
    const t = this.total();
    const moving = this.enabled && Object.values(t).some((v) => v !== 0);
    if (this.tripped) {
      if (moving) return;
      // Released after a trip: this tells the server and the worker it is over.
      this.tripped = false;
      if (this.releaseWith === "neutral") {
        this._sendNeutral();
      } else {
        this.send({ type: "stop" });
      }
      return;
    }
    if (!moving) {
      if (this.active) {
        // A release is a neutral jog: `stop` is kept for STOP and Escape, which every page is
        // told of even when they come from the page holding the jog.
        this.active = false;
        this.last = null;
        this._cancelTimer();
        this._sendNeutral();
        this.onActivity(false);
      }
      return;
    }
    const changed = !this.last || this.axes.some((a) => this.last[a] !== t[a]);
    this.last = t;
    if (!this.active) {
      this.active = true;
      this.onActivity(true);
      this._sendJog();
    } else if (changed) {
      const wait = this.lastSentAt + MIN_GAP_MS - performance.now();
      if (wait <= 0) this._sendJog();
      else this._arm(wait);
    }
  }

  _sendNeutral() {
    const axes = Object.fromEntries(this.axes.map((a) => [a, 0]));
    this.send({ type: "jog", axes, speed: round3(this.speed) });
  }

  _sendJog() {
    if (!this.last) return;
    this.send({ type: "jog", axes: { ...this.last }, speed: round3(this.speed) });
    this.lastSentAt = performance.now();
  }

  _arm(delayMs) {
    this._cancelTimer();
    // A change that came too soon after the last jog is sent when the gap has passed.
    this.timer = setTimeout(() => {
      this.timer = null;
      if (this.active) this._sendJog();
    }, delayMs);
  }

  _cancelTimer() {
    if (this.timer !== null) {
      clearTimeout(this.timer);
      this.timer = null;
    }
  }
}

// Keyboard hold-to-jog: held keys give full deflection, several at once give a diagonal.
//
// Key auto-repeat is ignored (a repeat is not a new intent), and every key counts as released
// on key-up, when the window loses focus and when the page is hidden, because a key-up that
// happens elsewhere is never delivered here. Escape always stops, even with a modifier held or
// from inside a text field (which it then leaves).

export const KEY_ACTIONS = [
  ["X+", "X", 1],
  ["X-", "X", -1],
  ["Y+", "Y", 1],
  ["Y-", "Y", -1],
  ["Z+", "Z", 1],
  ["Z-", "Z", -1],
];

export const DEFAULT_KEYS = {
  "X+": "ArrowRight",
  "X-": "ArrowLeft",
  "Y+": "ArrowUp",
  "Y-": "ArrowDown",
  "Z+": "PageUp",
  "Z-": "PageDown",
};

function isTextEntry(target) {
  if (!(target instanceof HTMLElement)) return false;
  if (target.isContentEditable) return true;
  if (target instanceof HTMLInputElement) {
    return !["checkbox", "radio", "button", "range"].includes(target.type);
  }
  return target instanceof HTMLTextAreaElement || target instanceof HTMLSelectElement;
}

export class KeyJog {
  /** bindings(): {action: KeyboardEvent.code}; onChange(contribution); onStop() for Escape. */
  constructor({ bindings, onChange, onStop }) {
    this.bindings = bindings;
    this.onChange = onChange;
    this.onStop = onStop;
    this.held = new Set();
    this.capture = null;
    window.addEventListener("keydown", (e) => this._down(e));
    window.addEventListener("keyup", (e) => this._up(e));
    window.addEventListener("blur", () => this.reset());
    document.addEventListener("visibilitychange", () => {
      if (document.visibilityState !== "visible") this.reset();
    });
  }

  /** Release every key (the user must press again to move). */
  reset() {
    if (this.held.size === 0) return;
    this.held.clear();
    this._emit();
  }

  /** Route the next key press to callback(code) instead of jogging (the settings panel). */
  captureNext(callback) {
    this.reset();
    this.capture = callback;
  }

  _action(code) {
    const b = this.bindings();
    for (const [action] of KEY_ACTIONS) if (b[action] === code) return action;
    return null;
  }

  _down(e) {
    const escape = e.code === "Escape" || e.key === "Escape";
    if (this.capture) {
      e.preventDefault();
      const cb = this.capture;
      this.capture = null;
      cb(escape ? null : e.code);
      if (!escape) return;
    }
    if (escape) {
      // Stopping is never unsafe: no field or modifier may keep Escape from it.
      if (isTextEntry(e.target)) e.target.blur();
      this.held.clear();
      this.onStop();
      return;
    }
    if (isTextEntry(e.target) || e.ctrlKey || e.metaKey || e.altKey) return;
    const action = this._action(e.code);
    if (!action) return;
    e.preventDefault(); // arrows and PageUp/PageDown would scroll the page
    if (e.repeat) return;
    this.held.add(action);
    this._emit();
  }

  _up(e) {
    const action = this._action(e.code);
    if (action && this.held.delete(action)) this._emit();
  }

  _emit() {
    const out = { X: 0, Y: 0, Z: 0 };
    for (const [action, axis, sign] of KEY_ACTIONS) {
      if (this.held.has(action)) out[axis] += sign;
    }
    this.onChange(out);
  }
}

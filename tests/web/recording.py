"""A PendantBackend that records every intent with its loop-clock time and serves a scripted view.

It also integrates a crude motion (position follows the held jog, actual speed lags commanded)
so the page has something alive to draw; it models nothing of Grbl.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from smoothjog.authority.gate import StopRecord
from smoothjog.control import CommandResult, ControlRefused
from smoothjog.core.intents import ContinuousIntent, GotoIntent, Intent, StepIntent, StopIntent
from smoothjog.web.protocol import CommandMessage

AXES = ("X", "Y", "Z")
#: The machine commands whose availability the view's control.commands states one by one.
COMMANDS = (
    "unlock",
    "home",
    "reset",
    "zero",
    "wcs",
    "override",
    "console",
    "hold",
    "resume",
    "goto_zero",
)
#: What the status line offers in a scripted state when the test scripts no control: the way
#: out the session offers there (session_backend's _offer, with homing on and no reset needed).
STATE_OFFERS: dict[str, list[str]] = {
    "Alarm": ["home", "unlock"],
    "Hold": ["resume", "reset"],
    "Door": ["resume", "reset"],
    "Sleep": ["reset"],
}


@dataclass(frozen=True)
class Call:
    """One backend call: when (loop clock), which method, with what."""

    t_s: float
    name: str
    args: tuple[object, ...]


def default_view() -> dict[str, object]:
    """A plausible idle machine with soft limits and two keep-out zones."""
    return {
        "t_s": 0.0,
        "firmware": "Grbl 1.1h (recording backend)",
        "axes": list(AXES),
        "state": "Idle",
        "substate": None,
        "link": "up",
        "stop": None,
        "can_jog": True,
        "reason": None,
        "units": "mm",
        "mpos": [-150.0, -100.0, -10.0],
        "wpos": [50.0, 40.0, 5.0],
        "feed_mm_min": 0.0,
        "commanded_speed_mm_s": 0.0,
        "actual_speed_mm_s": 0.0,
        "stop_point_mpos": None,
        "queue": {"queued_mm": 0.0, "blocks": 0, "planner_blocks": 15},
        "fault": None,
        "warning": None,
        "envelope": {"min_mm": [-300.0, -200.0, -80.0], "max_mm": [0.0, 0.0, 0.0]},
        "keepouts": [
            {"name": "vise", "min_mm": [-120.0, -60.0, -80.0], "max_mm": [-60.0, -20.0, 0.0]},
            {"name": "probe", "min_mm": [-290.0, -190.0, -80.0], "max_mm": [-270.0, -170.0, 0.0]},
        ],
        "max_rate_mm_min": [3000.0, 3000.0, 1000.0],
        "speed_ratios": {"X": 1.0, "Y": 1.0, "Z": 0.25},
        "default_speed": 0.25,
        "moving": False,
        "control": {
            "can_command": True,
            "reason": None,
            "running": None,
            "homing": True,
            "wcs": "G54",
            "wcs_list": ["G54", "G55", "G56", "G57", "G58", "G59"],
            "offsets": {"G54": [-200.0, -140.0, -15.0]},
            "wco": [-200.0, -140.0, -15.0],
            "overrides": {"feed": 100, "rapid": 100, "spindle": 100},
            "modal": "G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0",
            "steps_per_mm": [80.0, 80.0, 400.0],
            "commands": dict.fromkeys(COMMANDS),
            "offer": [],
        },
    }


class RecordingBackend:
    """Records calls; `view_state` is the scriptable snapshot (t_s and motion are filled in)."""

    def __init__(self, *, animate: bool = True) -> None:
        self.calls: list[Call] = []
        #: Every intent exactly as the arbiter forwarded it, in order.
        self.intents: list[Intent] = []
        self.view_state: dict[str, object] = default_view()
        self.animate = animate
        self.fail_on: set[str] = set()
        self._held: tuple[dict[str, float], float] | None = None
        self._last_view_s: float | None = None
        self._scripted_state: object = None
        #: What `command` answers per command name (a plain ok when absent).
        self.command_results: dict[str, CommandResult] = {}
        self.refuse_commands: str | None = None
        self._stop_listeners: list[Callable[[StopRecord], None]] = []

    @staticmethod
    def now_s() -> float:
        """The loop clock, the same one the server's dead-man uses."""
        return asyncio.get_running_loop().time()

    def _record(self, name: str, *args: object) -> None:
        self.calls.append(Call(self.now_s(), name, args))
        if name in self.fail_on:
            raise RuntimeError(f"recording backend told to fail on {name}")

    # -- PendantBackend ------------------------------------------------------------------------

    def set_intent(self, intent: Intent) -> None:
        """Record the intent under the name of what it does, and hold or release the jog.

        A non-neutral ContinuousIntent is recorded as "jog_continuous" (axes, speed), a
        StepIntent as "jog_step" (axis, dist_mm), a StopIntent or a neutral ContinuousIntent (the
        engine treats both as a stop) as "stop", a GotoIntent as "goto" (target).
        """
        self.intents.append(intent)
        if isinstance(intent, ContinuousIntent) and not intent.is_neutral():
            self._record("jog_continuous", dict(intent.axes), intent.speed)
            self._held = (dict(intent.axes), intent.speed)
        elif isinstance(intent, StepIntent):
            self._record("jog_step", intent.axis, intent.dist_mm)
        elif isinstance(intent, GotoIntent):
            self._record("goto", dict(intent.target_mpos_mm))
        else:
            self._record("stop")
            self._held = None
            if isinstance(intent, StopIntent) and not intent.release:
                self._tell_stop(intent.by or "an input")

    def add_stop_listener(self, callback: Callable[[StopRecord], None]) -> None:
        """Told of every StopIntent, as the real gate tells of every stop."""
        self._stop_listeners.append(callback)

    def _tell_stop(self, by: str) -> None:
        record = StopRecord(by, ("cancel",), f"stopped by {by}: the jog was cancelled", 0.0)
        for callback in list(self._stop_listeners):
            callback(record)

    def can_jog(self) -> tuple[bool, str | None]:
        """The scripted view's can_jog and reason (the state when it gives no reason)."""
        if self.view_state.get("can_jog") is not False:
            return True, None
        reason = self.view_state.get("reason") or f"machine state is {self.view_state.get('state')}"
        return False, str(reason)

    def view(self) -> Mapping[str, object]:
        """The scripted view, advanced by the crude motion when animate is on."""
        now_s = self.now_s()
        if "view" in self.fail_on:
            raise RuntimeError("recording backend view is broken")
        if self.animate:
            self._advance(now_s)
        self._last_view_s = now_s
        return {**self.view_state, "t_s": now_s}

    def set_speed_ratios(self, ratios: Mapping[str, float]) -> None:
        """Record the ratios and show them in the view."""
        self._record("set_speed_ratios", dict(ratios))
        self.view_state["speed_ratios"] = {**self.ratios(), **ratios}

    async def command(self, message: CommandMessage) -> CommandResult:
        """Record a machine command; answer with `command_results[name]` or a plain ok.

        `refuse_commands` (a reason) refuses every command in words, as the real one does while
        the machine moves.
        """
        self._record("command", message)
        if self.refuse_commands is not None:
            raise ControlRefused(self.refuse_commands)
        return self.command_results.get(message.name, CommandResult(message.name, True))

    def work_zero_targets(self) -> list[dict[str, float]]:
        """Z to -1, then X and Y, then Z to the scripted WCO."""
        control = self.view_state["control"]
        assert isinstance(control, dict)
        wco = control["wco"]
        assert isinstance(wco, list)
        return [{"Z": -1.0}, {"X": float(wco[0]), "Y": float(wco[1])}, {"Z": float(wco[2])}]

    # -- helpers for tests ---------------------------------------------------------------------

    def ratios(self) -> dict[str, float]:
        """The current speed ratios."""
        raw = self.view_state["speed_ratios"]
        assert isinstance(raw, dict)
        return {str(k): float(v) for k, v in raw.items()}

    def set_view(self, **changes: object) -> None:
        """Change some keys of the scripted view.

        A scripted state other than Idle or Jog (Alarm, Hold, Door) stays what the view reports
        while the crude motion runs down, as the machine's own report would. A scripted state
        without a scripted control gets the offer of STATE_OFFERS (none for other states).
        """
        self.view_state.update(changes)
        if "state" in changes:
            self._scripted_state = changes["state"]
            if "control" not in changes:
                self.set_control(offer=list(STATE_OFFERS.get(str(changes["state"]), [])))

    def set_control(self, **changes: object) -> None:
        """Change some keys of the view's control object (commands, offer, can_command...)."""
        control = self.view_state["control"]
        assert isinstance(control, dict)
        self.view_state["control"] = {**control, **changes}

    def named(self, name: str, since_s: float = -math.inf) -> list[Call]:
        """The calls of one method at or after since_s."""
        return [c for c in self.calls if c.name == name and c.t_s >= since_s]

    def jogs(self, since_s: float = -math.inf) -> list[dict[str, float]]:
        """The axes of every jog_continuous call at or after since_s."""
        out: list[dict[str, float]] = []
        for c in self.named("jog_continuous", since_s):
            axes = c.args[0]
            assert isinstance(axes, dict)
            out.append(axes)
        return out

    async def wait_for(
        self, predicate: Callable[[], object], timeout_s: float = 5.0, what: str = "condition"
    ) -> None:
        """Poll predicate on the loop until it is true; fail with the call log if it never is."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while not predicate():
            if loop.time() > deadline:
                tail = "\n".join(f"  {c.t_s:.3f} {c.name} {c.args}" for c in self.calls[-15:])
                raise AssertionError(f"timed out waiting for {what}; last calls:\n{tail}")
            await asyncio.sleep(0.01)

    def _advance(self, now_s: float) -> None:
        dt_s = 0.0 if self._last_view_s is None else min(now_s - self._last_view_s, 0.2)
        mpos = [float(v) for v in self.view_state["mpos"]]  # type: ignore[attr-defined]
        wpos = [float(v) for v in self.view_state["wpos"]]  # type: ignore[attr-defined]
        rates = [float(v) / 60.0 for v in self.view_state["max_rate_mm_min"]]  # type: ignore[attr-defined]
        ratios = self.ratios()
        velocity = [0.0] * len(AXES)
        if self._held is not None and self.view_state.get("can_jog"):
            axes, speed = self._held
            for i, a in enumerate(AXES):
                velocity[i] = axes.get(a, 0.0) * speed * rates[i] * ratios.get(a, 1.0)
        commanded = math.sqrt(sum(v * v for v in velocity))
        previous = float(self.view_state["actual_speed_mm_s"])  # type: ignore[arg-type]
        # First-order lag of about 0.15 s stands in for acceleration.
        actual = previous + (commanded - previous) * min(1.0, dt_s / 0.15)
        scale = actual / commanded if commanded > 0 else 0.0
        for i in range(len(AXES)):
            mpos[i] += velocity[i] * scale * dt_s
            wpos[i] += velocity[i] * scale * dt_s
        moving = actual > 0.01
        stop = [p + v * scale * 0.3 for p, v in zip(mpos, velocity, strict=True)]
        self.view_state.update(
            {
                "mpos": mpos,
                "wpos": wpos,
                "commanded_speed_mm_s": commanded,
                "actual_speed_mm_s": actual if moving else 0.0,
                "feed_mm_min": commanded * 60.0,
                "moving": moving,
                "state": self._state(moving),
                "stop_point_mpos": stop if moving else None,
                "queue": {
                    "queued_mm": commanded * 0.3,
                    "blocks": 6 if moving else 0,
                    "planner_blocks": 15,
                },
            }
        )

    def _state(self, moving: bool) -> object:
        if self._scripted_state not in (None, "Idle", "Jog"):
            return self._scripted_state
        if moving:
            return "Jog"
        state = self.view_state.get("state")
        return "Idle" if state == "Jog" else state

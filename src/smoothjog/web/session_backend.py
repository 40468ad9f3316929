"""The pendant's backend for real: intents the arbiter lets through go to the session's gate.

Every method returns at once (the engine only records the intent; the session's ticker acts on
it). Invalid intents raise JogBuildError, which the arbiter reports to the page in words. Whether
a jog or a command may start, and what a stop does, is the MotionGate's say; this module only
shows it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

from smoothjog.authority.commands import COMMAND_NAMES, command
from smoothjog.authority.gate import MotionGate, StopRecord
from smoothjog.control import WCS_WORDS, CommandResult, MachineControl
from smoothjog.core.codes import describe_alarm
from smoothjog.core.intents import Intent
from smoothjog.core.machine import UNHOMED_WARNING
from smoothjog.host import Host
from smoothjog.web.protocol import CommandMessage


def _finite(values: object) -> list[float | None] | None:
    """JSON has no NaN: unknown numbers become null."""
    if values is None:
        return None
    out: list[float | None] = []
    for v in values:  # type: ignore[attr-defined]
        out.append(float(v) if isinstance(v, int | float) and math.isfinite(v) else None)
    return out


class SessionBackend:
    """PendantBackend over a started Host."""

    def __init__(
        self,
        session: Host,
        *,
        speed_ratios: Mapping[str, float] | None = None,
        control: MachineControl | None = None,
        default_speed: float = 0.5,
    ):
        """Wrap a session whose start() has completed (and its machine control, if shared);
        default_speed is the page's speed until its user picks one ([jog] default_speed)."""
        self.session = session
        self.default_speed = default_speed
        self.control = control if control is not None else MachineControl(session)
        #: The session's motion gate: who may move the machine, and what a stop does.
        self.gate: MotionGate = self.control.gate
        engine = session.engine
        if engine is None:
            raise RuntimeError("SessionBackend needs a started Host")
        self._ratios = dict.fromkeys(engine.limits.axes, 1.0)
        if speed_ratios:
            self.set_speed_ratios(speed_ratios)

    def attach(self, session: Host) -> None:
        """Drive a new session (the link was lost and opened again): same page, same ratios."""
        if session.engine is None:
            raise RuntimeError("SessionBackend needs a started Host")
        self.session = session
        self.control.attach(session)
        self.set_speed_ratios(
            {axis: r for axis, r in self._ratios.items() if axis in session.engine.limits.axes}
        )

    # ------------------------------------------------------------------ intents
    def set_intent(self, intent: Intent) -> None:
        """Hand the gate the newest intent (the arbiter already let it through)."""
        self.gate.set_intent(intent)

    def can_jog(self) -> tuple[bool, str | None]:
        """The gate's verdict on a new jog."""
        return self.gate.can_jog()

    def add_stop_listener(self, callback: Callable[[StopRecord], None]) -> None:
        """Every stop of the machine, whoever gave it (the gate tells)."""
        self.gate.add_stop_listener(callback)

    def set_speed_ratios(self, ratios: Mapping[str, float]) -> None:
        """Per-axis top speed ratios in (0, 1]."""
        self.session.set_speed_ratios(ratios)
        self._ratios.update(ratios)

    # ------------------------------------------------------------------ machine control
    async def command(self, message: CommandMessage) -> CommandResult:
        """Run one machine command through the session's MachineControl."""
        m = message
        return await self.control.run(
            m.name, axes=m.axes, wcs=m.wcs, kind=m.kind, step=m.step, line=m.line
        )

    def work_zero_targets(self) -> list[dict[str, float]]:
        """Z up to a safe height, then X and Y, then Z down to work zero (machine positions)."""
        return self.control.work_zero_targets()

    def _offer(self) -> list[str]:
        """The one next action(s) the page offers beside the message, by state."""
        session = self.session
        state = self.gate.shown_state()
        if state in (command("resume").states or ()):  # Hold, Door: the catalogue's
            return ["resume", "reset"]
        if state == "Sleep" or (state == "Alarm" and session.reset_needed):
            return ["reset"]
        if state == "Alarm":
            return ["home", "unlock"] if self.control.homing_enabled else ["unlock"]
        return []

    def _control_view(self) -> dict[str, object]:
        session = self.session
        model = session.model
        control = self.control
        reason = control.refusal()
        gate = self.gate
        offsets = {
            name: list(values)
            for name, values in model.offsets_mm.items()
            if name in WCS_WORDS or name == "G92"
        }
        feed, rapid, spindle = model.overrides
        return {
            "can_command": reason is None,
            "reason": reason,
            "commands": {name: gate.command_refusal(name) for name in COMMAND_NAMES},
            "offer": self._offer(),
            "running": control.running,
            "homing": control.homing_enabled,
            "wcs": model.modal.wcs,
            "wcs_list": list(WCS_WORDS),
            "offsets": offsets,
            "wco": _finite(model.wco_mm),
            "overrides": {"feed": feed, "rapid": rapid, "spindle": spindle},
            "modal": " ".join(model.modal.words),
            "steps_per_mm": list(model.settings.steps_per_mm),
        }

    # ------------------------------------------------------------------ the snapshot
    def _fault(self) -> dict[str, str] | None:
        """The fault the page shows: the lost link first, then the engine's, then an alarm."""
        session = self.session
        if session.link_error is not None:
            return {"text": str(session.link_error), "hint": "check the cable and restart"}
        fault = session.view().fault
        if fault is not None:
            return {"text": fault[0], "hint": fault[1]}
        model = session.model
        if model.state == "Alarm" and model.last_alarm is not None:
            return {"text": describe_alarm(model.last_alarm), "hint": ""}
        return None

    def _warning(self) -> str | None:
        """What the page says beside a jog that may go but deserves care."""
        model = self.session.model
        if model.state == "Idle" and self.session.engine is not None and model.looks_unhomed():
            return UNHOMED_WARNING
        return None

    def _stop_view(self) -> dict[str, object] | None:
        """The last stop, for every page to say who stopped the machine and what it did."""
        stop = self.gate.last_stop
        if stop is None:
            return None
        return {"by": stop.by, "text": stop.text, "actions": list(stop.actions), "t_s": stop.t_s}

    def view(self) -> Mapping[str, object]:
        """Everything the page shows, in the documented keys."""
        session = self.session
        engine = session.engine
        assert engine is not None
        v = session.view()
        model = session.model
        limits = engine.limits
        env = limits.envelope
        lost = session.link_error is not None
        may_jog, reason = self.gate.can_jog()
        return {
            "t_s": v.t_s,
            "firmware": f"{model.firmware} {model.version or ''}".strip(),
            "axes": list(limits.axes),
            "state": self.gate.shown_state(),
            "substate": v.substate,
            "link": "lost" if lost else "up",
            "can_jog": may_jog,
            "reason": reason,
            "units": "inch" if model.settings.report_inches else "mm",
            "mpos": _finite(v.mpos_mm),
            "wpos": _finite(v.wpos_mm),
            "feed_mm_min": v.feed_mm_min,
            "commanded_speed_mm_s": v.commanded_speed_mm_s,
            "actual_speed_mm_s": v.actual_speed_mm_s,
            "stop_point_mpos": _finite(v.stop_point_mm),
            "queue": {
                "queued_mm": round(v.queued_mm, 4),
                "blocks": v.queued_blocks,
                "planner_blocks": limits.planner_blocks,
            },
            "fault": self._fault(),
            "warning": self._warning(),
            "stop": self._stop_view(),
            "envelope": (
                {"min_mm": list(env.min_mm), "max_mm": list(env.max_mm)}
                if env is not None
                else None
            ),
            "keepouts": [
                {"name": z.name, "min_mm": list(z.min_mm), "max_mm": list(z.max_mm)}
                for z in limits.keepouts
            ],
            "max_rate_mm_min": list(limits.max_rate_mm_min),
            "speed_ratios": dict(self._ratios),
            "default_speed": self.default_speed,
            "moving": self.gate.machine_moving(),
            "control": self._control_view(),
        }

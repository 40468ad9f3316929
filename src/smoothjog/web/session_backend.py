"""The pendant's backend for real: intents the arbiter lets through go to the host's engine.

Every method returns at once (the engine only records the intent; the session's ticker acts on
it). Invalid intents raise JogBuildError, which the arbiter reports to the page in words.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from smoothjog.control import WCS_WORDS, CommandResult, ControlRefused, MachineControl
from smoothjog.core.codes import describe_alarm
from smoothjog.core.intents import Intent
from smoothjog.host import Host
from smoothjog.web.protocol import CommandMessage

#: Why nothing may jog once the link is gone (the view's reason says the same).
LINK_LOST = "the connection to the controller is lost"


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
        self.control.host = session
        self.set_speed_ratios(
            {axis: r for axis, r in self._ratios.items() if axis in session.engine.limits.axes}
        )

    # ------------------------------------------------------------------ intents
    def set_intent(self, intent: Intent) -> None:
        """Hand the engine the newest intent (the arbiter already let it through)."""
        self.session.set_intent(intent)

    def can_jog(self) -> tuple[bool, str | None]:
        """The engine's verdict, and no jog at all once the link to the controller is lost."""
        if self.session.link_error is not None:
            return False, LINK_LOST
        busy = self.control.busy_reason()
        if busy is not None:
            return False, f"jogging waits: {busy}"
        v = self.session.view()
        return v.can_jog, v.reason

    def set_speed_ratios(self, ratios: Mapping[str, float]) -> None:
        """Per-axis top speed ratios in (0, 1]."""
        self.session.set_speed_ratios(ratios)
        self._ratios.update(ratios)

    # ------------------------------------------------------------------ machine control
    async def command(self, message: CommandMessage) -> CommandResult:
        """Run one machine command through the session's MachineControl."""
        control = self.control
        name = message.name
        if name == "unlock":
            return await control.unlock()
        if name == "home":
            return await control.home()
        if name == "reset":
            return await control.soft_reset()
        if name == "zero":
            return await control.set_work_zero(message.axes)
        if name == "wcs":
            return await control.select_wcs(message.wcs)
        if name == "override":
            return await control.override(message.kind, message.step)
        if name == "console":
            return await control.console(message.line)
        raise ControlRefused(f"unknown command {name!r}")

    def work_zero_targets(self) -> list[dict[str, float]]:
        """Z up to a safe height, then X and Y, then Z down to work zero (machine positions)."""
        reason = self.control.refusal()
        if reason is not None:
            raise ControlRefused(reason)
        return self.control.work_zero_targets()

    def _control_view(self) -> dict[str, object]:
        session = self.session
        model = session.model
        control = self.control
        reason = control.refusal()
        offsets = {
            name: list(values)
            for name, values in model.offsets_mm.items()
            if name in WCS_WORDS or name == "G92"
        }
        feed, rapid, spindle = model.overrides
        return {
            "can_command": reason is None,
            "reason": reason,
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
    def view(self) -> Mapping[str, object]:
        """Everything the page shows, in the documented keys."""
        session = self.session
        engine = session.engine
        assert engine is not None
        v = session.view()
        model = session.model
        limits = engine.limits
        env = limits.envelope
        fault: dict[str, str] | None = None
        if v.fault is not None:
            fault = {"text": v.fault[0], "hint": v.fault[1]}
        elif session.link_error is not None:
            fault = {"text": str(session.link_error), "hint": "check the cable and restart"}
        elif model.state == "Alarm" and model.last_alarm is not None:
            fault = {"text": describe_alarm(model.last_alarm), "hint": ""}
        reason = v.reason
        if session.link_error is not None:
            reason = LINK_LOST
        return {
            "t_s": v.t_s,
            "firmware": f"{model.firmware} {model.version or ''}".strip(),
            "axes": list(limits.axes),
            "state": v.state or "Unknown",
            "substate": v.substate,
            "can_jog": v.can_jog and session.link_error is None,
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
            "fault": fault,
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
            "moving": session.busy() or (v.state not in (None, "Idle", "Alarm", "Sleep")),
            "control": self._control_view(),
        }

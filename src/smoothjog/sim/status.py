"""Build Grbl 1.1h status reports (`<...>`), including the WCO and Ov refresh counters.

Field order, formats and counter rules are those of firmware-facts §5.4 and §5.5. Positions and
WCO arrive as the firmware's singles; WPos is their difference in single precision and every
coordinate is printed by printFloat_CoordValue's single arithmetic (f32.py, firmware-facts §1.5).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from smoothjog.core.units import mm_to_inch
from smoothjog.sim.f32 import f32, print_coord
from smoothjog.sim.settings import format_grbl_float

#: Reports between WCO fields while busy / otherwise (REPORT_WCO_REFRESH_*_COUNT, firmware-facts
#: §5.4).
WCO_BUSY_COUNT = 30
WCO_IDLE_COUNT = 10
#: Reports between Ov fields while busy / otherwise (REPORT_OVR_REFRESH_*_COUNT).
OVR_BUSY_COUNT = 20
OVR_IDLE_COUNT = 10

#: States in which the counters use their "busy" period and FS shows a feed (firmware-facts §5.4).
BUSY_STATES = frozenset({"Run", "Hold", "Jog", "Home", "Door"})


@dataclass(frozen=True)
class StatusInputs:
    """Everything one status report shows, in machine units (mm, mm/min)."""

    state: str  # base state name: Idle, Run, Hold, Jog, Home, Alarm, Check, Door, Sleep
    substate: int | None  # Hold:n / Door:n
    mpos_mm: Sequence[float]  # singles, from the step counters
    wco_mm: Sequence[float]  # singles
    planner_free: int
    rx_free: int
    feed_mm_min: float
    spindle_rpm: float
    overrides_pct: tuple[int, int, int]
    accessories: str  # "" or letters from S, C, F, M


class StatusReporter:
    """Formats reports and keeps the report counters that decide when WCO and Ov appear."""

    def __init__(self) -> None:
        """Counters at zero, as after boot or reset (so the first report carries WCO)."""
        self.wco_counter = 0
        self.ovr_counter = 0

    def reset(self) -> None:
        """Back to the power-up counters (soft reset clears them with the rest of `sys`)."""
        self.wco_counter = 0
        self.ovr_counter = 0

    def force_wco(self) -> None:
        """Put WCO in the next report (after any offset change)."""
        self.wco_counter = 0

    def force_ovr(self) -> None:
        """Put Ov in the next report (after an override, spindle or coolant change)."""
        self.ovr_counter = 0

    def build(self, inp: StatusInputs, *, status_mask: int, inches: bool) -> str:
        """One report line, without line end; advances the counters."""
        busy = inp.state in BUSY_STATES
        name = inp.state if inp.substate is None else f"{inp.state}:{inp.substate}"
        parts = [name]

        def axes(values_mm: Sequence[float]) -> str:
            return ",".join([print_coord(v, inches) for v in values_mm])

        if status_mask & 1:
            parts.append("MPos:" + axes(inp.mpos_mm))
        else:
            wpos = [f32(m - w) for m, w in zip(inp.mpos_mm, inp.wco_mm, strict=True)]
            parts.append("WPos:" + axes(wpos))
        if status_mask & 2:
            parts.append(f"Bf:{inp.planner_free},{inp.rx_free}")
        feed = inp.feed_mm_min if busy else 0.0
        feed_text = format_grbl_float(mm_to_inch(feed), 1) if inches else format_grbl_float(feed, 0)
        parts.append(f"FS:{feed_text},{format_grbl_float(inp.spindle_rpm, 0)}")
        if self.wco_counter > 0:
            self.wco_counter -= 1
        else:
            self.wco_counter = (WCO_BUSY_COUNT if busy else WCO_IDLE_COUNT) - 1
            # Ov is put off by one report when WCO is printed (firmware-facts §5.4).
            if self.ovr_counter == 0:
                self.ovr_counter = 1
            parts.append("WCO:" + axes(inp.wco_mm))
        if self.ovr_counter > 0:
            self.ovr_counter -= 1
        else:
            self.ovr_counter = (OVR_BUSY_COUNT if busy else OVR_IDLE_COUNT) - 1
            f, r, s = inp.overrides_pct
            parts.append(f"Ov:{f},{r},{s}")
            if inp.accessories:
                parts.append(f"A:{inp.accessories}")
        return "<" + "|".join(parts) + ">"

"""What a mover (the streamer, the step queue) reads and writes beside its own queue."""

from __future__ import annotations

from dataclasses import dataclass

from smoothjog.core.engine.clearance import Clearance
from smoothjog.core.engine.clock import LinkClock
from smoothjog.core.engine.limits import JogTuning
from smoothjog.core.engine.lines import EngineLines
from smoothjog.core.engine.records import EngineStats, Notices
from smoothjog.core.engine.tracker import PathTracker
from smoothjog.core.machine import MachineModel


@dataclass
class MotionParts:
    """The shared parts a mover is given by the phase machine (it owns none of them)."""

    model: MachineModel
    tuning: JogTuning
    track: PathTracker
    clock: LinkClock
    clearance: Clearance
    lines: EngineLines
    notices: Notices
    stats: EngineStats

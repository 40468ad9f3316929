"""The jog engine: a phase machine (jogger.py) and the parts it drives, one concern per file.

    jogger.py     the phase machine's API: intents, replies, the tick, the views
    phase.py      the phase machine's core: its state, reactions to reports and stop ends
                  (these two are the only code that changes the engine's phase)
    stream.py     continuous jogging: velocity, queue size, increments, turns
    steps.py      steps, go-tos and handwheel runs
    clearance.py  the soft-limit envelope and keep-outs: clipping, room, held-back lines
    stopper.py    the stop handshake and its driver
    clock.py      the link clock: round trips, stalls, lateness, wire time, the link split
    reports.py    report reading and the `?` schedule
    signs.py      outside events: the sign table and its one verdict type
    bounds.py     the planner's bounds the signs compare reports with
    restart.py    the restart watch after a reset with jog lines on the wire
    lines.py      the engine's lines in the ledger
    records.py    outputs, events, phase, counters, stop records, the view
    limits.py     tuning, machine limits, the states a jog starts in
    tracker.py    the path and the position estimate along it
    linksplit.py  the link's way out told from its way back

The parts never import jogger.py or phase.py; they take what they need and return results.
"""

from smoothjog.core.engine.jogger import Jogger
from smoothjog.core.engine.limits import EngineLimits, JogTuning
from smoothjog.core.engine.records import (
    EngineEvent,
    EngineStats,
    EngineView,
    Output,
    Phase,
    SendLine,
    SendRealtime,
    StopRecord,
)

__all__ = [
    "EngineEvent",
    "EngineLimits",
    "EngineStats",
    "EngineView",
    "JogTuning",
    "Jogger",
    "Output",
    "Phase",
    "SendLine",
    "SendRealtime",
    "StopRecord",
]

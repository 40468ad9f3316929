"""A driver for unit tests of the jog engine: scripted controller lines in, the engine's output out.

No simulator and no asyncio: the harness builds a MachineModel from a scripted connect handshake
(a Grbl 1.1h banner, `$I`, `$$` of a simple machine, an Idle report), a Ledger and a Jogger, and
routes every line exactly as `Host._on_line` does. Time is whatever the test passes as `now_s`
(or the harness's own clock `t`, moved on with `advance`).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Iterable, Sequence
from typing import Any

from smoothjog.core.engine import EngineLimits, Jogger, JogTuning, Output, SendLine, SendRealtime
from smoothjog.core.intents import Intent
from smoothjog.core.ledger import ENGINE, Entry, Ledger, foreign
from smoothjog.core.machine import KeepOut, MachineModel
from smoothjog.core.realtime import CYCLE_START, JOG_CANCEL, STATUS_QUERY
from smoothjog.core.responses import Banner, ErrorReply, Ok, Response, parse_response

#: The simple machine: 80 steps/mm, 5000 mm/min, 500 mm/s², 800 mm of travel on every axis.
STEPS_PER_MM = 80.0
MAX_RATE_MM_MIN = 5000.0
ACCEL_MM_S2 = 500.0
TRAVEL_MM = 800.0
#: Where the machine rests after the handshake (inside the default build's -800..0 envelope).
START_MPOS = (-1.0, -1.0, -1.0)

BANNER = "Grbl 1.1h ['$' for help]"

_JOG_LINE = re.compile(r"^\$J=G21(G91|G53)((?:[XYZABC]-?[0-9.]+)+)F[0-9.]+$")
_AXIS_WORD = re.compile(r"([XYZABC])(-?[0-9.]+)")


def jog_target(
    start_mm: Sequence[float], lines: Iterable[str], axes: str = "XYZ"
) -> tuple[float, ...]:
    """Where a machine at start_mm ends after the `$J=` lines (G91 adds, G53 sets)."""
    pos = list(start_mm)
    for line in lines:
        match = _JOG_LINE.match(line)
        assert match is not None, f"not a jog line smoothjog writes: {line!r}"
        for letter, value in _AXIS_WORD.findall(match.group(2)):
            i = axes.index(letter)
            pos[i] = (pos[i] if match.group(1) == "G91" else 0.0) + float(value)
    return tuple(pos)


def handshake_lines(*, soft_limits: bool, rx_bytes: int = 128) -> list[str]:
    """The lines a Grbl 1.1h controller prints for the connect handshake (firmware-facts §5.3)."""
    settings = {
        0: "10",
        1: "25",
        10: "1",
        11: "0.010",
        12: "0.002",
        13: "0",
        20: "1" if soft_limits else "0",
        21: "0",
        22: "1" if soft_limits else "0",
        27: "1.000",
    }
    for axis in range(3):
        settings[100 + axis] = f"{STEPS_PER_MM:.3f}"
        settings[110 + axis] = f"{MAX_RATE_MM_MIN:.3f}"
        settings[120 + axis] = f"{ACCEL_MM_S2:.3f}"
        settings[130 + axis] = f"{TRAVEL_MM:.3f}"
    return [
        "",
        BANNER,
        "[MSG:'$H'|'$X' to unlock]" if soft_limits else "[MSG:Caution: Unlocked]",
        "[VER:1.1h.20190830:]",
        f"[OPT:V,15,{rx_bytes}]",
        "ok",
        *(f"${n}={v}" for n, v in sorted(settings.items())),
        "ok",
        status_line("Idle", START_MPOS),
    ]


def status_line(
    state: str,
    mpos: Sequence[float],
    fs: tuple[float, float] = (0, 0),
    pn: str = "",
) -> str:
    """A Grbl 1.1h status report (firmware-facts §5.4): `<State|MPos:x,y,z|FS:f,s|Pn:..>`."""
    pos = ",".join(f"{p:.3f}" for p in mpos)
    pins = f"|Pn:{pn}" if pn else ""
    return f"<{state}|MPos:{pos}|FS:{fs[0]:g},{fs[1]:g}{pins}>"


class EngineHarness:
    """One engine on a scripted controller; `sent` holds every output the engine produced."""

    def __init__(
        self,
        *,
        soft_limits: bool = False,
        rx_bytes: int = 128,
        tuning: JogTuning | None = None,
        keepouts: Sequence[KeepOut] = (),
        limits: dict[str, Any] | None = None,
        handshake: Iterable[str] | None = None,
    ) -> None:
        """Handshake a model, derive the limits (fields in `limits` replaced), build the engine."""
        self.model = MachineModel()
        lines = (
            handshake
            if handshake is not None
            else handshake_lines(soft_limits=soft_limits, rx_bytes=rx_bytes)
        )
        for line in lines:
            self.model.apply(parse_response(line))
        engine_limits = EngineLimits.from_model(self.model, keepouts)
        if limits:
            engine_limits = dataclasses.replace(engine_limits, **limits)
        self.ledger = Ledger(self.model.rx_buffer_bytes)
        self.engine = Jogger(self.model, engine_limits, tuning, self.ledger)
        self.t = 0.0
        #: Where the machine rested when the jogs sent began (jog_target starts there).
        self.origin: tuple[float, ...] = tuple(self.model.mpos_mm or START_MPOS)
        self.sent: list[Output] = []
        #: Replies that reached no engine line (another owner's, or none waiting).
        self.other_replies: list[tuple[Entry | None, Ok | ErrorReply]] = []

    # ----------------------------------------------------------------- the clock
    def _now(self, now_s: float | None) -> float:
        if now_s is not None:
            self.t = now_s
        return self.t

    def advance(self, dt_s: float) -> float:
        """Move the harness clock on by dt_s; return the new time."""
        self.t += dt_s
        return self.t

    # ----------------------------------------------------------------- what the host does
    def feed(self, line: str, now_s: float | None = None) -> Response:
        """One received line, handled exactly as Host._on_line hands it to the engine."""
        now = self._now(now_s)
        resp = parse_response(line)
        self.model.apply(resp)
        if isinstance(resp, Ok | ErrorReply):
            entry = self.ledger.on_reply()
            if entry is not None and entry.owner == ENGINE:
                self.engine.on_reply(entry, resp, now)
            else:
                self.other_replies.append((entry, resp))
        else:
            if isinstance(resp, Banner):
                self.ledger.reset()
            self.engine.on_response(resp, now)
        return resp

    def poll(self, now_s: float | None = None) -> list[Output]:
        """The engine's poll; its outputs are also kept in `sent`."""
        out = self.engine.poll(self._now(now_s))
        self.sent.extend(out)
        return out

    def intent(self, intent: Intent, now_s: float | None = None) -> None:
        """Hand the engine an intent (JogBuildError propagates, as in Host.set_intent)."""
        self.engine.set_intent(intent, self._now(now_s))

    def run(self, until_s: float, *, tick_s: float = 0.002, ack: bool = True) -> None:
        """Poll every tick_s up to until_s; with ack, first answer `ok` to every engine line.

        Each line is so answered one tick after it was sent (a round trip of tick_s), and the
        lines sent by the last poll are left unanswered.
        """
        while self.t + tick_s <= until_s + 1e-9:
            self.advance(tick_s)
            if ack:
                while self.ledger.outstanding() and self.ledger.outstanding()[0].owner == ENGINE:
                    self.ok()
            self.poll()

    # ----------------------------------------------------------------- controller replies
    def oldest_engine_line(self) -> Entry:
        """The engine's oldest unanswered line; it must also be the ledger's oldest."""
        outstanding = self.ledger.outstanding()
        assert outstanding, "no line waits for a reply"
        assert outstanding[0].owner == ENGINE, f"the oldest line is {outstanding[0].owner}'s"
        return outstanding[0]

    def ok(self, now_s: float | None = None) -> str:
        """Answer the engine's oldest unanswered line with `ok`; return that line."""
        text = self.oldest_engine_line().text
        self.feed("ok", now_s)
        return text

    def error(self, code: int, now_s: float | None = None) -> str:
        """Answer the engine's oldest unanswered line with `error:code`; return that line."""
        text = self.oldest_engine_line().text
        self.feed(f"error:{code}", now_s)
        return text

    def ok_all(self, now_s: float | None = None) -> list[str]:
        """Answer every unanswered engine line with `ok`, oldest first."""
        answered = []
        while self.ledger.outstanding(ENGINE):
            answered.append(self.ok(now_s))
        return answered

    def status(
        self,
        state: str,
        mpos: Sequence[float] | None = None,
        fs: tuple[float, float] = (0, 0),
        pn: str = "",
        now_s: float | None = None,
    ) -> None:
        """A status report with this state, MPos (default: the model's), FS and Pn."""
        pos = mpos if mpos is not None else (self.model.mpos_mm or START_MPOS)
        self.feed(status_line(state, pos, fs, pn), now_s)

    def rest_at(self, mpos: Sequence[float], now_s: float | None = None) -> None:
        """An Idle report at mpos, taken as the origin of the jogs that follow."""
        self.status("Idle", mpos, now_s=now_s)
        self.origin = tuple(mpos)

    def path_end(self) -> tuple[float, ...]:
        """Where every jog line sent so far ends, from the origin."""
        return jog_target(self.origin, self.jog_lines())

    def foreign_line(self, text: str, name: str = "cncjs", now_s: float | None = None) -> Entry:
        """Record a line another sender wrote (it takes RX room until answered)."""
        return self.ledger.record_line(foreign(name), text, self._now(now_s))

    # ----------------------------------------------------------------- what was sent
    def lines(self) -> list[str]:
        """Every line the engine sent, in order."""
        return [o.text for o in self.sent if isinstance(o, SendLine)]

    def realtime(self) -> list[bytes]:
        """Every realtime byte the engine sent, in order."""
        return [o.byte for o in self.sent if isinstance(o, SendRealtime)]

    def jog_lines(self) -> list[str]:
        """The `$J=` lines the engine sent."""
        return [text for text in self.lines() if text.startswith("$J=")]

    def mark(self) -> int:
        """A position in `sent` to read what follows with `since`."""
        return len(self.sent)

    def since(self, mark: int) -> list[Output]:
        """The outputs sent after mark."""
        return self.sent[mark:]

    def unanswered(self) -> list[str]:
        """The engine's lines still waiting for a reply, oldest first."""
        return [e.text for e in self.ledger.outstanding(ENGINE)]

    def fault_texts(self) -> list[str]:
        """The text of every fault event so far."""
        return [e.text for e in self.engine.events if e.kind == "fault"]

    def event_kinds(self) -> list[str]:
        """The kind of every event so far."""
        return [e.kind for e in self.engine.events]


# ------------------------------------------------------------------------------ script steps
#: One step of a scripted engine test: something done to (or checked on) the harness.
Step = Callable[[EngineHarness], None]


def kinds(outputs: Sequence[Output]) -> list[str]:
    """Outputs in short: `$J` for any jog line, the other lines verbatim, `0x85`, `?`, `~`."""
    out = []
    for o in outputs:
        if isinstance(o, SendLine):
            out.append("$J" if o.text.startswith("$J=") else o.text)
        else:
            out.append(
                {JOG_CANCEL: "0x85", STATUS_QUERY: "?", CYCLE_START: "~"}.get(o.byte, repr(o.byte))
            )
    return out


def intent(i: Intent) -> Step:
    return lambda h: h.intent(i)


def sends(*expected: str) -> Step:
    """Poll once and check exactly what the engine sent (see kinds)."""

    def step(h: EngineHarness) -> None:
        got = kinds(h.poll())
        assert got == list(expected), f"at t={h.t:.3f} s the engine sent {got}"

    return step


def poll(h: EngineHarness) -> None:
    h.poll()


def ok(h: EngineHarness) -> None:
    h.ok()


def ok_all(h: EngineHarness) -> None:
    h.ok_all()


def wait(dt_s: float) -> Step:
    def step(h: EngineHarness) -> None:
        h.advance(dt_s)

    return step

"""The virtual-time driver: the jog engine against the simulator with a clock that tests advance.

The same engine as in real time, coupled to `sim.rig.SimRig` event by event: the next thing to
happen is either the rig's (a byte arriving, a segment ending, a reply leaving the controller) or
the engine's deadline. Nothing sleeps, so a minute of jogging runs in well under a second of wall
time, and two runs of one script are identical.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from typing import Protocol

from smoothjog.core.errors import ConnectError
from smoothjog.core.jogger import (
    EngineLimits,
    Intent,
    Jogger,
    JogTuning,
    Output,
    SendLine,
)
from smoothjog.core.machine import KeepOut, MachineModel
from smoothjog.core.responses import ErrorReply, Ok, Response, parse_response
from smoothjog.inputs.replay import TimedIntent
from smoothjog.sim.rig import SimRig


class JogHost(Protocol):
    """What drives the controller: smoothjog's Jogger, or a reference method in bench/."""

    def set_intent(self, intent: Intent, now_s: float) -> None:
        """Take the newest intent."""

    def on_response(self, resp: Response, now_s: float) -> None:
        """Take one line from the controller."""

    def poll(self, now_s: float) -> list[Output]:
        """What to send now."""

    def next_deadline_s(self, now_s: float) -> float:
        """Latest time to be polled again."""

    def busy(self) -> bool:
        """True while the host still has work in hand."""


HostFactory = Callable[[MachineModel], JogHost]

#: Queries of the connect handshake (the same as the real one, facts §5.3).
HANDSHAKE_LINES = ("$I", "$$", "$G", "$#")


class VirtualSession:
    """Drive a Jogger against a SimRig in virtual time."""

    def __init__(
        self,
        rig: SimRig,
        *,
        tuning: JogTuning | None = None,
        keepouts: Sequence[KeepOut] = (),
        start_s: float = 0.0,
        host_factory: HostFactory | None = None,
    ) -> None:
        """Prepare; call handshake() before jogging. host_factory defaults to the Jogger."""
        self.rig = rig
        self.host_factory = host_factory
        self.host: JogHost | None = None
        #: Set by kill(): the host is gone (a crashed client); only the controller runs on.
        self.dead = False
        self._poll_due = False
        self.tuning = tuning or JogTuning()
        self.keepouts = tuple(keepouts)
        self.now_s = start_s
        self.model = MachineModel()
        self.engine: Jogger | None = None
        self.received: list[tuple[float, Response]] = []
        self.on_response: Callable[[float, Response], None] | None = None

    # ----------------------------------------------------------------- set-up
    def handshake(self, timeout_s: float = 5.0) -> MachineModel:
        """Ask $I, $$, $G, $# and ? as the real handshake does; build the engine."""
        self._drain(self.now_s + 0.6)  # the banner (and a possible 500 ms alarm pause)
        for line in HANDSHAKE_LINES:
            self.rig.host_send(line.encode() + b"\n", self.now_s)
            self._await_reply(self.now_s + timeout_s, line)
        self.rig.host_send(b"?", self.now_s)
        self._drain(self.now_s + 0.05)
        self.model.set_keep_outs(self.keepouts)
        if self.host_factory is None:
            self.engine = Jogger(self.model, EngineLimits.from_model(self.model), self.tuning)
            self.host = self.engine
        else:
            self.host = self.host_factory(self.model)
        return self.model

    def query_line(self, line: str, timeout_s: float = 2.0) -> list[Response]:
        """Send a line outside the engine (e.g. `$G`); return what came back up to its reply."""
        start = len(self.received)
        self.rig.host_send(line.encode() + b"\n", self.now_s)
        self._await_reply(self.now_s + timeout_s, line)
        return [r for _, r in self.received[start:]]

    def _await_reply(self, deadline_s: float, line: str) -> None:
        while self.now_s < deadline_s:
            nxt = self.rig.next_event_s()
            t = deadline_s if nxt is None else min(nxt, deadline_s)
            for resp in self._deliver(t):
                if isinstance(resp, Ok | ErrorReply):
                    return
        raise ConnectError(f"the simulator did not answer {line!r}")

    def _drain(self, until_s: float) -> None:
        while self.now_s < until_s:
            nxt = self.rig.next_event_s()
            t = until_s if nxt is None else min(nxt, until_s)
            self._deliver(t)

    def _deliver(self, t_s: float) -> list[Response]:
        out: list[Response] = []
        for at_s, raw in self.rig.run_until(t_s):
            resp = parse_response(raw)
            self.received.append((at_s, resp))
            if self.host is None:
                self.model.apply(resp)
            elif not self.dead:
                self.host.on_response(resp, at_s)
            if self.on_response is not None:
                self.on_response(at_s, resp)
            out.append(resp)
        self.now_s = max(self.now_s, t_s)
        return out

    # ----------------------------------------------------------------- running
    def _host(self) -> JogHost:
        if self.host is None:
            raise RuntimeError("VirtualSession.handshake() has not run")
        return self.host

    def set_intent(self, intent: Intent) -> None:
        """Give the host an intent now."""
        if self.dead:
            return
        self._host().set_intent(intent, self.now_s)
        # The host acts at its next poll, as in real time: intents given at the same instant
        # reach it together and it acts on the newest (the engine's contract).
        self._poll_due = True

    def kill(self) -> None:
        """The host dies now: it sends and reads nothing more; the controller runs on."""
        self.dead = True

    def _poll(self) -> None:
        if self.dead:
            return
        for output in self._host().poll(self.now_s):
            self._send(output)

    def _send(self, output: Output) -> None:
        if isinstance(output, SendLine):
            self.rig.host_send(output.text.encode() + b"\n", self.now_s)
        else:
            self.rig.host_send(output.byte, self.now_s)

    def run_until(self, until_s: float) -> None:
        """Let virtual time pass to until_s, the engine reacting to everything on the way."""
        host = self._host()
        while self.now_s < until_s:
            deadline = math.inf if self.dead else host.next_deadline_s(self.now_s)
            nxt = self.rig.next_event_s()
            t = min(until_s, deadline, math.inf if nxt is None else nxt)
            t = max(t, self.now_s)
            if self._poll_due:
                self._poll_due = False
                self._poll()
                continue
            got = self._deliver(t)
            self.now_s = t
            if got or t >= deadline or t == until_s or (nxt is not None and t == nxt):
                self._poll()

    def run_script(self, script: Iterable[TimedIntent], *, settle_s: float = 5.0) -> None:
        """Apply timed intents (times relative to now), then run until idle or settle_s passes."""
        t0 = self.now_s
        for item in script:
            self.run_until(t0 + item.t_s)
            self.set_intent(item.intent)
        self.run_until_idle(settle_s)

    def idle(self) -> bool:
        """True when the engine has nothing to do and the controller reports Idle."""
        return (self.dead or not self._host().busy()) and self.model.state in (
            "Idle",
            "Alarm",
            "Door",
            "Hold",
        )

    def run_until_idle(self, timeout_s: float) -> bool:
        """Run until idle (True) or timeout_s of virtual time passes (False)."""
        end_s = self.now_s + timeout_s
        while self.now_s < end_s:
            self.run_until(min(self.now_s + 0.02, end_s))
            if self.idle():
                return True
        return self.idle()

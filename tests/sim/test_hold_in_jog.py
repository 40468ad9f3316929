"""A feed hold or jog cancel from someone else during a held jog: what `?` shows around the stop,
and when the lines waiting in RX start again (firmware-facts §3.7).

The host holds a jog the way smoothjog does: a short `$J=G91` line every 10 ms, and it keeps
sending while the hold slows the machine down, so lines wait in RX. It polls `?` every 50 ms,
at every phase of that 50 ms against the stop.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import pytest

from tests.sim.rigtools import Host, is_reply
from tests.sim.rigtools import field as report_field

#: `$1`, the step-idle delay: once in the stepper ISR at the stop, once more in st_reset.
STEP_IDLE_S = 0.025
POLL_S = 0.050
PHASES_S = [k * 0.005 for k in range(10)]
#: What the host holds: 0.5 mm every 10 ms is 3000 mm/min.
PACED_LINE = "$J=G21G91X-0.5F3000"
#: With the planner full: 1 mm lines sent as fast as the RX buffer takes them.
STREAMED_LINE = "$J=G21G91X-1F3000"


@dataclass
class Poll:
    """One `?`: when it reached the controller, and the report that answered it."""

    arrival_s: float
    report: str = ""

    @property
    def state(self) -> str:
        """The report's state field."""
        return self.report[1:].split("|", 1)[0]

    def value(self, name: str) -> str:
        """One field of the report (it must be there)."""
        got = report_field(self.report, name)
        assert got is not None, self.report
        return got


@dataclass
class HeldJog:
    """The outcome of one run: the stop and restart seen in the ground truth, and the polls."""

    stop_s: float
    restart_s: float
    stop_mpos: str
    polls: list[Poll] = field(default_factory=list)
    line_time_s: float = 0.0

    def in_window(self, poll: Poll, start_s: float, end_s: float) -> bool:
        """True when the poll's `?` reached the controller in [start_s, end_s)."""
        return start_s <= poll.arrival_s < end_s


def held_jog(
    cancel: bytes, phase_s: float, *, planner_full: bool = False, during_parse: bool = False
) -> HeldJog:
    """Hold a jog, have someone else send `cancel` about 1 s in, poll every 50 ms from phase_s on.

    The cancel comes between two lines (the main loop idle, reading), or with during_parse just
    behind a line, so it arrives while that line is parsed.
    """
    host = Host(machine="hobby-router")
    assert host.reply("$10=3") == "ok"  # MPos and Bf
    rig, fw = host.rig, host.fw
    line = STREAMED_LINE if planner_full else PACED_LINE
    pace_s = 0.0 if planner_full else 0.010
    unanswered: list[int] = []
    polls: list[Poll] = []
    t0 = host.now_s
    # Lines go out at t0 + k x 10 ms; one takes about 2 ms to arrive and 1.5 ms to parse.
    cancel_s = t0 + 1.0 + (0.0 if during_parse else 0.005)
    next_line_s = t0
    next_poll_s = cancel_s + phase_s
    cancelled = False
    while host.now_s < cancel_s + 0.6:
        now = host.now_s
        if now >= next_line_s and sum(unanswered) + len(line) + 1 <= 128:
            rig.host_send(line.encode() + b"\n", now)
            unanswered.append(len(line) + 1)
            next_line_s += pace_s
        if not cancelled and now >= cancel_s:
            rig.host_send(cancel, now)  # someone else's byte
            cancelled = True
        if now >= next_poll_s and now < cancel_s + 0.5:
            polls.append(Poll(rig.host_send(b"?", now)))
            next_poll_s += POLL_S
        for text in host.run(0.001):
            if is_reply(text):
                unanswered.pop(0)
            elif text.startswith("<") and host.now_s > cancel_s:
                pending = [p for p in polls if not p.report]
                assert pending, f"a report nobody asked for: {text}"
                pending[0].report = text
    assert all(p.report for p in polls), "a `?` was never answered"
    # The stop and the restart in the ground truth: the first pause after the cancel.
    segments = [s for s in fw.trace if s.t1_s > cancel_s]
    gaps = [(a, b) for a, b in itertools.pairwise(segments) if b.t0_s - a.t1_s > 1e-9]
    assert gaps, "the machine never stopped"
    before, after = gaps[0]
    stop_mpos = ",".join(f"{v:.3f}" for v in before.end_mm)
    return HeldJog(before.t1_s, after.t0_s, stop_mpos, polls, fw.profile.line_time_s)


@pytest.mark.parametrize("cancel", [b"!", b"\x85"], ids=["feed-hold", "0x85"])
def test_lines_waiting_in_rx_restart_after_both_delays_and_idle_shows_between(
    cancel: bytes,
) -> None:
    idle_seen = 0
    for phase_s in PHASES_S:
        run = held_jog(cancel, phase_s)
        # The main loop was reading lines, not waiting in mc_line: after st_reset's delay the
        # first buffered line is read, its end of line is a checkpoint (Idle), then it is parsed
        # and starts a new jog.
        assert run.restart_s == pytest.approx(run.stop_s + 2 * STEP_IDLE_S + run.line_time_s)
        isr_delay_end = run.stop_s + STEP_IDLE_S
        for poll in run.polls:
            if run.in_window(poll, run.stop_s, isr_delay_end):
                # Asked during the stepper ISR's delay: answered when it ends, before cycle stop
                # is handled, so still Jog, at rest, FS 0, with the host's lines waiting in RX.
                assert poll.state == "Jog", poll.report
                assert poll.value("FS") == "0,0"
                assert poll.value("MPos") == run.stop_mpos
                assert int(poll.value("Bf").split(",")[1]) < 128
            elif run.in_window(poll, isr_delay_end, run.restart_s):
                # Asked during st_reset's delay (or the parse after it): answered Idle, at rest,
                # before the buffered line restarts motion.
                assert poll.state == "Idle", poll.report
                assert poll.value("MPos") == run.stop_mpos
                assert int(poll.value("Bf").split(",")[1]) < 128
                idle_seen += 1
            elif poll.arrival_s >= run.restart_s:
                assert poll.state == "Jog", poll.report
        # A 50 ms poll sees Idle exactly when one `?` lands in that window.
        window = [p for p in run.polls if run.in_window(p, isr_delay_end, run.restart_s)]
        assert ("Idle" in [p.state for p in run.polls]) == bool(window)
    # About half of the phases: the window is $1 plus one line's parse time out of 50 ms.
    assert 3 <= idle_seen <= 7


@pytest.mark.parametrize("cancel", [b"!", b"\x85"], ids=["feed-hold", "0x85"])
@pytest.mark.parametrize("where", ["planner-full", "during-parse"])
def test_a_line_held_in_mc_line_restarts_at_once_so_no_idle_is_ever_reported(
    cancel: bytes, where: str
) -> None:
    for phase_s in PHASES_S:
        if where == "planner-full":
            run = held_jog(cancel, phase_s, planner_full=True)
        else:
            run = held_jog(cancel, phase_s, during_parse=True)
        # mc_line's checkpoint caught the hold (the line waited there for a planner block, or
        # had just been parsed); when the stop completes mc_line plans that line straight away,
        # with no checkpoint and no parse, and jog_execute starts it in Jog.
        assert run.restart_s == pytest.approx(run.stop_s + 2 * STEP_IDLE_S)
        assert "Idle" not in [p.state for p in run.polls]
        for poll in run.polls:
            if run.in_window(poll, run.stop_s + STEP_IDLE_S, run.restart_s):
                # Asked during st_reset's delay: answered at the next line's end of line, with
                # the machine already on its way again.
                assert poll.state == "Jog", poll.report
                assert poll.value("FS") != "0,0"

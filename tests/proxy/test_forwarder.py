"""The proxy against the in-process simulator on the virtual clock: routing, flow, lock, reset.

The real Host (with its engine) drives a simulated hobby router; a fake sender writes bytes
into a connection of the proxy and keeps everything it is sent.
"""

from __future__ import annotations

import asyncio

from smoothjog.authority.gate import MotionGate
from smoothjog.core.intents import ContinuousIntent, StopIntent
from smoothjog.core.ledger import CONSOLE, ENGINE, HANDSHAKE
from smoothjog.proxy import JOB_LOCK, SENDER
from tests.proxy.vrig import ProxyRig, direct_replies, run_proxy

#: A short job of absolute moves, as a sender streams it (the machine space is -800..0).
JOB = ["G21 G90 G94", "G1 F3000 X-10 Y-5", "X-20 Y-10", "X-5 Y-20 Z-2", "G0 Z-1", "G0 X-2 Y-3"]
#: Where it ends.
JOB_END = (-2.0, -3.0, -1.0)


async def _stream(sender_write: object, lines: list[str]) -> None:
    assert callable(sender_write)
    for line in lines:
        sender_write(line + "\n")


async def _wait(predicate: object, timeout_s: float = 10.0, step_s: float = 0.005) -> None:
    assert callable(predicate)
    async with asyncio.timeout(timeout_s):
        while not predicate():  # noqa: ASYNC110 - the state changes in callbacks, no event
            await asyncio.sleep(step_s)


def test_the_sender_gets_the_banner_on_open_and_the_machine_is_not_reset() -> None:
    async def body(r: ProxyRig) -> None:
        resets = r.host.model.reset_count
        sender = r.sender()
        await asyncio.sleep(0.05)
        assert sender.lines()[0] == "Grbl 1.1h ['$' for help]"
        assert r.host.model.reset_count == resets
        assert r.host.ledger.stats.realtime[SENDER] == 0  # nothing was sent for the open

    run_proxy(body)


def test_query_output_goes_only_to_whoever_asked() -> None:
    async def body(r: ProxyRig) -> None:
        sender = r.sender()
        await asyncio.sleep(0.05)
        got = await sender.ask("$G")
        assert got[0].startswith("[GC:G0 G54")
        assert got[-1] == "ok"
        # smoothjog's own queries (the pendant's console) print nothing at the sender...
        since = len(sender.lines())
        answer = await r.host.query("$#")
        assert any(type(x).__name__ == "Parameter" for x in answer)
        await asyncio.sleep(0.05)
        assert sender.non_reports(since) == []
        # ...and the two ask at once: each gets its own answer only.
        since = len(sender.lines())
        sender.write("$$\n")
        console_lines, _reply = await r.host.console("$G")
        await sender.wait_replies(1, since)
        mine = sender.non_reports(since)
        assert [x for x in mine if x.startswith("[GC:")] == []
        assert mine[-1] == "ok"
        assert sum(1 for x in mine if x.startswith("$")) >= 30  # the whole `$$` listing
        assert [x for x in console_lines if x.startswith("$")] == []
        assert console_lines[0].startswith("[GC:")

    run_proxy(body)


def test_status_reports_reach_the_sender_and_its_question_mark_is_answered() -> None:
    async def body(r: ProxyRig) -> None:
        sender = r.sender()
        await asyncio.sleep(0.3)
        since = len(sender.lines())
        sender.write("?")
        await asyncio.sleep(0.02)
        assert any(x.startswith("<Idle|") for x in sender.lines()[since:])
        assert r.host.ledger.stats.realtime[SENDER] == 1

    run_proxy(body)


def test_a_sender_that_overfills_the_buffer_loses_nothing() -> None:
    """Lines written with no counting at all: held until they fit, all answered in order."""

    async def body(r: ProxyRig) -> None:
        sender = r.sender()
        await asyncio.sleep(0.05)
        peak = 0

        def watch(_resp: object, _now: float) -> None:
            nonlocal peak
            peak = max(peak, r.host.ledger.in_flight_bytes)

        r.host.add_line_listener(watch)
        since = len(sender.lines())
        lines = [f"G4P0.00{k % 10}" if k % 7 else "G5" for k in range(300)]
        sender.write("".join(line + "\n" for line in lines))
        # Meanwhile smoothjog asks its own questions.
        for _ in range(5):
            await r.host.query("$G")
        got = await sender.wait_replies(300, since, timeout_s=30.0)
        assert got == ["error:20" if k % 7 == 0 else "ok" for k in range(300)]
        assert r.firmware.rx.dropped == 0
        assert peak <= 128
        assert r.host.ledger.stats.unowned_replies == 0
        assert r.proxy.stats.lines_forwarded == 300

    run_proxy(body)


def test_line_endings_control_bytes_and_long_lines_get_the_controller_s_own_answers() -> None:
    raw_lines = [
        b"G4P0\r\n",  # two line ends: two oks, as on the machine
        b"G4\tP0\n",  # a tab: dropped by Grbl's reader
        b"G0X1\x7f\n",  # DEL: refused
        b"$\x7f\n",
        b"G4P0 (" + b"c" * 200 + b")\n",  # a comment longer than the RX buffer
        b"G1 " + b"X1" * 50 + b"\n",  # more than Grbl's 79 characters: error:11
        b"\x01\x02\n",  # nothing but control bytes: an empty line
    ]
    expected = direct_replies(raw_lines)

    async def body(r: ProxyRig) -> list[str]:
        sender = r.sender()
        await asyncio.sleep(0.05)
        since = len(sender.lines())
        for raw in raw_lines:
            n = len(sender.replies(since))
            sender.write(raw)
            await sender.wait_replies(n + raw.count(b"\n") + raw.count(b"\r"), since)
        return sender.replies(since)

    got = run_proxy(body)
    assert got == expected
    assert expected == ["ok", "ok", "ok", "error:1", "error:2", "ok", "error:11", "ok"]


def test_a_job_locks_jogging_with_a_sentence_and_it_is_lifted_after_the_job() -> None:
    async def body(r: ProxyRig) -> None:
        sender = r.sender()
        await asyncio.sleep(0.05)
        since = len(sender.lines())
        await _stream(sender.write, JOB)
        await asyncio.sleep(0.01)
        assert r.host.model.jog_lock == JOB_LOCK
        ok, reason = r.host.view().can_jog, r.host.view().reason
        assert not ok
        assert reason == JOB_LOCK
        # A jog asked now does not move anything.
        r.host.set_intent(ContinuousIntent({"X": -1.0}, 1.0))
        await asyncio.sleep(0.2)
        assert r.host.ledger.stats.lines[ENGINE] == 0
        r.host.set_intent(StopIntent())
        await sender.wait_replies(len(JOB), since)
        await _wait(lambda: r.host.model.state == "Idle")
        assert r.host.model.jog_lock == JOB_LOCK  # the quiet time has not passed yet
        await asyncio.sleep(0.6)
        assert r.host.model.jog_lock is None
        assert r.host.view().can_jog
        assert r.host.model.mpos_mm == JOB_END

    run_proxy(body)


def test_the_sender_s_polls_never_lock_jogging() -> None:
    """CNCjs asks `$G` twice a second and `?` four times: jogging must stay free."""

    async def body(r: ProxyRig) -> None:
        sender = r.sender()
        for k in range(40):
            sender.write("?")
            if k % 2:
                sender.write("$G\n")
            await asyncio.sleep(0.25)
            assert r.host.model.jog_lock is None
        assert r.proxy.stats.lines_forwarded == 20

    run_proxy(body)


def test_a_job_that_starts_while_smoothjog_jogs_waits_for_the_jog_to_stop() -> None:
    async def body(r: ProxyRig) -> None:
        sender = r.sender()
        await asyncio.sleep(0.3)
        engine = r.host.engine
        assert engine is not None
        seen_together: list[str] = []
        ledger = r.host.ledger
        record = ledger.record_line

        def record_checked(owner: str, text: str, now_s: float, tag: object = None) -> object:
            if owner == SENDER and any(e.owner == ENGINE for e in ledger.outstanding()):
                seen_together.append(text)
            if owner == SENDER and engine.phase.value != "idle":
                seen_together.append(f"{text} while {engine.phase.value}")
            return record(owner, text, now_s, tag)

        ledger.record_line = record_checked  # type: ignore[method-assign]
        held = asyncio.get_running_loop().create_task(_hold_stick(r, 3.0))
        await _wait(lambda: r.host.model.state == "Jog")
        await asyncio.sleep(0.3)
        since = len(sender.lines())
        await _stream(sender.write, JOB)
        await sender.wait_replies(len(JOB), since, timeout_s=15.0)
        assert seen_together == []
        assert r.proxy.stats.held_for_jog == 1
        fault = engine.view(r.host.now_s()).fault
        assert fault is not None
        assert fault[0] == f"jogging stopped: {JOB_LOCK}"
        await _wait(lambda: r.host.model.jog_lock is None, timeout_s=15.0)
        assert r.host.model.mpos_mm == JOB_END  # the job ends where it says
        # The stick still held does not start a jog again by itself.
        await asyncio.sleep(0.5)
        assert r.host.model.mpos_mm == JOB_END
        held.cancel()

    run_proxy(body)


async def _hold_stick(r: ProxyRig, seconds: float) -> None:
    """A held stick: the same intent every 30 ms, as the pendant's heartbeat sends it."""
    end = r.host.now_s() + seconds
    while r.host.now_s() < end:
        r.host.set_intent(ContinuousIntent({"X": -1.0}, 0.6))
        await asyncio.sleep(0.03)
    r.host.set_intent(StopIntent())


def test_a_sender_s_reset_mid_job_leaves_no_stale_reply_on_either_side() -> None:
    async def body(r: ProxyRig) -> None:
        sender = r.sender()
        await asyncio.sleep(0.05)
        long_job = [f"G1 F2000 X-{10 + k} Y-{k % 5 + 1}" for k in range(40)]
        since = len(sender.lines())
        await _stream(sender.write, long_job)
        await _wait(lambda: r.host.model.state == "Run")
        await asyncio.sleep(0.3)
        answered_before = len(sender.replies(since))
        assert answered_before < len(long_job)
        sender.write(b"\x18")
        await _wait(lambda: any(x.startswith("Grbl 1.1h") for x in sender.lines()[since:]))
        at_banner = len(sender.lines())
        # The host reads the settings again; none of it reaches the sender.
        await _wait(lambda: not r.host.rehandshaking and r.host.model.state is not None)
        await asyncio.sleep(0.5)
        after = sender.lines()[at_banner:]
        assert [x for x in after if not x.startswith(("<", "ALARM", "[MSG:"))] == []
        assert r.host.ledger.stats.unowned_replies == 0
        assert r.host.error is None
        # The sender starts again: exactly its own replies.
        got = await sender.ask("$X")
        assert got[-1] == "ok"
        got = await sender.ask("$G")
        assert got[0].startswith("[GC:")
        assert sender.replies(at_banner) == ["ok", "ok"]
        assert r.host.ledger.stats.replies[HANDSHAKE] == 8  # the first and the second reading

    run_proxy(body)


def test_lines_written_right_after_a_reset_wait_for_the_banner() -> None:
    async def body(r: ProxyRig) -> None:
        sender = r.sender()
        await asyncio.sleep(0.05)
        since = len(sender.lines())
        sender.write(b"G1F100X-50\n\x18$G\n")
        await sender.wait_replies(1, since)
        lines = sender.non_reports(since)
        banner = next(i for i, x in enumerate(lines) if x.startswith("Grbl"))
        assert lines[banner + 1].startswith("[GC:")
        assert lines[banner + 2] == "ok"
        assert sender.replies(since) == ["ok"]  # the G1 was dropped unsent with the reset
        assert r.proxy.stats.lines_dropped == 1

    run_proxy(body)


def test_a_reset_from_smoothjog_drops_the_sender_s_held_lines() -> None:
    async def body(r: ProxyRig) -> None:
        sender = r.sender()
        await asyncio.sleep(0.05)
        since = len(sender.lines())
        executed = r.firmware.lines_executed
        sender.write("G4P1\n" + "G4P0.5\n" * 40)  # far more than fits: most are held here
        await asyncio.sleep(0.2)
        queued = len(r.proxy._queue)
        assert queued > 10
        r.host.send_realtime(CONSOLE, b"\x18")
        await _wait(lambda: r.host.model.reset_count > 0)
        await asyncio.sleep(1.0)
        assert not r.proxy._queue
        stats = r.proxy.stats
        assert stats.lines_dropped >= queued - 2  # a reply may have let one more go meanwhile
        assert stats.lines_dropped + stats.lines_forwarded == 41
        # The dwell cut short by the reset is answered (Grbl does so before it restarts), and
        # nothing after the banner: no line of the sender's ran after the reset.
        lines = sender.non_reports(since)
        banner = next(i for i, x in enumerate(lines) if x.startswith("Grbl"))
        assert [x for x in lines[:banner] if x == "ok"] == ["ok"]
        assert lines[banner + 1 :] == []
        assert r.host.ledger.stats.unowned_replies == 0
        assert r.firmware.lines_executed - executed == 1 + 4  # the G4P1, the handshake again
        assert r.host.ledger.stats.unowned_replies == 0

    run_proxy(body)


def test_smoothjog_jogs_again_once_the_sender_is_idle() -> None:
    async def body(r: ProxyRig) -> None:
        sender = r.sender()
        await asyncio.sleep(0.05)
        since = len(sender.lines())
        await _stream(sender.write, JOB)
        await sender.wait_replies(len(JOB), since)
        await _wait(lambda: r.host.model.jog_lock is None, timeout_s=15.0)
        start = r.host.model.mpos_mm
        assert start is not None
        hold = asyncio.get_running_loop().create_task(_hold_stick(r, 1.0))
        await asyncio.sleep(0.5)
        sender.write("?")  # the sender asks while smoothjog jogs
        await hold
        await _wait(r.host.at_rest)
        end = r.host.model.mpos_mm
        assert end is not None
        assert start[0] - end[0] > 5.0
        reports = [x for x in sender.lines() if x.startswith("<Jog|")]
        assert len(reports) == 1, "the sender's `?` shows smoothjog's jog"

    run_proxy(body)


def test_a_sender_gets_one_status_report_per_question_mark_and_none_unasked() -> None:
    async def body(r: ProxyRig) -> None:
        sender = r.sender()
        # Idle for 2 s while smoothjog polls: none of its reports is the sender's.
        await asyncio.sleep(2.0)
        assert not [x for x in sender.lines() if x.startswith("<")]
        for _ in range(3):
            sender.write("?")
            await asyncio.sleep(0.3)
        assert len([x for x in sender.lines() if x.startswith("<")]) == 3
        # A job streaming meanwhile still gets only what it asks for, and every reply.
        since = len(sender.lines())
        sender.write("G1X-20F3000\n")
        await sender.wait_replies(1, since)
        await asyncio.sleep(1.0)
        assert not [x for x in sender.lines()[since:] if x.startswith("<")]

    run_proxy(body)


def test_a_sender_that_goes_away_mid_job_takes_its_lines_and_its_motion_with_it() -> None:
    # Forty short moves: more than the planner and the RX buffer hold, so some wait here.
    moves = [f"G1 F3000 X{-10 - 4 * i} Y{-10 - 10 * (i % 2)}" for i in range(40)]
    long_job = ["G21 G90 G94", *moves]

    async def body(r: ProxyRig) -> None:
        gate = MotionGate(r.host)
        r.proxy.gated(gate)
        stops: list[str] = []
        gate.add_stop_listener(lambda record: stops.append(record.text))
        sender = r.sender()
        await asyncio.sleep(0.05)
        await _stream(sender.write, long_job)
        await _wait(lambda: r.firmware.status_state() == "Run")
        await asyncio.sleep(0.5)
        assert sender.conn is not None
        sender.conn.close()  # the sender's process died
        await asyncio.sleep(2.0)
        assert r.firmware.status_state() == "Hold:0"
        held_at = r.firmware.mpos_mm()
        await asyncio.sleep(1.0)
        assert r.firmware.mpos_mm() == held_at
        assert held_at[0] > -166.0 + 1.0  # far from where the job would have ended
        assert stops == [
            "stopped by the sender closing its port mid-job: the machine is in feed hold: press"
            " Resume to go on or Reset to end the program"
        ]
        assert r.proxy.stats.lines_dropped > 0

    run_proxy(body)


def test_a_sender_that_goes_away_at_rest_stops_nothing() -> None:
    async def body(r: ProxyRig) -> None:
        gate = MotionGate(r.host)
        r.proxy.gated(gate)
        sender = r.sender()
        assert await sender.ask("$G")
        assert sender.conn is not None
        sender.conn.close()
        await asyncio.sleep(0.5)
        assert gate.last_stop is None
        assert r.firmware.status_state() == "Idle"

    run_proxy(body)

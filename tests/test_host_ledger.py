"""The host's line ledger in use: every owner's replies reach that owner, whoever else writes.

These run the real Host on the virtual-clock loop against the simulator, without the jog engine
(start(jog=False)), so only the routing is under test; tests/test_host.py jogs.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import TypeVar

import pytest

from smoothjog.core.errors import ConnectError
from smoothjog.core.ledger import CONSOLE, HANDSHAKE, Entry, foreign
from smoothjog.core.responses import ErrorReply, GcodeModes, Ok, StatusReport
from smoothjog.host import Host
from smoothjog.links.base import RefusedError
from smoothjog.links.sim import SimLink
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.vclock import VirtualClockLoop

T = TypeVar("T")


def run_virtual(body: Callable[[Host, SimLink], Awaitable[T]]) -> T:
    """Start a jog-less host on a simulated hobby router in virtual time and run body."""
    loop = VirtualClockLoop()

    async def main() -> T:
        link = SimLink(rig=SimRig(GrblFirmware(machine="hobby-router"), LinkModel()))
        await link.open()
        host = Host(link)
        await host.start(jog=False)
        try:
            return await body(host, link)
        finally:
            await host.close()

    try:
        return loop.run_until_complete(main())
    finally:
        loop.close()


def test_the_handshake_goes_through_the_ledger_and_sizes_it() -> None:
    async def body(host: Host, link: SimLink) -> None:
        assert host.ledger.stats.lines[HANDSHAKE] == 4  # $I $$ $G $#
        assert host.ledger.stats.replies[HANDSHAKE] == 4
        assert host.ledger.capacity_bytes == host.model.rx_buffer_bytes == 128
        assert host.ledger.in_flight_bytes == 0

    run_virtual(body)


def test_a_console_query_returns_its_output_and_reply() -> None:
    async def body(host: Host, link: SimLink) -> None:
        got = await host.query("$G")
        assert isinstance(got[0], GcodeModes)
        assert isinstance(got[-1], Ok)
        bad = await host.query("G5")
        assert bad[-1] == ErrorReply(20)  # unsupported command: the console sees its own error

    run_virtual(body)


def test_a_line_the_link_refuses_is_never_counted_in_the_ledger() -> None:
    async def body(host: Host, link: SimLink) -> None:
        for text in ("G0 X1 ?", "G0\nX1", "G0 X1 \u00b5"):
            with pytest.raises(RefusedError):
                await host.write_line(CONSOLE, text)
        assert host.ledger.stats.lines[CONSOLE] == 0
        assert host.ledger.in_flight_bytes == 0
        # The console still works: nothing was left unanswered in the count.
        lines, reply = await host.console("$G")
        assert reply == Ok()
        assert lines[0].startswith("[GC:")

    run_virtual(body)


def test_interleaved_owners_each_get_their_own_replies() -> None:
    """A foreign sender's lines and the console's, interleaved on the wire, never mix."""

    async def body(host: Host, link: SimLink) -> None:
        got: list[tuple[str, str, object]] = []

        def on_foreign(entry: Entry, resp: Ok | ErrorReply, now_s: float) -> None:
            got.append((entry.owner, entry.text, resp))

        host.add_reply_handler(foreign("cncjs"), on_foreign)
        for k in range(30):
            await host.write_line(foreign("cncjs"), "G5" if k % 3 == 0 else "$G")
        replies = [await host.query(f"G4P0.00{k}") for k in range(5)]
        await asyncio.sleep(0.5)
        assert [r[-1] for r in replies] == [Ok()] * 5
        assert len(got) == 30
        assert [resp for _o, text, resp in got if text == "G5"] == [ErrorReply(20)] * 10
        assert {resp for _o, text, resp in got if text == "$G"} == {Ok()}
        assert host.ledger.stats.replies == {HANDSHAKE: 4, "foreign:cncjs": 30, CONSOLE: 5}
        assert host.ledger.stats.unowned_replies == 0
        # The controller never dropped a byte: every line was held until it fitted.
        assert link.firmware.rx.dropped == 0

    run_virtual(body)


def test_write_line_waits_for_room_in_the_rx_buffer() -> None:
    """Lines beyond what the controller's 128 bytes hold wait; none is counted past the size."""

    async def body(host: Host, link: SimLink) -> None:
        peak = 0

        def watch(resp: object, now_s: float) -> None:
            nonlocal peak
            peak = max(peak, host.ledger.in_flight_bytes)

        host.add_line_listener(watch)
        line = "G4P0.01" + " " * 50  # 58 bytes: two fit, a third waits
        await asyncio.gather(*(host.write_line(foreign("x"), line) for _ in range(6)))
        assert host.ledger.in_flight_bytes <= 128
        assert peak <= 128
        await asyncio.sleep(0.5)
        assert host.ledger.stats.replies[foreign("x")] == 6

    run_virtual(body)


def test_status_reports_reach_every_listener() -> None:
    async def body(host: Host, link: SimLink) -> None:
        seen: list[object] = []
        host.add_line_listener(lambda resp, now_s: seen.append(resp))
        host.send_realtime(CONSOLE, b"?")
        await asyncio.sleep(0.05)
        assert any(isinstance(r, StatusReport) for r in seen)
        assert host.ledger.stats.realtime[CONSOLE] == 1

    run_virtual(body)


def test_a_console_line_lost_to_a_reset_fails_in_words() -> None:
    """A reset empties the controller's buffer: the ledger forgets its lines, and says so."""

    async def body(host: Host, link: SimLink) -> None:
        dwell = asyncio.ensure_future(host.query("G4P2"))  # a 2 s dwell
        waiting = asyncio.ensure_future(host.query("$G"))  # still in the RX buffer behind it
        await asyncio.sleep(0.1)
        host.send_realtime(CONSOLE, b"\x18")
        with pytest.raises(ConnectError, match="reset before it answered '\\$G'"):
            await waiting
        await asyncio.gather(dwell, return_exceptions=True)
        assert host.ledger.in_flight_bytes == 0
        assert host.ledger.stats.lost_to_reset >= 1

    run_virtual(body)


def test_a_second_writer_during_a_held_jog_changes_nothing_for_either() -> None:
    """CNCjs-style `$G` every 400 ms and `?` every 250 ms while smoothjog streams a jog.

    The engine gets only its own replies, the other writer all of its own, no byte is ever
    dropped by the controller's RX buffer, and the jog holds its speed and stops on the path.
    """
    from bench import measure

    from smoothjog.core.intents import ContinuousIntent, StopIntent
    from smoothjog.core.ledger import ENGINE
    from smoothjog.virtual import VirtualHost

    rig = SimRig(GrblFirmware(machine="hobby-router"), LinkModel())
    with VirtualHost(rig) as vs:
        vs.handshake()
        other = foreign("cncjs")
        answers: list[Ok | ErrorReply] = []
        vs.host.add_reply_handler(other, lambda entry, resp, now_s: answers.append(resp))

        async def status_polls() -> None:
            for _ in range(20):
                vs.host.send_realtime(other, b"?")
                await asyncio.sleep(0.25)

        async def gcode_polls() -> None:
            for _ in range(12):
                await vs.host.write_line(other, "$G")
                await asyncio.sleep(0.4)

        t0 = vs.now_s
        tasks = [vs.loop.create_task(status_polls()), vs.loop.create_task(gcode_polls())]
        vs.set_intent(ContinuousIntent({"X": -1.0}, 1.0))
        vs.run_until(t0 + 5.0)
        vs.set_intent(StopIntent())
        assert vs.run_until_idle(5.0)
        vs.run_until(vs.now_s + 0.5)
        assert all(t.done() for t in tasks)
        engine = vs.engine
        assert engine is not None
        stats = vs.host.ledger.stats
        assert stats.unowned_replies == 0
        assert stats.replies[ENGINE] == stats.lines[ENGINE] == engine.stats.lines_sent
        assert len(answers) == stats.lines[other] == 12
        assert set(answers) == {Ok()}
        assert engine.stats.error_replies == 0
        assert rig.firmware.rx.dropped == 0
        assert not [e for e in vs.events if e.kind == "fault"]
        share, dips = measure.hold_quality(rig.trace, t0 + 0.5, t0 + 5.0, 5000 / 60)
        assert share > 0.98
        assert dips == 0
        assert engine.stats.stops[-1].tracked_error_steps <= 1.0


def test_query_output_is_routed_to_the_owner_that_asked() -> None:
    """[GC:] of another owner's `$G` reaches the routed listeners as that owner's, not all's."""

    async def body(host: Host, link: SimLink) -> None:
        other = foreign("sender")
        routed: list[tuple[str, str | None]] = []

        def watch(raw: bytes, resp: object, route: Entry | None) -> None:
            if not isinstance(resp, StatusReport):
                routed.append((raw.decode(), None if route is None else route.owner))

        host.add_routed_listener(watch)
        host.add_reply_handler(other, lambda entry, resp, now_s: None)
        await host.write_line(other, "$G")
        lines, reply = await host.console("$#")  # the console asks while $G is answered
        await asyncio.sleep(0.1)
        assert reply == Ok()
        assert not [x for x in lines if x.startswith("[GC:")]  # not the console's own
        assert lines[0].startswith("[G54:")
        gc = [owner for text, owner in routed if text.startswith("[GC:")]
        assert gc == [other]
        params = {owner for text, owner in routed if text.startswith("[G5")}
        assert params == {CONSOLE}
        assert [owner for text, owner in routed if text == "ok"] == [other, CONSOLE]

    run_virtual(body)


def test_output_with_no_line_waiting_is_nobody_s_and_a_banner_is_everyone_s() -> None:
    async def body(host: Host, link: SimLink) -> None:
        routed: list[tuple[str, str | None]] = []
        everything: list[object] = []
        host.add_routed_listener(
            lambda raw, resp, route: routed.append(
                (raw.decode(), None if route is None else route.owner)
            )
        )
        host.add_line_listener(lambda resp, now_s: everything.append(resp))
        host._on_line(b"[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]", host.now_s())
        assert routed == []  # nobody asked for it
        assert len(everything) == 1  # the plain listeners still see every line
        host.send_realtime(CONSOLE, b"\x18")
        assert host.reset_pending
        await asyncio.sleep(0.6)
        assert not host.reset_pending
        banners = [(text, owner) for text, owner in routed if text.startswith("Grbl")]
        assert banners == [("Grbl 1.1h ['$' for help]", None)]

    run_virtual(body)


def test_startup_lines_after_a_reset_go_to_everyone() -> None:
    """`>G54:ok` runs at the restart, before any line is read: nobody's query, though the
    re-handshake's first line may already wait."""

    async def body(host: Host, link: SimLink) -> None:
        routed: list[tuple[str, str | None]] = []
        host.add_routed_listener(
            lambda raw, resp, route: routed.append(
                (raw.decode(), None if route is None else route.owner)
            )
        )
        await host.write_line(CONSOLE, "G4P1")
        host._on_line(b"Grbl 1.1h ['$' for help]", host.now_s())
        await host.write_line(HANDSHAKE, "$I")
        host._on_line(b">G54:ok", host.now_s())
        assert (">G54:ok", None) in routed
        host._on_line(b"ok", host.now_s())
        await host.write_line(CONSOLE, "$H")
        host._on_line(b">G54:ok", host.now_s())  # after `$H`: that line's
        assert routed[-1] == (">G54:ok", CONSOLE)

    run_virtual(body)


def test_jog_locks_of_several_sources_combine() -> None:
    async def body(host: Host, link: SimLink) -> None:
        assert host.model.jog_lock is None
        host.set_jog_lock("relay", "a CNCjs job")
        host.set_jog_lock("sender", "the sender's job")
        assert host.model.jog_lock == "a CNCjs job"
        host.set_jog_lock("relay", None)
        assert host.model.jog_lock == "the sender's job"
        host.set_jog_lock("sender", None)
        assert host.model.jog_lock is None

    run_virtual(body)

"""The host in real time over the in-process simulator: jog, stop, reset, close, lost link."""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator, Callable, Mapping

import pytest

from smoothjog.core.engine import EngineEvent
from smoothjog.core.errors import LinkError
from smoothjog.core.intents import ContinuousIntent, StepIntent, StopIntent
from smoothjog.core.responses import Banner
from smoothjog.host import Host
from smoothjog.links.sim import SimLink
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile

#: Generous upper bounds on the wall clock; every wait ends as soon as its condition holds.
WAIT_S = 10.0
CLOSE_S = 10.0
#: hobby-router: X/Y 80 steps/mm, Z 400 steps/mm; it starts homed, Idle at MPos -1,-1,-1.
STEP_MM = (1 / 80, 1 / 80, 1 / 400)
START_MM = (-1.0, -1.0, -1.0)
MAX_RATE_MM_S = (5000 / 60, 5000 / 60, 1500 / 60)


async def eventually(condition: Callable[[], bool], what: str, timeout_s: float = WAIT_S) -> None:
    """Wait until condition() holds; fail the test saying what did not happen."""
    loop = asyncio.get_running_loop()
    deadline_s = loop.time() + timeout_s
    while not condition():
        if loop.time() > deadline_s:
            pytest.fail(f"{what}: not within {timeout_s} s")
        await asyncio.sleep(0.005)


async def close_within(session: Host, timeout_s: float = CLOSE_S) -> None:
    """session.close(), failing the test (after cleaning up) if it does not return in time."""
    closer = asyncio.create_task(session.close())
    done, _ = await asyncio.wait({closer}, timeout=timeout_s)
    if closer in done:
        closer.result()
        return
    # close() is stuck: tear everything down so that no task outlives the test, then fail.
    await session.link.close()
    for task in [closer, *(t for t in asyncio.all_tasks() if t.get_name().startswith("smooth"))]:
        for _ in range(100):
            if task.done():
                break
            task.cancel()
            await asyncio.sleep(0.01)
        if task.done() and not task.cancelled():
            task.exception()  # retrieved: a LinkError from a task the link closed under
    pytest.fail(f"Host.close() did not return within {timeout_s} s")


@contextlib.asynccontextmanager
async def open_session(
    firmware: str = "grbl",
) -> AsyncIterator[tuple[Host, SimLink, list[EngineEvent]]]:
    """A started session over a SimLink to a simulated hobby-router; closed afterwards."""
    link = SimLink(GrblFirmware(get_firmware_profile(firmware), "hobby-router"))
    await link.open()
    events: list[EngineEvent] = []
    session = Host(link, handshake_timeout_s=WAIT_S, on_event=events.append)
    try:
        await session.start()
        yield session, link, events
    finally:
        await close_within(session)


def assert_at_rest_where_tracked(session: Host, link: SimLink) -> None:
    """The controller is Idle and host and ground truth agree to within one step per axis."""
    assert link.firmware.status_state() == "Idle"
    assert session.model.state == "Idle"
    truth = link.firmware.mpos_mm()
    assert session.model.mpos_mm is not None
    for axis, (host_mm, real_mm) in enumerate(zip(session.model.mpos_mm, truth, strict=True)):
        assert abs(host_mm - real_mm) <= STEP_MM[axis] + 1e-9


@pytest.mark.parametrize("firmware", ["grbl", "grblhal", "fluidnc"])
async def test_start_returns_the_model(firmware: str) -> None:
    """start(): the handshake's model, with the firmware, its settings and the state."""
    async with open_session(firmware) as (session, link, _events):
        model = session.model
        assert model.firmware == firmware
        assert model.state == "Idle"
        assert model.mpos_mm == START_MM
        assert model.axis_letters == ("X", "Y", "Z")
        assert model.axis_max_rate_mm_min() == (5000.0, 5000.0, 1500.0)
        assert session.engine is not None
        assert session.engine.limits.axes == ("X", "Y", "Z")
        assert session.view().can_jog
        assert not session.busy()
        assert session.link_error is None
        assert link.firmware.mpos_mm() == START_MM


async def test_start_returns_the_session_model() -> None:
    """The model start() returns is the one the session keeps up to date."""
    link = SimLink(GrblFirmware(machine="hobby-router"))
    await link.open()
    session = Host(link, handshake_timeout_s=WAIT_S)
    try:
        model = await session.start()
        assert model is session.model
        assert model.version == "1.1h"
    finally:
        await close_within(session)


@pytest.mark.parametrize(
    ("axes", "speed"),
    [
        ({"X": -1.0}, 0.5),
        ({"X": -0.7, "Y": -0.7}, 1.0),
        ({"Z": -1.0}, 0.8),
        ({"Y": -0.3}, 1.0),
    ],
)
async def test_a_continuous_jog_moves_and_a_stop_intent_stops(
    axes: Mapping[str, float], speed: float
) -> None:
    """Hold a deflection: the machine moves that way; StopIntent: it stops where it is tracked."""
    async with open_session() as (session, link, events):
        session.set_intent(ContinuousIntent(dict(axes), speed))
        moving = [i for i, a in enumerate("XYZ") if a in axes]

        def moved_enough() -> bool:
            now_mm = link.firmware.mpos_mm()
            return all(abs(now_mm[i] - START_MM[i]) > 1.0 for i in moving)

        await eventually(moved_enough, f"the machine moving {axes}")
        assert link.firmware.status_state() == "Jog"
        session.set_intent(StopIntent())
        await session.wait_idle(WAIT_S)
        assert not session.busy()

        assert_at_rest_where_tracked(session, link)
        final_mm = link.firmware.mpos_mm()
        for i, axis in enumerate("XYZ"):
            if axis in axes:
                assert math.copysign(1.0, final_mm[i] - START_MM[i]) == math.copysign(
                    1.0, axes[axis]
                )
            else:
                assert final_mm[i] == START_MM[i]
        assert session.engine is not None
        stops = session.engine.stats.stops
        assert len(stops) == 1
        assert stops[0].cancelled
        assert stops[0].tracked_error_steps <= 1.0
        assert all(
            abs(a - b) <= STEP_MM[i] + 1e-9
            for i, (a, b) in enumerate(zip(stops[0].mpos_mm, final_mm, strict=True))
        )
        assert [e for e in events if e.kind == "fault"] == []
        # Ground truth: no axis ever ran faster than deflection x speed x the fastest axis's
        # rate allows, nor faster than its own $11x.
        for seg in link.firmware.trace:
            dt_s = seg.t1_s - seg.t0_s
            if dt_s < 0.005:
                continue
            for i, axis in enumerate("XYZ"):
                axis_mm_s = abs(seg.end_mm[i] - seg.start_mm[i]) / dt_s
                asked_mm_s = max(MAX_RATE_MM_S) * speed * abs(axes.get(axis, 0.0))
                limit_mm_s = min(asked_mm_s, MAX_RATE_MM_S[i])
                assert axis_mm_s <= limit_mm_s * 1.02 + STEP_MM[i] / dt_s


async def test_a_controller_reset_mid_session_is_survived() -> None:
    """Ctrl-X while idle: the session re-reads the controller, then jogs again."""
    async with open_session() as (session, link, events):
        assert session.engine is not None
        # A setting changed behind the host's back (another sender); the reset must reveal it.
        link.firmware.settings.force(110, 4000.0)
        link.send_realtime(b"\x18")

        def rehandshaken() -> bool:
            assert session.engine is not None
            return (
                session.model.reset_count == 1
                and session.model.state == "Idle"
                and session.engine.limits.max_rate_mm_min[0] == 4000.0
            )

        await eventually(rehandshaken, "the re-handshake after the reset")
        assert session.model.axis_max_rate_mm_min()[0] == 4000.0
        assert any("reset" in e.text for e in events)
        assert session.link_error is None

        # A step lands exactly.
        session.set_intent(StepIntent("X", -2.0, 0.5))
        await eventually(session.busy, "the step starting", timeout_s=1.0)
        await session.wait_idle(WAIT_S)
        assert link.firmware.mpos_mm() == (-3.0, -1.0, -1.0)

        # A stick jog moves and stops.
        session.set_intent(ContinuousIntent({"Y": -1.0}, 1.0))
        await eventually(lambda: link.firmware.mpos_mm()[1] < -3.0, "the jog after the reset")
        session.set_intent(StopIntent())
        await session.wait_idle(WAIT_S)
        assert_at_rest_where_tracked(session, link)
        assert link.firmware.mpos_mm()[0] == -3.0
        stops = session.engine.stats.stops
        assert stops
        assert stops[-1].tracked_error_steps <= 1.0
        assert not [e for e in events if e.kind == "fault" and "reset" not in e.text]


async def test_a_controller_held_right_after_a_reset_keeps_the_session_until_resumed() -> None:
    """Ctrl-X, then someone's `!` at once: the settings cannot be read while the controller is
    in Hold. The session stays, says why, and reads them once someone resumes the controller."""
    async with open_session() as (session, link, events):
        link.firmware.settings.force(110, 4000.0)

        def hold_after_the_banner(resp: object, _now_s: float) -> None:
            if isinstance(resp, Banner):
                link.send_realtime(b"!")  # on the wire before the re-handshake's first line

        session.add_line_listener(hold_after_the_banner)
        link.send_realtime(b"\x18")
        await eventually(
            lambda: any("restarted and is in Hold" in e.text for e in events),
            "the message that the held controller reads no line",
        )
        assert session.error is None
        assert session.link_error is None
        assert session.rehandshaking
        assert link.firmware.status_state() == "Hold:0"
        assert not session.view().can_jog
        await asyncio.sleep(0.6)  # it waits, and asks again and again, without giving up
        assert session.error is None
        assert session.rehandshaking

        link.send_realtime(b"~")  # the user resumes it
        await eventually(lambda: not session.rehandshaking, "the re-handshake after the resume")
        assert session.engine is not None
        assert session.engine.limits.max_rate_mm_min[0] == 4000.0
        assert session.error is None
        session.set_intent(StepIntent("X", -2.0, 0.5))
        await eventually(session.busy, "the step starting", timeout_s=1.0)
        await session.wait_idle(WAIT_S)
        assert link.firmware.mpos_mm() == (-3.0, -1.0, -1.0)


@pytest.mark.parametrize("firmware", ["grbl", "grblhal", "fluidnc"])
async def test_close_while_jogging_stops_the_machine_first(firmware: str) -> None:
    """close() during a jog: the full stop, then the link closes; the machine is left at rest."""
    link = SimLink(GrblFirmware(get_firmware_profile(firmware), "hobby-router"))
    await link.open()
    session = Host(link, handshake_timeout_s=WAIT_S)
    try:
        await session.start()
        session.set_intent(ContinuousIntent({"X": -1.0, "Y": -0.5}, 1.0))
        await eventually(lambda: link.firmware.mpos_mm()[0] < -10.0, "the machine moving")
        # The engine is jogging (on a loaded machine the controller may be between two lines
        # for an instant, so its own state is not what is asserted here).
        assert session.busy()
    finally:
        await close_within(session)
    assert session.engine is not None
    assert_at_rest_where_tracked(session, link)
    stops = session.engine.stats.stops
    assert len(stops) == 1
    assert stops[0].cancelled
    assert stops[0].tracked_error_steps <= 1.0
    with pytest.raises(LinkError):
        await link.read_line()
    with pytest.raises(LinkError):
        link.send_realtime(b"?")


@pytest.mark.parametrize("jogging", [False, True], ids=["idle", "jogging"])
async def test_a_link_closed_under_the_session_is_surfaced(jogging: bool) -> None:
    """The link goes away: session.link_error says so and close() still returns."""
    async with open_session() as (session, link, _events):
        if jogging:
            session.set_intent(ContinuousIntent({"X": -1.0}, 0.5))
            await eventually(lambda: link.firmware.mpos_mm()[0] < -2.0, "the machine moving")
        await link.close()
        await eventually(lambda: session.link_error is not None, "session.link_error")
        error = session.link_error
        assert isinstance(error, LinkError)
        assert "closed" in str(error)
        if jogging:
            # Still busy with the jog: waiting for rest cannot succeed and says why.
            with pytest.raises(LinkError) as caught:
                await session.wait_idle(WAIT_S)
            assert caught.value is error


class _PlainLink(SimLink):
    """A link with only the required contract: no read callback, and every line may wait."""

    def __init__(self, *, stall_every: int = 0) -> None:
        super().__init__(GrblFirmware(machine="hobby-router"))
        self.stall_every = stall_every
        self.wire: list[str] = []
        self._count = 0

    def subscribe(self, on_line: object, on_end: object) -> bool:
        return False

    def _write_line_nowait(self, data: bytes) -> bool:
        self._count += 1
        if self.stall_every and self._count % self.stall_every == 0:
            return False  # as a link whose queue is past its high-water mark
        self.wire.append(data.decode().strip())
        return super()._write_line_nowait(data)

    async def _write_line(self, data: bytes) -> None:
        await asyncio.sleep(0.002)  # the wire drains a little later
        self.wire.append(data.decode().strip())
        await super()._write_line(data)


@pytest.mark.parametrize("stall_every", [0, 7])
async def test_a_link_without_callbacks_or_room_still_jogs_in_ledger_order(
    stall_every: int,
) -> None:
    """The reader task and the waiting writer: the host jogs and stops, and every line reaches
    the wire in the order the ledger recorded it (the count of ok's depends on that order)."""
    link = _PlainLink(stall_every=stall_every)
    await link.open()
    session = Host(link, handshake_timeout_s=WAIT_S)
    recorded: list[str] = []
    record = session.ledger.record_line

    def spy(owner: str, text: str, now_s: float, tag: object = None) -> object:
        recorded.append(text)
        return record(owner, text, now_s, tag)

    session.ledger.record_line = spy  # type: ignore[method-assign,assignment]
    try:
        await session.start()
        assert not session._tasks or session._tasks[0].get_name() == "smoothjog-reader"
        session.set_intent(ContinuousIntent({"X": -1.0}, 1.0))
        await eventually(lambda: link.firmware.mpos_mm()[0] < START_MM[0] - 5.0, "moving")
        session.set_intent(StopIntent())
        await session.wait_idle(WAIT_S)
        assert_at_rest_where_tracked(session, link)
        assert link.wire == recorded
        if stall_every:
            assert len(recorded) > stall_every  # the waiting writer really ran
    finally:
        await close_within(session)

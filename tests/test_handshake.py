"""The connect handshake against the scripted Grbl over real pty and TCP links, and the summary."""

from __future__ import annotations

import asyncio

import pytest

from smoothjog.core.errors import ConnectError, LinkError
from smoothjog.core.machine import MachineModel
from smoothjog.core.responses import parse_response
from smoothjog.handshake import ControllerResetError, format_summary, handshake
from smoothjog.links.serial import SerialLink
from smoothjog.links.tcp import TcpLink
from tests.peers import PtyPeer, ScriptedGrbl, TcpPeer

QUERY_LINES = [b"$I", b"$$", b"$G", b"$#"]


async def test_handshake_over_serial_with_banner() -> None:
    """A freshly reset Grbl on a serial port: everything lands in the model."""
    grbl = ScriptedGrbl(mpos=(-10.0, -20.0, -1.5), wco=(-5.0, -5.0, 0.0))
    grbl.settings[110] = "3000.000"
    grbl.settings[122] = "50.000"
    with PtyPeer(grbl, boot_s=0.01) as peer:
        async with SerialLink(peer.path, wait_banner_s=30) as link:
            model = await handshake(link, timeout_s=10)
    assert (model.firmware, model.version) == ("grbl", "1.1h")
    assert (model.planner_blocks, model.rx_buffer_bytes) == (15, 128)
    assert model.axis_max_rate_mm_min() == (3000.0, 500.0, 500.0)
    assert model.axis_accel_mm_s2() == (10.0, 10.0, 50.0)
    assert model.state == "Idle"
    assert model.mpos_mm == (-10.0, -20.0, -1.5)
    assert model.wpos_mm == (-5.0, -15.0, -1.5)
    assert model.modal.units == "G21"
    assert "G54" in model.offsets_mm
    assert grbl.received_lines == QUERY_LINES
    assert grbl.received_realtime == [ord("?")]


async def test_handshake_over_tcp_without_banner() -> None:
    """A network controller that prints no banner on connect."""
    with TcpPeer() as peer:
        async with TcpLink(peer.host, peer.port) as link:
            model = await handshake(link, timeout_s=10)
    assert model.version == "1.1h"
    assert model.state == "Idle"
    assert peer.grbl.received_lines == QUERY_LINES


async def test_given_model_is_filled_and_returned() -> None:
    """The session can pass its own model to redo the handshake after a reset."""
    mine = MachineModel()
    with TcpPeer() as peer:
        async with TcpLink(peer.host, peer.port) as link:
            assert await handshake(link, timeout_s=10, model=mine) is mine
    assert mine.version == "1.1h"


async def test_reset_mid_handshake_starts_over_once() -> None:
    """A banner instead of the `$G` reply: the queries start again from `$I`."""
    grbl = ScriptedGrbl(reset_on="$G")
    with TcpPeer(grbl) as peer:
        async with TcpLink(peer.host, peer.port) as link:
            model = await handshake(link, timeout_s=10)
    assert grbl.received_lines == [b"$I", b"$$", b"$G", *QUERY_LINES]
    assert model.state == "Idle"
    assert model.reset_count == 1


async def test_controller_that_keeps_resetting_is_an_error() -> None:
    """Two resets after answers: ConnectError saying it keeps resetting."""
    grbl = ScriptedGrbl(reset_on="$G", reset_times=5)
    with TcpPeer(grbl) as peer:
        async with TcpLink(peer.host, peer.port) as link:
            with pytest.raises(ControllerResetError, match=r"reset .* power supply") as info:
                await handshake(link, timeout_s=10)
    assert isinstance(info.value, ConnectError)
    assert grbl.received_lines.count(b"$I") == 2


async def test_controller_resetting_before_any_answer_is_bounded() -> None:
    """A controller that resets on every `$I` ends in ConnectError, not a loop."""
    grbl = ScriptedGrbl(reset_on="$I", reset_times=100)
    with TcpPeer(grbl) as peer:
        async with TcpLink(peer.host, peer.port) as link:
            with pytest.raises(ConnectError, match="reset"):
                await handshake(link, timeout_s=10)
    assert grbl.received_lines.count(b"$I") == 3


async def test_alarm_state_and_refused_queries_are_noted_not_fatal() -> None:
    """In Alarm, an error:9 to a query and an ALARM push still give a model in Alarm."""
    grbl = ScriptedGrbl(
        state="Alarm",
        replies={"$G": ["ALARM:1", "[MSG:Reset to continue]", "error:9"]},
    )
    with TcpPeer(grbl) as peer:
        async with TcpLink(peer.host, peer.port) as link:
            model = await handshake(link, timeout_s=10)
    assert model.state == "Alarm"
    assert model.last_alarm == 1
    assert model.last_error == 9
    assert "Hard limit" in format_summary(model)


async def test_stale_ok_before_a_reply_is_skipped() -> None:
    """An ok that carries no `$I` content (a reply to a pre-reset line) does not end `$I`."""
    grbl = ScriptedGrbl(replies={"$I": ["ok", "[VER:1.1h.20190830:]", "[OPT:VZ,15,128]", "ok"]})
    grbl.settings[111] = "1234.000"
    with TcpPeer(grbl) as peer:
        async with TcpLink(peer.host, peer.port) as link:
            model = await handshake(link, timeout_s=10)
    assert model.option_codes == "VZ"
    assert model.axis_max_rate_mm_min()[1] == 1234.0


async def test_messages_between_replies_are_tolerated() -> None:
    """`[MSG:...]` and blank lines in the middle of `$$` do not disturb it."""
    settings = ["$0=10", "[MSG:Caution: Unlocked]", "", "$110=999.000", "ok"]
    grbl = ScriptedGrbl(replies={"$$": settings})
    with TcpPeer(grbl) as peer:
        async with TcpLink(peer.host, peer.port) as link:
            model = await handshake(link, timeout_s=10)
    assert model.axis_max_rate_mm_min()[0] == 999.0
    assert model.last_message == "Caution: Unlocked"


async def test_no_status_report_is_tolerated() -> None:
    """A controller that makes no status report (homing, limit alarm) still connects."""
    with TcpPeer(ScriptedGrbl(answer_status=False)) as peer:
        async with TcpLink(peer.host, peer.port) as link:
            model = await handshake(link, timeout_s=0.3)
    assert model.version == "1.1h"
    assert model.state is None
    assert "unknown" in format_summary(model)


async def test_silent_serial_peer_times_out_with_baud_hint() -> None:
    """No answer at all on a serial port: ConnectError naming the port, time and baud."""
    with PtyPeer(ScriptedGrbl(silent=True), banner_on_open=False) as peer:
        async with SerialLink(peer.path, wait_banner_s=0) as link:
            with pytest.raises(ConnectError) as info:
                await handshake(link, timeout_s=0.3)
    assert str(info.value) == (
        f"no answer from {peer.path} at 115200 baud within 0.3 s:"
        " is it a Grbl controller, and is the baud rate right?"
    )


async def test_a_controller_held_in_feed_hold_is_named_not_called_silent() -> None:
    """Someone's `!` left it in Hold:0: it answers `?` but no line; say so, not "is it Grbl"."""
    with TcpPeer(ScriptedGrbl(state="Hold:0")) as peer:
        async with TcpLink(peer.host, peer.port) as link:
            with pytest.raises(ConnectError) as info:
                await handshake(link, timeout_s=0.3)
    assert "reports Hold:0 and reads no line in that state" in str(info.value)
    assert "resume it (cycle start, ~)" in str(info.value)


async def test_silent_tcp_peer_times_out_without_baud_hint() -> None:
    """No answer over TCP: the message does not talk about baud rates."""
    with TcpPeer(ScriptedGrbl(silent=True)) as peer:
        async with TcpLink(peer.host, peer.port) as link:
            with pytest.raises(
                ConnectError, match=r"no answer from tcp://.* within 0\.3 s"
            ) as info:
                await handshake(link, timeout_s=0.3)
    assert "baud" not in str(info.value)


@pytest.mark.parametrize("reply", [b"Hello, I am a modem\r\n", b"\xfe\x81garbage\xf0\r\n"])
async def test_peer_that_is_not_grbl(reply: bytes) -> None:
    """Only lines that are not Grbl's: ConnectError saying it is the wrong device."""
    with TcpPeer(ScriptedGrbl(foreign_reply=reply)) as peer:
        async with TcpLink(peer.host, peer.port) as link:
            with pytest.raises(ConnectError, match="not like a Grbl controller"):
                await handshake(link, timeout_s=0.3)


async def test_noise_flood_is_refused_early() -> None:
    """A stream of noise lines (wrong baud) fails fast, before the timeout."""
    with TcpPeer(ScriptedGrbl(foreign_reply=b"\xff\xfe\r\n" * 50)) as peer:
        async with TcpLink(peer.host, peer.port) as link:
            with pytest.raises(ConnectError, match=r"baud|wrong device"):
                await handshake(link, timeout_s=60)


async def test_peer_gone_during_handshake_is_a_link_error() -> None:
    """The device vanishing mid-handshake surfaces as a LinkError, not a hang."""
    peer = PtyPeer(ScriptedGrbl(silent=True), banner_on_open=False)
    try:
        async with SerialLink(peer.path, wait_banner_s=0) as link:
            peer.close()
            with pytest.raises(LinkError, match="lost"):
                await handshake(link, timeout_s=60)
    finally:
        peer.close()


def _model(*lines: str) -> MachineModel:
    """A model fed the given controller lines."""
    model = MachineModel()
    for line in lines:
        model.apply(parse_response(line))
    return model


@pytest.mark.parametrize(
    ("lines", "expected"),
    [
        (["Grbl 1.1h ['$' for help]", "[VER:1.1h.20190830:]", "[OPT:V,15,128]"],
         ["grbl 1.1h, build 20190830, options V", "15 blocks, RX buffer 128 bytes"]),
        (["$110=3000.000", "$111=2500.000", "$112=800.000", "$120=100.000", "$132=80.000"],
         ["3000 mm/min", "2500 mm/min", "800 mm/min", "100 mm/s²", "80 mm"]),
        (["$20=1", "$22=1", "$130=300.000", "$131=200.000", "$132=200.000"],
         ["Soft limits   on (X -300..0, Y -200..0, Z -200..0 mm", "Homing        on"]),
        (["$20=0"], ["Soft limits   off", "Homing        off"]),
        (["$13=1"], ["inches ($13=1)"]),
        (["$10=0"], ["Reports       WPos, mm"]),
        (["ALARM:2", "<Alarm|MPos:-1.000,-2.000,-3.000|FS:0,0>"],
         ["State         Alarm: locked", "ALARM:2",
          "MPos          X -1.000  Y -2.000  Z -3.000 mm"]),
        (["<Idle|MPos:1.000,2.000,3.000|FS:0,0|WCO:1.000,1.000,1.000>"],
         ["State         Idle: ready", "WPos          X 0.000  Y 1.000  Z 2.000 mm"]),
        (["<Hold:0|MPos:0.000,0.000,0.000|FS:0,0>"], ["Hold:0: feed hold"]),
        ([], ["State         unknown", "MPos          unknown"]),
    ],
)  # fmt: skip
def test_summary_contents(lines: list[str], expected: list[str]) -> None:
    """The summary shows what the controller told us, in words."""
    summary = format_summary(_model(*lines))
    for text in expected:
        assert text in summary, f"{text!r} not in\n{summary}"


async def test_a_held_controller_is_named_long_before_the_timeout() -> None:
    """A query unanswered for STATUS_CHECK_S asks `?` once: a Hold:0 is said then, not after
    the whole timeout (a `!` just after a reset left the re-handshake waiting 5 s)."""
    with TcpPeer(ScriptedGrbl(state="Hold:0")) as peer:
        async with TcpLink(peer.host, peer.port) as link:
            with pytest.raises(ConnectError) as info:
                await asyncio.wait_for(handshake(link, timeout_s=60.0), 20.0)
    assert "reports Hold:0 and reads no line in that state" in str(info.value)

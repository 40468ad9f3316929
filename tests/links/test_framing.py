"""LineFramer: bytes pushed straight in, lines checked; every split point and EOL style."""

from __future__ import annotations

import pytest

from smoothjog.links.framing import LineFramer


def feed_all(framer: LineFramer, chunks: list[bytes]) -> list[bytes]:
    """Feed the chunks in order and collect every line."""
    lines: list[bytes] = []
    for chunk in chunks:
        lines.extend(framer.feed(chunk))
    return lines


@pytest.mark.parametrize(
    ("chunks", "expected"),
    [
        ([b"ok\r\n"], [b"ok"]),
        ([b"ok\n"], [b"ok"]),
        ([b"ok\r"], [b"ok"]),
        ([b"ok\r", b"\n", b"ok\r\n"], [b"ok", b"ok"]),
        ([b"o", b"k", b"\r", b"\n"], [b"ok"]),
        ([b"ok\r\n\r\n"], [b"ok", b""]),
        ([b"\r\nGrbl 1.1h ['$' for help]\r\n"], [b"", b"Grbl 1.1h ['$' for help]"]),
        ([b"a\rb\nc\r\nd"], [b"a", b"b", b"c"]),
        ([b"a\n\rb\r\n"], [b"a", b"", b"b"]),
        ([b"a\r", b"\r\n"], [b"a", b""]),
        ([b"a\r", b"b\r\n"], [b"a", b"b"]),
        ([b"", b"ok", b"", b"\r\n"], [b"ok"]),
        ([b"<Idle|MPos:0.000,0.000,0.000|FS:0,0>\r\nok\r\nerror:9\r\n"],
         [b"<Idle|MPos:0.000,0.000,0.000|FS:0,0>", b"ok", b"error:9"]),
    ],
)  # fmt: skip
def test_lines_from_chunks(chunks: list[bytes], expected: list[bytes]) -> None:
    """Every end-of-line style ends a line, CRLF counts once even split across reads."""
    assert feed_all(LineFramer(), chunks) == expected


def test_every_split_point_gives_the_same_lines() -> None:
    """A stream cut anywhere in two reads frames exactly like the whole stream."""
    stream = b"\r\nGrbl 1.1h ['$' for help]\r\n[MSG:'$H'|'$X' to unlock]\r\nok\rerror:8\nok\r\n"
    whole = LineFramer().feed(stream)
    for cut in range(len(stream) + 1):
        assert feed_all(LineFramer(), [stream[:cut], stream[cut:]]) == whole, cut


def test_one_byte_at_a_time() -> None:
    """Lines assembled byte by byte come out whole."""
    stream = b"$0=10\r\n$1=25\r\nok\r\n"
    assert feed_all(LineFramer(), [bytes([b]) for b in stream]) == [b"$0=10", b"$1=25", b"ok"]


def test_burst_of_many_lines_in_one_read() -> None:
    """Hundreds of lines in one read all come out, in order."""
    lines = [f"$1{n:02d}=250.000".encode() for n in range(500)]
    assert LineFramer().feed(b"\r\n".join(lines) + b"\r\n") == lines


def test_unfinished_line_is_held_back() -> None:
    """Bytes without an end stay pending until the end arrives."""
    framer = LineFramer()
    assert framer.feed(b"<Idle|MPos") == []
    assert framer.pending_bytes == len(b"<Idle|MPos")
    assert framer.feed(b":0,0,0>\r\n") == [b"<Idle|MPos:0,0,0>"]
    assert framer.pending_bytes == 0


@pytest.mark.parametrize("chunk_size", [1, 7, 16, 100, 5000])
def test_runaway_line_is_cut_and_the_rest_dropped(chunk_size: int) -> None:
    """A line longer than the cap comes out cut at the cap, once; the next line is intact."""
    framer = LineFramer(max_line_bytes=16)
    stream = b"x" * 100 + b"\r\nok\r\n"
    chunks = [stream[i : i + chunk_size] for i in range(0, len(stream), chunk_size)]
    assert feed_all(framer, chunks) == [b"x" * 16, b"ok"]
    assert framer.overflowed_lines == 1


def test_runaway_without_end_stays_bounded() -> None:
    """Endless noise without an end-of-line never grows the pending buffer past the cap."""
    framer = LineFramer(max_line_bytes=64)
    out: list[bytes] = []
    for _ in range(1000):
        out.extend(framer.feed(b"\xff" * 1000))
        assert framer.pending_bytes <= 64
    assert out == [b"\xff" * 64]
    assert framer.feed(b"\nok\n") == [b"ok"]


def test_line_exactly_at_the_cap_is_whole() -> None:
    """A line of exactly max_line_bytes is not an overflow."""
    framer = LineFramer(max_line_bytes=4)
    assert framer.feed(b"abcd\r\n") == [b"abcd"]
    assert framer.overflowed_lines == 0


def test_clear_forgets_a_half_line() -> None:
    """clear() drops a pending partial line and a pending CR."""
    framer = LineFramer()
    framer.feed(b"garbage\r")
    framer.clear()
    assert framer.feed(b"\nok\r\n") == [b"", b"ok"]


def test_bad_cap_is_refused() -> None:
    """A cap below one byte makes no sense."""
    with pytest.raises(ValueError, match="at least 1"):
        LineFramer(max_line_bytes=0)

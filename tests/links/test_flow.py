"""CharCounter: the byte count, the order of releases, and the protocol faults."""

from __future__ import annotations

import pytest

from smoothjog.core.errors import LinkError
from smoothjog.links.flow import CharCounter, FlowError, OverfillError, UnexpectedAckError


def test_counts_each_line_with_its_newline() -> None:
    """A line costs its length plus the one `\\n`."""
    counter = CharCounter()
    counter.sent("$J=G91X1F100")
    assert counter.in_flight_bytes == len("$J=G91X1F100") + 1
    assert counter.free_bytes == 128 - 13
    assert counter.outstanding == ("$J=G91X1F100",)


def test_releases_oldest_first() -> None:
    """Each ok/error releases the oldest line, whatever was sent after it."""
    counter = CharCounter()
    for line in ("G21", "$J=G91X1F100", ""):
        counter.sent(line)
    assert [counter.acknowledged() for _ in range(3)] == ["G21", "$J=G91X1F100", ""]
    assert counter.in_flight_bytes == 0


@pytest.mark.parametrize(
    ("capacity", "in_flight", "line", "fits"),
    [
        (128, [], "x" * 127, True),
        (128, [], "x" * 128, False),
        (128, ["x" * 63], "y" * 63, True),
        (128, ["x" * 63], "y" * 64, False),
        (128, ["x" * 63, "y" * 63], "", False),
        (1024, ["x" * 500], "y" * 500, True),
        (2, [], "", True),
        (2, [""], "", True),
        (2, ["", ""], "", False),
    ],
)
def test_fits(capacity: int, in_flight: list[str], line: str, fits: bool) -> None:
    """A line fits exactly when its bytes and newline stay within the capacity."""
    counter = CharCounter(capacity)
    for sent in in_flight:
        counter.sent(sent)
    assert counter.fits(line) is fits


def test_sending_what_does_not_fit_is_refused_and_not_counted() -> None:
    """sent() of an oversize line raises and leaves the count alone."""
    counter = CharCounter(16)
    counter.sent("x" * 10)
    with pytest.raises(OverfillError, match="only 5 of"):
        counter.sent("y" * 5)
    assert counter.outstanding == ("x" * 10,)
    assert counter.in_flight_bytes == 11


def test_ack_with_nothing_outstanding_is_a_typed_fault() -> None:
    """An ok that answers nothing is a FlowError (a LinkError) the caller can report."""
    counter = CharCounter()
    counter.sent("G4P0")
    counter.acknowledged()
    with pytest.raises(UnexpectedAckError, match="no line was waiting") as info:
        counter.acknowledged()
    assert isinstance(info.value, FlowError)
    assert isinstance(info.value, LinkError)


def test_clear_after_reset() -> None:
    """clear() empties the count, so the next ack is a fault and a full line fits."""
    counter = CharCounter()
    counter.sent("x" * 100)
    counter.clear()
    assert counter.in_flight_bytes == 0
    assert counter.outstanding == ()
    assert counter.fits("y" * 127)
    with pytest.raises(UnexpectedAckError):
        counter.acknowledged()


def test_impossible_capacity_is_refused() -> None:
    """A buffer that cannot hold even an empty line is refused."""
    with pytest.raises(FlowError, match="cannot hold"):
        CharCounter(1)


def test_long_stream_never_exceeds_capacity() -> None:
    """Streaming many lines with acks in between keeps the count within the buffer."""
    counter = CharCounter()
    lines = [f"$J=G91X{n % 7}.5F{1000 + n}" for n in range(300)]
    sent = acked = 0
    while acked < len(lines):
        while sent < len(lines) and counter.fits(lines[sent]):
            counter.sent(lines[sent])
            sent += 1
        assert counter.in_flight_bytes <= 128
        assert counter.acknowledged() == lines[acked]
        acked += 1
    assert counter.in_flight_bytes == 0

"""The line ledger: RX byte counting across owners, replies to the oldest line's owner, resets."""

from __future__ import annotations

import pytest

from smoothjog.core.ledger import (
    CONSOLE,
    ENGINE,
    HANDSHAKE,
    Ledger,
    LedgerError,
    foreign,
    line_cost_bytes,
)


def test_a_line_costs_its_bytes_and_one_newline() -> None:
    ledger = Ledger()
    ledger.record_line(ENGINE, "$J=G91X1F100", 0.0)
    assert ledger.in_flight_bytes == line_cost_bytes("$J=G91X1F100") == 13
    assert ledger.free_bytes == 128 - 13


@pytest.mark.parametrize(
    ("capacity", "in_flight", "line", "fits"),
    [
        (128, [], "x" * 127, True),
        (128, [], "x" * 128, False),
        (128, ["x" * 63], "y" * 63, True),
        (128, ["x" * 63], "y" * 64, False),
        (128, ["x" * 63, "y" * 63], "", False),
        (1024, ["x" * 500], "y" * 500, True),
        (2, [""], "", True),
        (2, ["", ""], "", False),
    ],
)
def test_fits_counts_every_owner(
    capacity: int, in_flight: list[str], line: str, fits: bool
) -> None:
    """Room is shared: lines of other owners take it as much as the engine's own."""
    ledger = Ledger(capacity)
    for k, text in enumerate(in_flight):
        ledger.record_line((ENGINE, foreign("cncjs"))[k % 2], text, 0.0)
    assert ledger.fits(line) is fits


def test_a_line_that_does_not_fit_is_refused_and_not_counted() -> None:
    ledger = Ledger(16)
    ledger.record_line(CONSOLE, "x" * 10, 0.0)
    with pytest.raises(LedgerError, match="only 5 of"):
        ledger.record_line(ENGINE, "y" * 5, 0.0)
    assert [e.text for e in ledger.outstanding()] == ["x" * 10]
    assert ledger.in_flight_bytes == 11


def test_each_reply_goes_to_the_owner_of_the_oldest_line() -> None:
    """Grbl answers in order, whoever wrote the line: a foreign `$G` between two jogs."""
    ledger = Ledger()
    ledger.record_line(ENGINE, "$J=G91X1F100", 0.0, tag="first")
    ledger.record_line(foreign("cncjs"), "$G", 0.001)
    ledger.record_line(ENGINE, "$J=G91X1F100", 0.002, tag="second")
    owners = []
    for _ in range(3):
        entry = ledger.on_reply()
        assert entry is not None
        owners.append((entry.owner, entry.tag))
    assert owners == [(ENGINE, "first"), ("foreign:cncjs", None), (ENGINE, "second")]
    assert ledger.in_flight_bytes == 0
    assert ledger.stats.replies == {ENGINE: 2, "foreign:cncjs": 1}


def test_a_reply_with_no_line_waiting_is_counted_not_raised() -> None:
    ledger = Ledger()
    assert ledger.on_reply() is None
    assert ledger.stats.unowned_replies == 1


def test_outstanding_and_waiting_by_owner() -> None:
    ledger = Ledger()
    ledger.record_line(HANDSHAKE, "$I", 0.0)
    ledger.record_line(ENGINE, "G4P0", 0.0)
    assert [e.text for e in ledger.outstanding(ENGINE)] == ["G4P0"]
    assert ledger.waiting(HANDSHAKE) == 1
    assert ledger.waiting(CONSOLE) == 0


def test_query_output_belongs_to_the_oldest_line() -> None:
    """Grbl prints a query's lines just before its ok: the oldest line's owner asked for them."""
    ledger = Ledger()
    assert ledger.oldest() is None
    first = ledger.record_line(foreign("sender"), "$G", 0.0)
    ledger.record_line(ENGINE, "$J=G91X1F100", 0.0)
    assert ledger.oldest() is first
    ledger.on_reply()
    oldest = ledger.oldest()
    assert oldest is not None
    assert oldest.owner == ENGINE


def test_a_relayed_line_not_on_the_wire_owns_no_output() -> None:
    ledger = Ledger(relayed=True)
    ledger.record_line(ENGINE, "$G", 0.0)
    assert ledger.oldest() is None  # not echoed: it may not have reached the controller
    ledger.on_echo("$G", foreign("cncjs"), 0.0)
    oldest = ledger.oldest()
    assert oldest is not None
    assert oldest.owner == ENGINE


def test_a_reset_drops_everything_and_says_what() -> None:
    """A controller reset empties its RX buffer: nothing is owed an answer any more."""
    ledger = Ledger()
    ledger.record_line(ENGINE, "$J=G91X1F100", 0.0)
    ledger.record_line(CONSOLE, "$G", 0.0)
    dropped = ledger.reset()
    assert [e.owner for e in dropped] == [ENGINE, CONSOLE]
    assert ledger.in_flight_bytes == 0
    assert ledger.stats.lost_to_reset == 2
    assert ledger.on_reply() is None


def test_realtime_bytes_take_no_room() -> None:
    ledger = Ledger()
    ledger.record_realtime(ENGINE, b"\x85")
    assert ledger.free_bytes == 128
    assert ledger.stats.realtime == {ENGINE: 1}


@pytest.mark.parametrize("capacity", [0, 1, -5])
def test_an_impossible_rx_size_is_refused(capacity: int) -> None:
    with pytest.raises(LedgerError, match="impossible"):
        Ledger(capacity)


def test_the_rx_size_can_be_set_after_the_handshake() -> None:
    """The host sizes its ledger from `[OPT:]` once the handshake has read it."""
    ledger = Ledger()
    assert ledger.capacity_bytes == 128
    ledger.capacity_bytes = 1024
    assert (ledger.capacity_bytes, ledger.free_bytes) == (1024, 1024)


# --- a relayed ledger: lines of other clients placed by the relay's echo ------------------------

CNCJS = foreign("cncjs-client")


def _owners(ledger: Ledger) -> list[tuple[str, str]]:
    return [(e.owner, e.text) for e in ledger.outstanding()]


def test_a_relayed_line_is_on_the_wire_only_once_echoed() -> None:
    ledger = Ledger(relayed=True)
    entry = ledger.record_line(ENGINE, "$J=G91X1F100", 0.0)
    assert not entry.on_wire
    assert ledger.on_echo("$J=G91X1F100", CNCJS, 0.1) is entry
    assert entry.on_wire
    assert ledger.stats.lines[CNCJS] == 0


def test_a_foreign_echo_goes_before_own_lines_not_yet_echoed() -> None:
    # Own A echoed, own B sent but not echoed, then another client's $G is echoed: on the wire
    # the order is A, $G, B, so the second reply is the other client's, not B's.
    ledger = Ledger(relayed=True)
    ledger.record_line(ENGINE, "A", 0.0)
    ledger.on_echo("A", CNCJS, 0.0)
    ledger.record_line(ENGINE, "B", 0.0)
    foreign_entry = ledger.on_echo("$G", CNCJS, 0.0)
    assert foreign_entry.owner == CNCJS
    assert _owners(ledger) == [(ENGINE, "A"), (CNCJS, "$G"), (ENGINE, "B")]
    assert ledger.in_flight_bytes == 2 + 3 + 2
    ledger.on_echo("B", CNCJS, 0.0)
    replies = [ledger.on_reply() for _ in range(3)]
    assert [(e.owner, e.text) for e in replies if e is not None] == [
        (ENGINE, "A"),
        (CNCJS, "$G"),
        (ENGINE, "B"),
    ]
    assert ledger.stats.replies_before_echo == 0


def test_a_foreign_line_counts_even_past_the_buffer() -> None:
    ledger = Ledger(20, relayed=True)
    ledger.on_echo("x" * 30, CNCJS, 0.0)
    assert ledger.free_bytes == 20 - 31
    assert not ledger.fits("")


def test_an_own_line_the_relay_never_echoed_is_dropped_when_a_later_one_is() -> None:
    ledger = Ledger(relayed=True)
    ledger.record_line(ENGINE, "A", 0.0)
    ledger.record_line(ENGINE, "B", 0.0)
    assert ledger.on_echo("B", CNCJS, 0.0).text == "B"
    assert _owners(ledger) == [(ENGINE, "B")]
    assert ledger.stats.unechoed_dropped == 1
    assert ledger.in_flight_bytes == 2


def test_a_plain_ledger_treats_every_echo_as_foreign_at_the_end() -> None:
    ledger = Ledger()
    ledger.record_line(ENGINE, "A", 0.0)
    ledger.on_echo("A", CNCJS, 0.0)
    assert _owners(ledger) == [(ENGINE, "A"), (CNCJS, "A")]


def test_a_reply_before_the_echo_still_pops_and_is_counted() -> None:
    ledger = Ledger(relayed=True)
    ledger.record_line(ENGINE, "A", 0.0)
    entry = ledger.on_reply()
    assert entry is not None
    assert entry.text == "A"
    assert ledger.stats.replies_before_echo == 1
    # The unechoed count followed: a new line and its echo match again.
    ledger.record_line(ENGINE, "B", 0.0)
    assert ledger.on_echo("B", CNCJS, 0.0).owner == ENGINE


def test_reset_and_presumed_answers_keep_the_echo_count() -> None:
    ledger = Ledger(relayed=True)
    a = ledger.record_line(ENGINE, "A", 0.0)
    ledger.record_line(ENGINE, "B", 0.0)
    ledger.presume_answered([a])
    assert ledger.on_echo("B", CNCJS, 0.0).owner == ENGINE
    ledger.record_line(ENGINE, "C", 0.0)
    ledger.reset()
    assert ledger.on_echo("C", CNCJS, 0.0).owner == CNCJS  # C was lost with the reset

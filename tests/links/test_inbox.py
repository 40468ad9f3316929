"""LineInbox delivering by callback: order, the end of the link, and going back to read_line."""

from __future__ import annotations

import pytest

from smoothjog.core.errors import LinkError
from smoothjog.links.base import LineInbox


async def test_subscribe_delivers_queued_lines_first_then_each_new_one_at_once() -> None:
    inbox = LineInbox()
    inbox.feed(b"ok\r\n<Idle|MPos:0,0,0>\r\n")
    got: list[bytes] = []
    ends: list[LinkError] = []
    inbox.subscribe(got.append, ends.append)
    assert got == [b"ok", b"<Idle|MPos:0,0,0>"]
    inbox.feed(b"err")
    assert got == [b"ok", b"<Idle|MPos:0,0,0>"]  # no end of line yet
    inbox.feed(b"or:9\nok\n")
    assert got[2:] == [b"error:9", b"ok"]
    assert inbox.peek() == ()
    gone = LinkError("gone")
    inbox.peer_gone(gone)
    assert ends == [gone]


async def test_unsubscribe_queues_lines_for_read_line_again() -> None:
    inbox = LineInbox()
    got: list[bytes] = []
    inbox.subscribe(got.append, lambda _e: None)
    inbox.feed(b"ok\n")
    inbox.unsubscribe()
    inbox.feed(b"ALARM:1\n")
    assert got == [b"ok"]
    assert await inbox.get() == b"ALARM:1"


async def test_a_subscriber_that_leaves_mid_chunk_loses_no_line() -> None:
    inbox = LineInbox()
    got: list[bytes] = []

    def take(line: bytes) -> None:
        got.append(line)
        inbox.unsubscribe()

    inbox.subscribe(take, lambda _e: None)
    inbox.feed(b"ok\nok\nok\n")
    assert got == [b"ok"]
    assert inbox.peek() == (b"ok", b"ok")


async def test_subscribing_after_the_end_reports_it_at_once() -> None:
    inbox = LineInbox()
    closed = LinkError("closed here")
    inbox.close(closed)
    ends: list[LinkError] = []
    inbox.subscribe(lambda _l: None, ends.append)
    assert ends == [closed]
    with pytest.raises(LinkError):
        await inbox.get()

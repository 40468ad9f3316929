"""The link clock: round trips, stalls, the host's lateness, wire time and the link split.

Every queue the engine keeps ahead of the machine is sized by how long a new line takes to
reach the planner; this part measures that from the replies and reports, and knows when the
engine's bytes have left the host.
"""

from __future__ import annotations

import bisect
from collections import deque

from smoothjog.core import increments as inc
from smoothjog.core.engine.linksplit import LinkSplit
from smoothjog.core.engine.tracker import PathTracker
from smoothjog.core.firmware import BITS_PER_BYTE_8N1, DEFAULT_BAUD
from smoothjog.core.responses import StatusReport
from smoothjog.core.units import mm_s_to_mm_min

#: Jog-line latencies the round-trip estimate looks at.
RTT_WINDOW = 64
#: How long a round trip far above the usual (a stall) keeps the queue long.
RTT_MEMORY_S = 30.0
#: A round trip over twice the window's slow one plus this is a stall, to be remembered.
STALL_MIN_S = 0.020
#: A round trip longer than this is a link that stopped, not one to size a queue for.
RTT_CAP_S = 0.5
#: Bytes of a typical jog line with its newline, for sizing before the first one is written.
JOG_LINE_BYTES = 24
#: A report's FS is the feed rounded to whole mm/min (Grbl prints it with no decimals).
FEED_PRINT_MM_MIN = 0.5


class Window:
    """The last `size` values, also kept in order so a percentile is one index away.

    Every reply and every late wake-up takes a percentile of such a window: keeping it sorted as
    values come and go costs less than sorting it again each time.
    """

    __slots__ = ("_recent", "ranked")

    def __init__(self, size: int) -> None:
        """An empty window of size values."""
        self._recent: deque[float] = deque(maxlen=size)
        #: The same values as the window, in increasing order.
        self.ranked: list[float] = []

    def add(self, value: float) -> None:
        """Take value in, dropping the oldest once the window is full."""
        recent = self._recent
        ranked = self.ranked
        if len(recent) == recent.maxlen:
            del ranked[bisect.bisect_left(ranked, recent[0])]
        recent.append(value)
        bisect.insort(ranked, value)


class LinkClock:
    """How long the link takes each way, measured; when the engine's bytes leave the host."""

    def __init__(self, byte_s: float | None) -> None:
        """A link not yet measured; byte_s is the wire time of one byte (None: 115200 8N1)."""
        self.byte_s = byte_s or BITS_PER_BYTE_8N1 / DEFAULT_BAUD
        self.line_bytes = JOG_LINE_BYTES
        self.last_report_bytes = 50  # a Grbl 1.1 report with MPos, FS and Pn
        self.rtt_s = 0.003  # time for a jog line to be planned: a low percentile of its ok latency
        self._rtts = Window(RTT_WINDOW)
        self.rtt_hi_s = self.rtt_s  # what the queue and the lines in flight are sized for
        #: Decreasing latencies of the last RTT_MEMORY_S (a sliding maximum), oldest first.
        self._rtt_peaks: deque[tuple[float, float]] = deque()
        #: A stall of the last RTT_MEMORY_S sizes the queue (rtt_hi_s is that peak).
        self.stall_sized = False
        self._services = Window(RTT_WINDOW)
        self._prev_sent_s = -float("inf")
        #: How late the host woke the engine for its planned top-ups (90th percentile).
        self._late_s = Window(RTT_WINDOW)
        self.lateness_s = 0.0
        #: The way out and the way back, told apart by the reports of a cruise.
        self.split = LinkSplit()
        #: When the engine's bytes written so far have all left the host, at the wire's rate.
        self.wire_free_s = -float("inf")
        #: How long the last `?` waited behind the engine's own lines.
        self.status_backlog_s = 0.0

    def woke_late(self, late_s: float) -> None:
        """The host woke the engine late_s after a planned top-up.

        Only late wake-ups are counted, so this is a percentile of the late ones: counting the
        ones on time as 0 let slow jogs over the Wi-Fi bridge run dry (bench/results/links.md,
        "Tried and not kept").
        """
        self._late_s.add(late_s)
        ranked = self._late_s.ranked
        self.lateness_s = ranked[(9 * len(ranked)) // 10]

    def jog_ok(self, latency_s: float, sent_s: float, now_s: float) -> bool:
        """Take the latency of a jog line's ok; True when it was held up on the link (a stall).

        The round trip is the upper quartile of recent latencies; the queue is sized for the
        90th percentile of the lines that went out first in their poll (the others of a burst
        wait behind it in the parser), or for a stall of the last RTT_MEMORY_S that stands out.
        """
        held_up = latency_s > 2.0 * self.rtt_s + 0.010
        self._rtts.add(latency_s)
        ranked = self._rtts.ranked
        self.rtt_s = ranked[(3 * len(ranked)) // 4]
        if sent_s != self._prev_sent_s:
            self._services.add(latency_s)
            peaks = self._rtt_peaks
            while peaks and peaks[-1][1] <= latency_s:
                peaks.pop()
            peaks.append((now_s, min(latency_s, RTT_CAP_S)))
        self._prev_sent_s = sent_s
        peaks = self._rtt_peaks
        while peaks and peaks[0][0] < now_s - RTT_MEMORY_S:
            peaks.popleft()
        ranked_s = self._services.ranked or [latency_s]
        window_s = ranked_s[(9 * len(ranked_s)) // 10]
        # The longest of the memory counts only when it stands out from the window (a stall),
        # so one slow reply does not lengthen the queue for half a minute.
        peak_s = peaks[0][1] if peaks else 0.0
        self.stall_sized = peak_s > 2.0 * window_s + STALL_MIN_S
        self.rtt_hi_s = peak_s if self.stall_sized else window_s
        return held_up

    def queue_rtt_s(self, now_s: float) -> float:
        """The link's share of the queue: the time a new line may need to reach the planner.

        With the estimate placed by the link split, that is the line's own wire time, the
        controller's parse and the jitter of the way out; never more than the slow end of the
        round trips, which is all there is before a cruise showed its split or during a stall.
        """
        spread_s = self.split.spread_s()
        floors_s = self.split.fastest_s()
        if spread_s is None or floors_s is None or self.stall_sized:
            return self.rtt_hi_s
        line_s = self.line_bytes * self.byte_s
        ok_s = len("ok\r\n") * self.byte_s
        # The fastest jog round trip less the wire times of the line and its ok is the parse
        # plus both ways' floors; the fastest report round trip less its wire time is those
        # floors alone (a line waits for the ones before it, a `?` does not).
        ranked = self._rtts.ranked
        fastest_s = ranked[0] if ranked else self.rtt_s
        parse_s = max(fastest_s - line_s - ok_s - floors_s, 0.0)
        # A `?` that came while a line was parsed is answered after it, so the spread holds
        # the parse already when it is the larger.
        backlog_s = max(self.wire_free_s - now_s, 0.0)
        return min(self.rtt_hi_s, backlog_s + line_s + max(parse_s, spread_s))

    def query_written(self, now_s: float) -> None:
        """A `?` went out now, behind the engine's own lines still on the wire."""
        self.status_backlog_s = max(self.wire_free_s - now_s, 0.0)
        self.wire_free_s = max(self.wire_free_s, now_s) + self.byte_s

    def report_wire_s(self, report: StatusReport) -> float:
        """How long the report's bytes took to arrive: its least age (firmware-facts §6)."""
        return (len(report.raw) + 2) * self.byte_s

    def split_by(
        self,
        report: StatusReport,
        asked_s: float | None,
        now_s: float,
        move: inc.VectorMove,
        track: PathTracker,
        *,
        jogging: bool,
    ) -> None:
        """Feed a report of a cruise to the link split; once it is ready, age the estimate by
        the split rather than by the report's wire time alone.

        A cruise here is a Jog report at the commanded feed, on a block of that speed, with the
        estimate cruising too: then the machine ran at that speed since the report before.
        """
        x_mm = track.x_reported_mm
        here = track.seg_at(x_mm) if x_mm is not None else None
        feed = report.feed
        if (
            x_mm is None
            or here is None
            or asked_s is None
            or report.state != "Jog"
            or not jogging
            or feed is None
            or abs(feed - mm_s_to_mm_min(move.speed_mm_s)) > FEED_PRINT_MM_MIN
            or here.speed_mm_s != move.speed_mm_s
            or track.v_est_mm_s != move.speed_mm_s
        ):
            self.split.reset()
            return
        wire_s = self.report_wire_s(report)
        self.split.add(move, asked_s + self.status_backlog_s, now_s, x_mm, move.speed_mm_s, wire_s)
        age_s = self.split.newest_age_s()
        if age_s is not None and age_s > wire_s:
            track.x_est_mm = min(x_mm + track.v_est_mm_s * age_s, track.length_mm())

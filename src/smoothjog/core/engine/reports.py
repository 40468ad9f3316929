"""Report reading: what each status report says of the run, and when the next `?` is due.

A report tells whether a jog runs unbraked (a cancel only ever slows a jog down), whether a
cancel may still be ending, how long the controller has reported Idle and after which `?`s,
which hold or door inputs read active at rest, and how fast the machine moved since the last.
"""

from __future__ import annotations

import math

from smoothjog.core.engine.clock import LinkClock
from smoothjog.core.engine.limits import JogTuning
from smoothjog.core.engine.records import Notices, Output, SendRealtime
from smoothjog.core.realtime import STATUS_QUERY
from smoothjog.core.responses import StatusReport
from smoothjog.core.units import Vec

#: The control inputs a status report's Pn field names (firmware-facts §5.4).
PIN_NAMES = {"H": "feed-hold", "D": "door"}
#: Status polling while an owed cancel waits for the stale lines to show themselves.
OWED_POLL_S = 0.010
#: Share of the return wire the status reports may take (the rest: replies, messages).
REPORT_SHARE = 0.3


class ReportReader:
    """The run as the reports show it, and the `?` schedule (one `?` at a time)."""

    def __init__(self, tuning: JogTuning, clock: LinkClock, notices: Notices) -> None:
        """Nothing reported yet."""
        self.tuning = tuning
        self.clock = clock
        self.notices = notices
        #: When the `?` now awaited was written (None: none awaited).
        self.asked_s: float | None = None
        self.last_sent_s = -math.inf
        #: The last report showed a jog running and not braking (Jog, a speed above 0 and no
        #: lower than the report before): an owed cancel may act on it.
        self.jog_unbraked = False
        self.prev_feed_mm_min: float | None = None  # FS of the last report, None if not Jog
        #: A jog cancel (smoothjog's or an outside one) may still be ending: no report since
        #: showed a state other than Jog or a jog running unbraked.
        self.cancel_ending = False
        self.idle_since_s: float | None = None  # the first of the Idle reports in a row
        #: When the `?` of each Idle report in a row was written (None: not known).
        self.idle_asked_s: list[float | None] = []
        #: Pn letters seen while the machine rested (an input that reads active while Idle).
        self.rest_pins = ""
        self._pins_warned = ""
        self._last: tuple[float, Vec] | None = None
        self.actual_speed_mm_s = 0.0

    def take(self, report: StatusReport, mpos: Vec | None, now_s: float) -> float | None:
        """Read a report; return when its `?` was written (None: not known).

        A report of Jog right after one of another state is a jog just started, at any speed
        but 0; at rest in Jog is a jog ending. A jog too short for its segments to speed up
        reports Jog with FS:0 as it starts: a 0x85 then lands in its last moments and leaves
        Grbl 1.1h suspended (firmware-facts §3.8). Without an FS field every Jog report counts.
        """
        asked_s, self.asked_s = self.asked_s, None
        self.clock.last_report_bytes = len(report.raw) + 2
        feed = report.feed
        if report.state != "Jog":
            self.jog_unbraked = False
            self.prev_feed_mm_min = None
        elif feed is None or self.prev_feed_mm_min is None:
            self.jog_unbraked = feed is None or feed > 0.0
            self.prev_feed_mm_min = feed
        else:
            self.jog_unbraked = feed > 0.0 and feed >= self.prev_feed_mm_min
            self.prev_feed_mm_min = feed
        if report.state != "Jog" or self.jog_unbraked:
            self.cancel_ending = False
        if report.state != "Idle":
            self.idle_since_s = None
            self.idle_asked_s.clear()
        else:
            if self.idle_since_s is None:
                self.idle_since_s = now_s
            self.idle_asked_s.append(asked_s)
            del self.idle_asked_s[:-4]
        if mpos is not None:
            if self._last is not None and now_s > self._last[0]:
                dt = now_s - self._last[0]
                self.actual_speed_mm_s = math.dist(mpos, self._last[1]) / dt
            self._last = (now_s, tuple(mpos))
        return asked_s

    def idle_answers_since(self, since_s: float) -> int:
        """How many of the Idle reports in a row answer a `?` written at since_s or later."""
        return sum(1 for a in self.idle_asked_s if a is not None and a >= since_s)

    def cancel_sent(self) -> None:
        """A 0x85 went out: the next one needs a new report of a jog running."""
        self.jog_unbraked = False
        self.cancel_ending = True

    def restarted(self) -> None:
        """A banner with jog lines on the wire: reports from before it say nothing now.

        The first Jog report after it may show a jog braking under the reset's 0x85 rather
        than one just started: only a speed that rises counts as running then. A reset drops
        a `?` still pending: ask again at once.
        """
        self.jog_unbraked = False
        self.prev_feed_mm_min = math.inf
        self.idle_since_s = None
        self.idle_asked_s.clear()
        self.asked_s = None
        self.last_sent_s = -math.inf

    def note_pins(self, report: StatusReport, now_s: float, *, at_rest: bool) -> None:
        """Remember the inputs that read active at rest, and warn once about hold and door."""
        if report.state != "Idle" or not at_rest:
            return
        self.rest_pins = report.pins or ""
        stuck = "".join(p for p in "HD" if p in self.rest_pins and p not in self._pins_warned)
        if stuck:
            self._pins_warned += stuck
            names = " and ".join(PIN_NAMES[p] for p in stuck)
            self.notices.info(
                now_s,
                f"the controller reports its {names} input active while Idle (Pn:{report.pins})",
                "Grbl acts only when an input changes, so jogging works; check the wiring"
                " or the input's invert setting ($14)",
            )

    def pressed_inputs(self, report: StatusReport) -> str:
        """Hold or door inputs active now that were not active while the machine rested."""
        pins = report.pins or ""
        return " and ".join(PIN_NAMES[p] for p in "HD" if p in pins and p not in self.rest_pins)

    def interval_s(self, *, watching_restart: bool, busy: bool, cancel_owed: bool) -> float:
        """The routine time between two `?`s.

        While a restart is watched, one `?` every OWED_POLL_S (no new line's reply needs the
        return wire then); while a cancel is owed, as often, so it comes within a block or two.
        Reports leave the return wire room for the replies: at 9600 baud a 50-byte report
        takes 52 ms, so 20 Hz would fill it.
        """
        if watching_restart:
            return OWED_POLL_S
        interval_s = self.tuning.poll_moving_s if busy else self.tuning.poll_idle_s
        if cancel_owed:
            interval_s = OWED_POLL_S
        report = self.clock.last_report_bytes * self.clock.byte_s / REPORT_SHARE
        return max(interval_s, report)

    def poll(self, now_s: float, out: list[Output], *, urgent: bool, due_s: float) -> None:
        """Ask `?` when a report is urgent or due, one at a time (Grbl folds a second in, §5.2)."""
        asked = self.asked_s
        if asked is not None and now_s - asked < self.tuning.status_timeout_s:
            return
        if urgent or now_s >= due_s:
            out.append(SendRealtime(STATUS_QUERY))
            self.asked_s = now_s
            self.last_sent_s = now_s
            self.clock.query_written(now_s)

"""How a link's delay splits into its two ways, read from status reports during a cruise.

A round trip alone cannot tell the way to the controller from the way back. Both matter to a
held jog, for different reasons: the queue must hold enough for a new line to *reach* the
planner, while a status report is *old* by the way back (plus the wait for the controller to
answer). An FTDI adapter shows why the split pays: its way back waits for a 16 ms latency
timer, its way out takes one 1 ms USB frame, so a queue sized for the whole round trip carries
some 15 ms (1.2 mm at 5000 mm/min) more than a line needs to arrive.

While the machine cruises at a known speed v along a straight run, its position tells the time
the controller built each report: x_i / v, give or take one constant. Subtracting the time the
`?` was written leaves D_i = x_i / v - asked_i, the report's way out (plus the controller's
wait to answer) up to that same constant. So over a window of such reports:

- max(D) - min(D) is how much the way out varies (its jitter, the wire's backlog included);
- asked_i + (D_i - min(D)) is the earliest time report i can have been built, taking the
  fastest way out seen as instant. That puts the report's age at its round trip minus
  (D_i - min(D)).

The constant is the way out's floor F, which the window cannot see. It cancels: the estimate
placed by these ages runs F ahead of the machine (a safe error: the queue then looks shorter
than it is, so the engine tops it up sooner), and a new line needs F plus its own wire time
and jitter to arrive, of which the engine adds all but F. Whatever the split says, the engine
never sizes for more than the round trips it measures (see Jogger._queue_rtt_s).
"""

from __future__ import annotations

from collections import deque

#: Reports of one cruise kept: one second of them at the engine's 20 Hz status polls.
WINDOW = 20
#: Reports a cruise needs before its split is trusted.
MIN_SAMPLES = 8
#: Longest gap between two reports of one cruise: a longer one starts a new window, as the
#: machine may have slowed between them (a stall).
MAX_GAP_S = 0.5


class LinkSplit:
    """The reports of the current cruise and what they tell of the way out."""

    __slots__ = ("_d_max", "_d_min", "_fastest", "_key", "_last_along_mm", "_last_s", "_samples")

    def __init__(self) -> None:
        self._key: object = None
        #: (D_i, round trip, round trip less the report's own wire time) of each report of
        #: the cruise, oldest first.
        self._samples: deque[tuple[float, float, float]] = deque(maxlen=WINDOW)
        self._last_along_mm = 0.0
        self._last_s = 0.0
        # The window's extremes, worked out once per report: the engine asks at every poll.
        self._d_min = self._d_max = self._fastest = 0.0

    def reset(self) -> None:
        """Forget the cruise (it ended, or a report broke it)."""
        self._key = None
        self._samples.clear()

    def add(
        self,
        key: object,
        asked_s: float,
        now_s: float,
        along_mm: float,
        speed_mm_s: float,
        wire_s: float,
    ) -> None:
        """One report of a cruise at speed_mm_s, asked at asked_s and taken in at now_s; its
        bytes take wire_s on the wire.

        key names the cruise (the commanded move): a report of another cruise, one that does
        not lie further along the path, or one after a long gap starts the window afresh.
        """
        if speed_mm_s <= 0.0 or now_s < asked_s:
            self.reset()
            return
        if key != self._key or along_mm <= self._last_along_mm or now_s - self._last_s > MAX_GAP_S:
            self._samples.clear()
            self._key = key
        self._last_along_mm = along_mm
        self._last_s = now_s
        rtt_s = now_s - asked_s
        samples = self._samples
        samples.append((along_mm / speed_mm_s - asked_s, rtt_s, rtt_s - wire_s))
        ds = [d for d, _, _ in samples]
        self._d_min = min(ds)
        self._d_max = max(ds)
        self._fastest = min(net for _, _, net in samples)

    @property
    def ready(self) -> bool:
        """True once the window holds enough reports of one cruise to be trusted."""
        return len(self._samples) >= MIN_SAMPLES

    def spread_s(self) -> float | None:
        """How much the way out varied over the window (None until ready)."""
        if not self.ready:
            return None
        return self._d_max - self._d_min

    def fastest_s(self) -> float | None:
        """The fastest round trip of a report less its wire time: both ways' floors (None
        until ready)."""
        if not self.ready:
            return None
        return self._fastest

    def newest_age_s(self) -> float | None:
        """The largest age the newest report can have: its round trip less the part of its way
        out that was slower than the fastest seen (None until ready)."""
        if not self.ready:
            return None
        d_new, rtt_new, _ = self._samples[-1]
        return max(rtt_new - (d_new - self._d_min), 0.0)

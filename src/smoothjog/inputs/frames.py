"""evdev frame assembly: raw events in, one `EvdevFrame` per SYN_REPORT out.

The kernel ends each frame with SYN_REPORT and a decoder applies a frame's changes together.
EV_MSC (hid-generic sends MSC_SCAN before each key) is dropped here, so no decoder mistakes
a scan code for a key. SYN_DROPPED means the kernel's queue overflowed and changes were lost:
everything up to and including the next SYN_REPORT is discarded, and the frame given instead
is a resync frame holding the whole current state, read from the device when it can be asked
(live) or rebuilt from the events seen so far (a recording).

Recordings often omit the SYN_REPORT lines; events stamped with different times cannot belong
to one frame, so a new time also closes the frame before it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

from smoothjog.inputs.device import (
    EV_ABS,
    EV_KEY,
    EV_MSC,
    EV_SYN,
    SYN_DROPPED,
    SYN_REPORT,
    EvdevEvent,
    EvdevFrame,
)

#: Reads the device's whole state now: absolute values and held keys, as events.
Snapshot = Callable[[], Iterable[EvdevEvent]]


class FrameAssembler:
    """Collects events into frames; keeps the state seen so far for resyncs without a device."""

    def __init__(self, snapshot: Snapshot | None = None) -> None:
        """snapshot reads the live device after a SYN_DROPPED; None rebuilds from history."""
        self._snapshot = snapshot
        self._pending: list[EvdevEvent] = []
        self._pending_t: float | None = None
        self._dropping = False
        self._abs: dict[int, int] = {}
        self._keys: set[int] = set()
        #: How many SYN_DROPPED were seen (the device or the reader was too slow).
        self.dropped = 0

    def feed(self, t_s: float, type_: int, code: int, value: int) -> list[EvdevFrame]:
        """One event; returns the frames it completed (none, one, or two on a time change)."""
        out: list[EvdevFrame] = []
        if self._pending and self._pending_t is not None and t_s != self._pending_t:
            out.extend(self._close())
        if type_ == EV_SYN:
            if code == SYN_DROPPED:
                self.dropped += 1
                self._dropping = True
                self._pending.clear()
                self._pending_t = None
            elif code == SYN_REPORT:
                if self._dropping:
                    self._dropping = False
                    out.append(self._resync(t_s))
                else:
                    out.extend(self._close())
            return out
        if type_ == EV_MSC or self._dropping:
            return out
        self._pending.append(EvdevEvent(type_, code, value))
        self._pending_t = t_s
        return out

    def flush(self) -> list[EvdevFrame]:
        """The last frame of a recording that ends without SYN_REPORT."""
        if self._dropping:
            return []
        return self._close()

    def _close(self) -> list[EvdevFrame]:
        if not self._pending or self._pending_t is None:
            return []
        events = tuple(self._pending)
        frame = EvdevFrame(self._pending_t, events)
        self._pending.clear()
        self._pending_t = None
        for ev in events:
            self._remember(ev)
        return [frame]

    def _remember(self, ev: EvdevEvent) -> None:
        if ev.type == EV_ABS:
            self._abs[ev.code] = ev.value
        elif ev.type == EV_KEY:
            if ev.value == 0:
                self._keys.discard(ev.code)
            elif ev.value == 1:
                self._keys.add(ev.code)

    def _resync(self, t_s: float) -> EvdevFrame:
        if self._snapshot is not None:
            try:
                state = tuple(self._snapshot())
            except OSError:
                # The device went away while asked; the read that follows reports the loss.
                state = self._history()
            else:
                self._abs = {e.code: e.value for e in state if e.type == EV_ABS}
                self._keys = {e.code for e in state if e.type == EV_KEY and e.value}
        else:
            state = self._history()
        return EvdevFrame(t_s, state, resync=True)

    def _history(self) -> tuple[EvdevEvent, ...]:
        return tuple(EvdevEvent(EV_ABS, c, v) for c, v in sorted(self._abs.items())) + tuple(
            EvdevEvent(EV_KEY, c, 1) for c in sorted(self._keys)
        )


def assemble(events: Iterable[tuple[float, int, int, int]]) -> list[EvdevFrame]:
    """All frames of a finite list of (t_s, type, code, value) events."""
    assembler = FrameAssembler()
    frames: list[EvdevFrame] = []
    for t_s, type_, code, value in events:
        frames.extend(assembler.feed(t_s, type_, code, value))
    frames.extend(assembler.flush())
    return frames

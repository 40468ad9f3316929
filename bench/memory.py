"""A long day of jogging on the embedded default machine: does memory stay flat?

`python -m bench memory [--minutes 30] [--keep-trace]`

The host the pendant runs (engine, ledger, model) drives the built-in simulator as `smoothjog`
builds it (no ground-truth trace kept), in virtual time: the stick is held 3 s one way along X,
then 3 s back, without pause. After each minute of jogging the Python heap in use is read with
tracemalloc (after a full collection), with the harness's own logs of received lines emptied.
`--keep-trace` keeps every executed segment, as the simulator did before, for comparison.
"""

from __future__ import annotations

import argparse
import gc
import sys
import time
import tracemalloc

from smoothjog.core.intents import ContinuousIntent
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.profiles import get_firmware_profile
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.virtual import VirtualHost

MACHINE = "hobby-router"
#: How long the stick is held one way before it turns (s).
LEG_S = 3.0


def _heap_bytes(vh: VirtualHost) -> int:
    """Python heap in use now, without the harness's own logs."""
    vh.received.clear()
    vh.events.clear()
    gc.collect()
    return tracemalloc.get_traced_memory()[0]


def _rss_bytes() -> int:
    """The process's resident memory now (Linux), 0 where /proc is missing."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def _jog_for(vh: VirtualHost, seconds: float, direction: float) -> float:
    """Jog back and forth along X for seconds of virtual time; the direction it ends with."""
    end_s = vh.now_s + seconds
    while vh.now_s < end_s:
        vh.set_intent(ContinuousIntent({"X": direction}, 1.0))
        vh.run_until(min(end_s, vh.now_s + LEG_S))
        direction = -direction
    return direction


def run(minutes: int, *, keep_trace: bool) -> list[tuple[int, int, int, float]]:
    """(minute, heap bytes, resident bytes, wall seconds so far) after each minute."""
    fw = GrblFirmware(get_firmware_profile("grbl"), MACHINE, keep_trace=keep_trace)
    vh = VirtualHost(SimRig(fw, LinkModel()))
    vh.handshake()
    tracemalloc.start()
    started = time.monotonic()
    rows = []
    direction = -1.0
    try:
        for minute in range(1, minutes + 1):
            direction = _jog_for(vh, 60.0, direction)
            rows.append((minute, _heap_bytes(vh), _rss_bytes(), time.monotonic() - started))
    finally:
        tracemalloc.stop()
        vh.close()
    return rows


def _print(rows: list[tuple[int, int, int, float]], keep_trace: bool) -> None:
    kept = "every segment kept (--keep-trace)" if keep_trace else "no trace kept (the default)"
    print(f"{MACHINE}, Grbl 1.1h profile, virtual time, stick reversed every {LEG_S:g} s; {kept}")
    print("| minute of jogging | Python heap | since minute 1 | resident (RSS) | since minute 1 |")
    print("|---|---|---|---|---|")
    heap0, rss0 = rows[0][1], rows[0][2]
    for minute, heap, rss, _wall in rows:
        print(
            f"| {minute} | {heap / 1e6:.2f} MB | {(heap - heap0) / 1e6:+.2f} MB"
            f" | {rss / 1e6:.1f} MB | {(rss - rss0) / 1e6:+.1f} MB |"
        )
    print(f"wall time {rows[-1][3]:.0f} s")


def main(argv: list[str] | None = None) -> int:
    """Print the heap after each minute of jogging."""
    parser = argparse.ArgumentParser(
        prog="python -m bench memory", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--minutes", type=int, default=30, help="minutes to jog (default: 30)")
    parser.add_argument(
        "--keep-trace", action="store_true", help="keep every segment (the old default)"
    )
    args = parser.parse_args(argv)
    if args.minutes < 1:
        print("python -m bench memory: --minutes must be at least 1", file=sys.stderr)
        return 2
    _print(run(args.minutes, keep_trace=args.keep_trace), args.keep_trace)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

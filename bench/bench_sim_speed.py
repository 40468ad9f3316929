"""How much faster than real time the virtual-time rig runs a 60 s jog stream (target: >= 200x)."""

from __future__ import annotations

import time

from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.rig import SimRig

#: Virtual length of the jog stream, s.
VIRTUAL_S = 60.0
#: One jog every 50 ms at 3000 mm/min (2.5 mm each: the middle of the jogging doc's 25-60 ms
#: range), send-response, with the doc's recommended 5 Hz status poll.
JOG_DT_S = 0.050


def run_stream(virtual_s: float = VIRTUAL_S) -> tuple[float, int]:
    """Run the stream; returns (virtual seconds simulated, lines received)."""
    rig = SimRig(GrblFirmware(machine="hobby-router"))
    received = 0
    t = 0.0
    next_poll_s = 0.0
    direction = -1.0
    waiting = False
    while t < virtual_s:
        if not waiting:
            x_mm = rig.firmware.mpos_mm()[0]
            if x_mm < -700.0:
                direction = 1.0
            elif x_mm > -100.0:
                direction = -1.0
            rig.send_line(f"$J=G21G91X{direction * 3000 / 60 * JOG_DT_S:.3f}F3000", t)
            waiting = True
        if t >= next_poll_s:
            rig.host_send(b"?", t)
            next_poll_s += 0.2
        t += JOG_DT_S / 3
        for _arrival, line in rig.run_until(t):
            received += 1
            if line == b"ok" or line.startswith(b"error"):
                waiting = False
    return t, received


#: The rig must run at least this many times faster than real time.
TARGET_RATIO = 200


def main() -> int:
    """Print the ratio of virtual to wall-clock time; 0 when it meets TARGET_RATIO."""
    start = time.perf_counter()
    virtual_s, lines = run_stream()
    wall_s = time.perf_counter() - start
    ratio = virtual_s / wall_s
    verdict = "ok" if ratio >= TARGET_RATIO else "TOO SLOW"
    print(
        f"simulated {virtual_s:.1f} s of jogging ({lines} lines received) in {wall_s:.3f} s"
        f" of wall-clock time: {ratio:.0f}x real time (target >= {TARGET_RATIO}x: {verdict})"
    )
    return 0 if ratio >= TARGET_RATIO else 1


if __name__ == "__main__":
    raise SystemExit(main())

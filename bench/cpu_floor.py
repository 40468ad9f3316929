"""The floor under the CPU benchmark: a host that only streams jog lines, with no engine.

`python -m bench.cpu_floor jog --port PTY --baud B --replay FILE --settle S` takes the arguments
the CPU benchmark gives `smoothjog jog` and does the least any jogging host must do for the same
traffic. It opens the port as smoothjog's serial link does (pyserial, then its file descriptor in
the asyncio loop), reads the axis's `$11x` once, and while the replay's stick is held it writes
one `$J=G91` line of v x 10.5 ms every 10.5 ms (the engine's shortest block, so as many lines a
second as smoothjog sends at these speeds), reads every reply, and asks `?` every 50 ms, as
smoothjog does while moving. A reversal just writes the other direction; the release writes
0x85. It keeps no estimate, ledger or tracker. Its CPU per second of held jog is what the event
loop, pyserial and the kernel's pty cost for that traffic alone on this machine: the floor of
any Python host's figure, which the benchmark reports smoothjog's against (`--floor`).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import sys
from pathlib import Path

import serial  # type: ignore[import-untyped,unused-ignore]

# The floor imports nothing of smoothjog: its start-up would then cost what an engine's does,
# and the short run it is measured against would vary by more than the traffic costs. The
# engine's figures are copied here, and tests/test_bench_cpu.py checks them against the engine.
#: One block: the engine's shortest (core/jogger.py JogTuning.dt_floor_s).
BLOCK_S = 0.0105
#: Blocks written at once when a press begins, so the planner never starves.
LEAD_BLOCKS = 5
#: Status polling while moving (the engine's JogTuning.poll_moving_s).
POLL_S = 0.050

_MPOS = re.compile(rb"MPos:([-\d.]+(?:,[-\d.]+)*)")
_SETTING = re.compile(rb"^\$(\d+)=([-\d.]+)")


class FloorHost:
    """The port, what was read from it, and the stream's state."""

    def __init__(self, fd: int) -> None:
        """Watch fd (already opened and non-blocking)."""
        self.fd = fd
        self.buf = b""
        self.settings: dict[int, float] = {}
        self.oks = 0
        self.state = b""
        self.mpos = b""
        self.got_ok = asyncio.Event()

    def on_readable(self) -> None:
        """Read what came and split it into lines (the least a host must do with a reply)."""
        try:
            data = os.read(self.fd, 4096)
        except BlockingIOError:
            return
        self.buf += data
        *lines, self.buf = self.buf.split(b"\n")
        for raw in lines:
            line = raw.strip()
            if line == b"ok" or line.startswith(b"error"):
                self.oks += 1
                self.got_ok.set()
            elif line.startswith(b"<"):
                self.state = line[1:].split(b"|", 1)[0]
                found = _MPOS.search(line)
                if found:
                    self.mpos = found.group(1)
            else:
                setting = _SETTING.match(line)
                if setting:
                    self.settings[int(setting.group(1))] = float(setting.group(2))

    def write(self, data: bytes) -> None:
        """Write at once (a pty takes it whole)."""
        os.write(self.fd, data)


def jog_line(axis: str, dist_mm: float, feed_mm_min: float) -> bytes:
    """The `$J=` line smoothjog's jogline.build_jog_line writes for this move, with its `\n`."""
    # Four decimals without trailing zeros, as jogline.format_number writes them.
    dist = f"{dist_mm:.4f}".rstrip("0").rstrip(".")
    return f"$J=G21G91{axis}{dist}F{feed_mm_min:g}\n".encode()


class _Stream:
    """One line per block on an absolute schedule (no drift), `?` every POLL_S, until end_s.

    Timer callbacks, as smoothjog's host arms them: a coroutine sleeping per line would cost a
    task step and a future each time, which no host needs.
    """

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        host: FloorHost,
        line: bytes,
        end_s: float,
        done: asyncio.Future[None],
    ) -> None:
        """Prepare; start() arms the first block."""
        self.loop = loop
        self.host = host
        self.line = line
        self.end_s = end_s
        self.done = done
        self.next_s = loop.time()
        self.next_poll_s = self.next_s

    def start(self) -> None:
        """Write the first block now."""
        self._tick()

    def _tick(self) -> None:
        now = self.loop.time()
        out = self.line
        if now >= self.next_poll_s:
            out += b"?"
            self.next_poll_s += POLL_S
        self.host.write(out)
        self.next_s += BLOCK_S
        if self.next_s < self.end_s:
            self.loop.call_at(self.next_s, self._tick)
        else:
            self.done.set_result(None)


def _replay(path: Path) -> tuple[list[tuple[float, str, int]], float]:
    """(time, axis, sign) per stick change of a CPU-benchmark replay (sign 0: the release), and
    the stick's speed."""
    events = []
    speed = 1.0
    for text in path.read_text(encoding="utf-8").splitlines():
        if text.strip():
            entry = json.loads(text)
            axis, value = next(iter(entry["axes"].items()))
            sign = 0 if value == 0 else (1 if value > 0 else -1)
            events.append((float(entry["t"]), axis.upper(), sign))
            speed = float(entry.get("speed", speed)) if sign else speed
    return events, speed


async def _run(
    port: str, baud: int, events: list[tuple[float, str, int]], speed: float, settle_s: float
) -> str:
    link = serial.Serial(port, baud, timeout=0)
    fd = link.fileno()
    os.set_blocking(fd, False)
    loop = asyncio.get_running_loop()
    host = FloorHost(fd)
    loop.add_reader(fd, host.on_readable)
    try:
        host.write(b"$$\n")
        axis = events[0][1]
        index = "XYZ".index(axis)
        while 110 + index not in host.settings or not host.oks:
            host.got_ok.clear()
            await asyncio.wait_for(host.got_ok.wait(), 5.0)
        feed_mm_min = host.settings[110 + index] * speed
        step_mm = feed_mm_min / 60.0 * BLOCK_S
        t0 = loop.time()
        sign = 0
        for i, (t_s, _axis, new_sign) in enumerate(events):
            await asyncio.sleep(max(t0 + t_s - loop.time(), 0.0))
            if new_sign == 0 or i + 1 == len(events):
                break
            line = jog_line(axis, new_sign * step_mm, feed_mm_min)
            if sign == 0:
                host.write(line * LEAD_BLOCKS)
            sign = new_sign
            done = loop.create_future()
            _Stream(loop, host, line, t0 + events[i + 1][0], done).start()
            await done
        host.write(b"\x85")
        deadline = loop.time() + settle_s
        while loop.time() < deadline:
            await asyncio.sleep(0.1)
            host.write(b"?")
            await asyncio.sleep(0.05)
            if host.state == b"Idle":
                break
    finally:
        loop.remove_reader(fd)
        link.close()
    return (
        f"replay finished on {port} at {baud} baud\n"
        f"  final state     {host.state.decode()} at MPos {host.mpos.decode()}\n"
        f"  replies         {host.oks}"
    )


def main(argv: list[str] | None = None) -> int:
    """Parse the CPU benchmark's `jog` arguments and stream."""
    parser = argparse.ArgumentParser(prog="python -m bench.cpu_floor", description=__doc__)
    parser.add_argument("command", choices=["jog"])
    parser.add_argument("--port", required=True)
    parser.add_argument("--baud", type=int, default=115200)
    parser.add_argument("--replay", type=Path, required=True)
    parser.add_argument("--settle", type=float, default=5.0)
    args = parser.parse_args(argv)
    try:
        events, speed = _replay(args.replay)
        print(asyncio.run(_run(args.port, args.baud, events, speed, args.settle)))
    except (OSError, TimeoutError, ValueError, KeyError, serial.SerialException) as exc:
        print(f"python -m bench.cpu_floor: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

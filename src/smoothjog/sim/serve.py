"""Run the simulator in real time on asyncio, and serve it on a pseudo-terminal and/or TCP port.

This module (with links/sim.py) is the only place the simulator meets a real clock: the rig's
virtual time is the event loop's clock minus the moment the driver started.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import json
import math
import os
import signal
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from smoothjog.core.errors import SimError
from smoothjog.core.firmware import DEFAULT_BAUD
from smoothjog.pty_port import PtyPort
from smoothjog.sim.firmware import GrblFirmware
from smoothjog.sim.motion import TraceSegment
from smoothjog.sim.profiles import get_firmware_profile, load_machine_profile
from smoothjog.sim.rig import LinkModel, SimRig
from smoothjog.sim.settings import Eeprom, load_eeprom, save_eeprom

_READ_CHUNK_BYTES = 4096


class RealtimeSim:
    """Drives a SimRig with the event loop's clock; received lines go to on_line."""

    def __init__(self, rig: SimRig, on_line: Callable[[bytes], None]) -> None:
        """Wrap a rig; nothing runs until run() is awaited."""
        self.rig = rig
        self.on_line = on_line
        self._t0 = 0.0
        self._start_rig_s = rig.now_s
        self._wake: asyncio.Event | None = None
        self._started = False

    def now_s(self) -> float:
        """The rig time that corresponds to the loop's clock now."""
        return asyncio.get_running_loop().time() - self._t0 + self._start_rig_s

    def loop_time_s(self, rig_s: float) -> float:
        """The loop's clock (time.monotonic() on the default loop) at rig time rig_s."""
        return rig_s - self._start_rig_s + self._t0

    def send(self, data: bytes) -> None:
        """Bytes from the host, sent now."""
        if not self._started:
            raise SimError("the simulator is not running yet")
        self.rig.host_send(data, max(self.now_s(), self.rig.now_s))
        if self._wake is not None:
            self._wake.set()

    def catch_up(self) -> None:
        """Run the rig up to the loop's clock now (once stopped, so the trace ends now)."""
        if self._started:
            for _arrival_s, line in self.rig.run_until(max(self.now_s(), self.rig.now_s)):
                self.on_line(line)

    async def run(self) -> None:
        """Run forever (until cancelled), sleeping until the rig's next event or new input."""
        loop = asyncio.get_running_loop()
        self._t0 = loop.time()
        self._start_rig_s = self.rig.now_s
        self._wake = asyncio.Event()
        self._started = True
        while True:
            now = max(self.now_s(), self.rig.now_s)
            for _arrival_s, line in self.rig.run_until(now):
                self.on_line(line)
            nxt = self.rig.next_event_s()
            self._wake.clear()
            timeout = None if nxt is None else max(0.0, nxt - self.now_s())
            # asyncio.timeout, not wait_for: on Python 3.11 wait_for can swallow a cancellation
            # that lands as the event fires (a byte sent while closing), and run() never ends.
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(timeout):
                    await self._wake.wait()


@dataclass(frozen=True)
class ServeOptions:
    """What `smoothjog sim` was asked to do."""

    firmware: str = "grbl"
    machine: str = "grbl-defaults"
    settings_path: Path | None = None
    link_path: Path | None = None
    pty: bool = True
    tcp_port: int | None = None
    baud: int = DEFAULT_BAUD
    trace_path: Path | None = None


def trace_line(seg: TraceSegment) -> str:
    """One segment of a trace file as a JSON object on one line (floats kept exactly)."""
    return json.dumps(
        {
            "t0_s": seg.t0_s,
            "t1_s": seg.t1_s,
            "start_mm": list(seg.start_mm),
            "end_mm": list(seg.end_mm),
        }
    )


def read_trace(path: Path) -> list[TraceSegment]:
    """The segments of a trace file `smoothjog sim --trace` wrote; SimError in words if not one."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise SimError(f"cannot read trace file {path}: {exc.strerror}") from None
    trace: list[TraceSegment] = []
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            item = json.loads(line)
            seg = TraceSegment(
                float(item["t0_s"]),
                float(item["t1_s"]),
                tuple(float(x) for x in item["start_mm"]),
                tuple(float(x) for x in item["end_mm"]),
            )
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            raise SimError(f"{path}:{number}: not a trace segment ({exc})") from None
        if not all(math.isfinite(t) for t in (seg.t0_s, seg.t1_s)):
            raise SimError(f"{path}:{number}: a segment time is not a finite number")
        trace.append(seg)
    return trace


def build_firmware(opts: ServeOptions) -> GrblFirmware:
    """The firmware for these options, with EEPROM loaded from and saved to the settings file."""
    profile = get_firmware_profile(opts.firmware)
    machine = load_machine_profile(opts.machine)
    path = opts.settings_path
    eeprom = load_eeprom(path) if path is not None else None

    def persist(image: Eeprom) -> None:
        assert path is not None
        save_eeprom(path, image)

    return GrblFirmware(
        profile,
        machine,
        eeprom=eeprom,
        on_eeprom_write=persist if path is not None else None,
        keep_trace=opts.trace_path is not None,
    )


class SimServer:
    """The simulator on a pseudo-terminal and/or a loopback TCP port, until stopped."""

    def __init__(self, opts: ServeOptions, *, out: Callable[[str], None] | None = None) -> None:
        """Prepare; serve() opens the ports."""
        self.opts = opts
        self.out = out if out is not None else _print
        self.firmware = build_firmware(opts)
        self.rig = SimRig(self.firmware, LinkModel(baud=opts.baud))
        self.sim = RealtimeSim(self.rig, self._on_line)
        self._pty: PtyPort | None = None
        self.pty_path: str | None = None
        self._server: asyncio.Server | None = None
        self.tcp_port: int | None = None
        self._clients: set[asyncio.StreamWriter] = set()
        #: `error:N` lines sent, by code, for the summary at the end.
        self.errors_sent: collections.Counter[str] = collections.Counter()

    async def serve(self, stop: asyncio.Event) -> None:
        """Open the ports, run until stop is set, then close everything."""
        runner = asyncio.create_task(self.sim.run())
        try:
            if self.opts.pty:
                # The simulator holds the pty's far end itself: it lives, and its output waits
                # in it, whether or not a sender has it open (as a UART's wires would).
                self._pty = PtyPort(self.sim.send, link_path=self.opts.link_path)
                self.pty_path = self._pty.open()
            if self.opts.tcp_port is not None:
                self._server = await asyncio.start_server(
                    self._on_client, "127.0.0.1", self.opts.tcp_port
                )
                self.tcp_port = self._server.sockets[0].getsockname()[1]
            self.out(self._ready_message())
            await stop.wait()
        finally:
            runner.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await runner
            self.sim.catch_up()
            await self._close()
            if self.opts.trace_path is not None:
                self.write_trace(self.opts.trace_path)

    def trace(self) -> list[TraceSegment]:
        """Every motion segment executed so far, its times on the loop's (the host's) clock."""
        at = self.sim.loop_time_s
        return [
            TraceSegment(at(seg.t0_s), at(seg.t1_s), seg.start_mm, seg.end_mm)
            for seg in self.rig.trace
        ]

    def write_trace(self, path: Path) -> None:
        """Write trace() as JSON Lines, atomically (a reader never sees half a file)."""
        tmp = path.with_name(path.name + ".tmp")
        try:
            with tmp.open("w", encoding="utf-8") as out:
                for seg in self.trace():
                    out.write(trace_line(seg) + "\n")
            os.replace(tmp, path)
        except OSError as exc:
            raise SimError(f"cannot write trace file {path}: {exc.strerror}") from None

    def summary(self) -> str:
        """What went wrong on the wire during the run, for the line printed at the end."""
        errors = ", ".join(f"error:{code} x{n}" for code, n in sorted(self.errors_sent.items()))
        return (
            f"RX bytes dropped {self.firmware.rx.dropped}; errors sent: {errors or 'none'};"
            f" G-code motion blocks {self.firmware.gcode_blocks}"
        )

    def _ready_message(self) -> str:
        """One line saying where to connect."""
        where = []
        if self.pty_path is not None:
            link = f" (link {self.opts.link_path})" if self.opts.link_path else ""
            where.append(f"pty {self.pty_path}{link}")
        if self.tcp_port is not None:
            where.append(f"tcp 127.0.0.1:{self.tcp_port}")
        return (
            f"smoothjog sim: {self.firmware.profile.banner} on {', '.join(where)};"
            f" machine {self.firmware.machine.name}; Ctrl-C to stop"
        )

    async def _on_client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """One TCP client: its bytes go to the controller; it gets every line it sends."""
        self._clients.add(writer)
        try:
            while data := await reader.read(_READ_CHUNK_BYTES):
                self.sim.send(data)
        except ConnectionError:
            pass
        finally:
            self._clients.discard(writer)
            writer.close()

    def _on_line(self, line: bytes) -> None:
        """A line from the controller: to the pty and to every TCP client."""
        data = line + b"\r\n"
        if line.startswith(b"error:"):
            self.errors_sent[line[6:].decode("ascii", "replace")] += 1
        if self._pty is not None:
            self._pty.write(data)  # nobody reading a full pty loses output
        for writer in list(self._clients):
            if not writer.is_closing():
                writer.write(data)

    async def _close(self) -> None:
        """Close ports, remove the symlink."""
        if self._server is not None:
            self._server.close()
            for writer in list(self._clients):
                writer.close()
            await self._server.wait_closed()
        if self._pty is not None:
            self._pty.close()
            self._pty = None


def _print(text: str) -> None:
    """Print a status line at once (a parent process may be waiting for it)."""
    print(text, flush=True)


async def serve_until_signal(opts: ServeOptions) -> int:
    """Serve until SIGINT or SIGTERM; returns the exit code."""
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    received: list[str] = []

    def on_signal(name: str) -> None:
        received.append(name)
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, on_signal, sig.name)
    server = SimServer(opts)
    try:
        await server.serve(stop)
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
    why = received[0] if received else "request"
    print(f"smoothjog sim: stopped on {why} ({server.summary()})", file=sys.stderr, flush=True)
    return 0

"""A Link over a serial port (USB or UART), opened with pyserial and driven by the event loop.

pyserial opens and configures the port (raw mode, baud, exclusive lock); after that the link
reads and writes the file descriptor itself, non-blocking, from the event loop (`add_reader` /
`add_writer`) rather than from a reader thread. Why: there is no thread to hand lines across or to
stop, a realtime byte is written from the same thread that orders the queue (so it can overtake
the queued lines safely), and a vanished device shows up at once as a readable fd that returns an
error. The cost: this needs a selector event loop on a POSIX system (Linux, macOS, BSD).
"""

from __future__ import annotations

import asyncio
import errno
import itertools
import os
import stat

import serial

from smoothjog.core.errors import LinkError
from smoothjog.core.firmware import BITS_PER_BYTE_8N1
from smoothjog.core.realtime import STATUS_QUERY
from smoothjog.core.responses import Banner, StatusReport, parse_response
from smoothjog.links.base import READ_CHUNK_BYTES, WRITE_CHUNK_BYTES, LineInbox, Link, OutQueue

#: Grbl's default baud rate (firmware-facts §5.1).
DEFAULT_BAUD = 115200
#: An Arduino-based Grbl resets when the port opens (DTR); its bootloader waits about 1-2 s before
#: Grbl prints the banner. open() waits at most this long for a first sign of life.
DEFAULT_WAIT_BANNER_S = 2.5
#: How long open() waits for a banner before asking `?`: a controller that does not reset on open
#: (grblHAL, FluidNC, a Grbl board without the DTR reset) prints none and answers `?` at once.
QUICK_BANNER_S = 0.05
#: How often `?` is asked again while nothing answers (a controller still in its bootloader).
PROBE_INTERVAL_S = 0.25


def is_banner(line: bytes) -> bool:
    """True when line is a Grbl-family welcome banner."""
    return isinstance(parse_response(line), Banner)


def _is_alive(line: bytes) -> bool:
    """True for a banner (the controller restarted) or a status report (it runs, no reset)."""
    return isinstance(parse_response(line), (Banner, StatusReport))


class SerialLink(Link):
    """A serial port to a controller; `open()` waits for the reset banner or a status report."""

    def __init__(
        self,
        path: str,
        baud: int = DEFAULT_BAUD,
        *,
        wait_banner_s: float = DEFAULT_WAIT_BANNER_S,
    ) -> None:
        """Describe the port; nothing is opened until open()."""
        self.path = path
        self.baud = baud
        self.wait_banner_s = wait_banner_s
        self._serial: serial.Serial | None = None
        self._fd = -1
        self._inbox = LineInbox()
        # Each entry is one encoded line or one realtime byte, not yet fully written.
        self._out = OutQueue()
        # Bytes of the first queued item already written: a realtime byte must not land inside
        # that line.
        self._head_written = 0
        self._writer_armed = False
        self._corked = False  # a host's tick is queuing several items: write them at uncork()
        self._error: LinkError | None = None
        self.banner_seen = False

    def describe(self) -> str:
        """The port and its speed."""
        return f"{self.path} at {self.baud} baud"

    @property
    def queued_bytes(self) -> int:
        """Bytes accepted by the link but not yet handed to the operating system."""
        return self._out.size

    async def open(self) -> None:
        """Open the port and wait up to wait_banner_s for a sign of life: the banner a reset
        prints, or the answer to `?` from a controller that did not reset (see _await_life)."""
        if self._serial is not None:
            return
        if self.baud <= 0:
            raise LinkError(
                f"baud rate {self.baud} for {self.path} is not positive: use e.g. 115200"
            )
        self._check_path()
        port = self._open_port()
        loop = asyncio.get_running_loop()
        self._serial = port
        self._fd = port.fileno()
        os.set_blocking(self._fd, False)
        self._inbox = LineInbox()
        self._error = None
        loop.add_reader(self._fd, self._on_readable)
        self.banner_seen = await self._await_life()
        if self._error is not None:
            await self.close()
            raise self._error

    async def _await_life(self) -> bool:
        """Wait for a banner or a status report; True when a banner came.

        A banner within QUICK_BANNER_S ends the wait. Otherwise `?` is asked, and again every
        PROBE_INTERVAL_S: a controller that did not reset answers it within a round trip, so
        connecting to it takes no banner wait; one that is still booting (an Arduino's bootloader
        after the DTR reset) ignores it and prints its banner later. Only `?` is sent here: a
        realtime byte that a restarting controller runs as nothing but a report. Nothing is read
        from the inbox: the banner or report stays for the handshake.
        """
        loop = asyncio.get_running_loop()
        deadline_s = loop.time() + self.wait_banner_s
        wait_s = min(QUICK_BANNER_S, self.wait_banner_s)
        while not await self._inbox.wait_for(_is_alive, wait_s):
            remaining_s = deadline_s - loop.time()
            if remaining_s <= 0 or self._error is not None or self._inbox.ended:
                return False
            self._write_realtime(STATUS_QUERY)
            wait_s = min(PROBE_INTERVAL_S, remaining_s)
        return any(is_banner(line) for line in self._inbox.peek())

    async def read_line(self) -> bytes:
        """The next received line without its end-of-line."""
        return await self._inbox.get()

    async def close(self) -> None:
        """Stop watching the port and close it; harmless when already closed."""
        port, self._serial = self._serial, None
        if port is None:
            return
        self._stop_watching()
        self._out.clear()
        closed = LinkError(f"the link to {self.describe()} was closed")
        if self._error is None:
            self._error = closed
        self._inbox.close(closed)
        port.close()

    async def _write_line(self, data: bytes) -> None:
        """Queue a line and write what the OS accepts now; wait while the queue is too long."""
        await self._out.put(data, self._check_usable)
        self._flush()

    def _write_line_nowait(self, data: bytes) -> bool:
        """Queue a line and write what the OS accepts now, unless the queue is too long."""
        if not self._out.put_nowait(data, self._check_usable):
            return False
        if not self._corked:
            self._flush()
        return True

    def cork(self) -> None:
        """Queue lines and realtime bytes without writing them until uncork()."""
        self._corked = True

    def uncork(self) -> None:
        """Write everything queued since cork() (one system call for a line and its `?`)."""
        self._corked = False
        if self._serial is not None and self._error is None:
            self._flush()

    def byte_time_s(self) -> float:
        """One byte at this baud rate, 8N1."""
        return BITS_PER_BYTE_8N1 / self.baud

    def _line_inbox(self) -> LineInbox:
        return self._inbox

    def _write_realtime(self, byte: bytes) -> None:
        """Put the byte ahead of every whole queued line, then write."""
        self._check_usable()
        # A line already partly written must finish first: grblHAL drops a half-read line on a
        # jog cancel (firmware-facts §7), which would turn its second half into a garbled new line.
        self._out.insert(1 if self._head_written else 0, byte)
        if not self._corked:
            self._flush()

    def _check_usable(self) -> None:
        """Raise the link's error if it is closed or the device has gone."""
        if self._error is not None:
            raise self._error
        if self._serial is None:
            raise LinkError(f"the link to {self.describe()} is not open: call open() first")

    def _flush(self) -> None:
        """Write as much of the queue as the OS takes; arm the writer callback for the rest."""
        items = self._out.items
        while items:
            chunk = bytearray(items[0][self._head_written :])
            for item in itertools.islice(items, 1, None):
                if len(chunk) + len(item) > WRITE_CHUNK_BYTES:
                    break
                chunk += item
            try:
                written = os.write(self._fd, chunk)
            except BlockingIOError:
                written = 0
            except OSError as exc:
                self._lost(f"writing failed: {exc.strerror}")
                return
            self._consume(written)
            if written < len(chunk):
                break
        self._arm_writer(bool(items))

    def _consume(self, written: int) -> None:
        """Drop written bytes from the front of the queue."""
        self._out.taken(written)
        items = self._out.items
        while written > 0:
            left_in_head = len(items[0]) - self._head_written
            if written >= left_in_head:
                items.popleft()
                self._head_written = 0
                written -= left_in_head
            else:
                self._head_written += written
                written = 0

    def _arm_writer(self, wanted: bool) -> None:
        """Ask the loop to call _flush when the fd can take more, or stop asking."""
        if wanted == self._writer_armed:
            return
        loop = asyncio.get_running_loop()
        if wanted:
            loop.add_writer(self._fd, self._flush)
        else:
            loop.remove_writer(self._fd)
        self._writer_armed = wanted

    def _on_readable(self) -> None:
        """Read what arrived and frame it into lines."""
        try:
            data = os.read(self._fd, READ_CHUNK_BYTES)
        except BlockingIOError:
            return
        except OSError as exc:
            self._lost(f"reading failed: {exc.strerror}")
            return
        if not data:
            self._lost("the device reported end of file")
            return
        self._inbox.feed(data)

    def _lost(self, reason: str) -> None:
        """The device went away: stop watching it and fail every reader and writer."""
        self._stop_watching()
        error = LinkError(
            f"lost {self.describe()} ({reason}): the controller was unplugged, reset or"
            " powered off; check the cable and connect again"
        )
        self._error = error
        self._out.clear()
        self._inbox.peer_gone(error)

    def _stop_watching(self) -> None:
        """Remove the fd from the event loop."""
        if self._fd < 0:
            return
        loop = asyncio.get_running_loop()
        loop.remove_reader(self._fd)
        if self._writer_armed:
            loop.remove_writer(self._fd)
            self._writer_armed = False

    def _check_path(self) -> None:
        """Refuse a path that does not exist or is not a character device, with a clear hint."""
        try:
            mode = os.stat(self.path).st_mode
        except FileNotFoundError:
            raise LinkError(
                f"no serial port at {self.path}: check that the controller is plugged in and"
                " the name is right (ls /dev/ttyUSB* /dev/ttyACM*)"
            ) from None
        except OSError as exc:
            raise LinkError(f"cannot look at {self.path}: {exc.strerror}") from None
        if not stat.S_ISCHR(mode):
            raise LinkError(
                f"{self.path} is not a serial port (it is not a device file): give the"
                " controller's port, e.g. /dev/ttyUSB0 or /dev/ttyACM0"
            )

    def _open_port(self) -> serial.Serial:
        """Open and configure the port with pyserial, translating its errors."""
        try:
            return serial.Serial(
                self.path,
                self.baud,
                timeout=0,
                write_timeout=0,
                exclusive=True,
            )
        except ValueError as exc:
            raise LinkError(f"cannot use {self.describe()}: {exc}; try 115200") from None
        except serial.SerialException as exc:
            raise self._open_error(exc) from None

    def _open_error(self, exc: serial.SerialException) -> LinkError:
        """One actionable sentence for a failed open."""
        code = exc.errno
        if code == errno.EACCES:
            return LinkError(
                f"permission denied opening {self.path}: add your user to the port's group"
                " (e.g. `sudo usermod -aG dialout $USER`, then log in again)"
            )
        if code in (errno.EBUSY, errno.EAGAIN) or "exclusively lock" in str(exc):
            return LinkError(
                f"{self.path} is in use by another program (a G-code sender, a serial"
                " monitor?): close it and try again"
            )
        if code in (errno.ENOENT, errno.ENODEV, errno.ENXIO):
            return LinkError(
                f"no serial port at {self.path}: check that the controller is plugged in"
                " and powered"
            )
        if code in (errno.ENOTTY, errno.EINVAL) or "Inappropriate ioctl" in str(exc):
            return LinkError(
                f"{self.path} is not a serial port: give the controller's port,"
                " e.g. /dev/ttyUSB0 or /dev/ttyACM0"
            )
        return LinkError(f"cannot open {self.describe()}: {exc}")

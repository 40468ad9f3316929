"""A raw pseudo-terminal whose far end a program opens as if it were a controller's serial port.

Two things serve a pty: the simulator (`smoothjog sim`) and the proxy (`smoothjog proxy`), where
a desktop sender opens it. Both need the same opening: a raw pty (no echo, no CR/LF
translation), a stable symlink to its slave (`--link`), reading from the master on the event
loop, and the symlink gone at the end. They differ in one thing:

- the simulator keeps the slave open itself (`hold_slave=True`), so the pty lives whether or not
  anybody has it open, and output written meanwhile waits in it as it would in a UART's wires;
- the proxy does not (`hold_slave=False`), so it can tell when a sender opens and closes the
  port (to replay the banner on open, and to write nothing while nobody listens).

What the second relies on (Linux, checked on a 6.x kernel): while no process has the slave
open, poll() on the master reports POLLHUP and read() on it fails with EIO; the moment a process
opens the slave, POLLHUP goes away; the termios settings made once (raw mode) survive the slave
being closed and opened again; bytes written to the master while the slave is closed are kept
for the next opener, which is why the port flushes them (TCOFLUSH on the master drops only what
the master wrote, never what the sender wrote). The open is found by polling for POLLHUP to go
away every `poll_s` (50 ms), so a sender may wait that long for its banner.

A leaf module (it imports only core): the simulator may not import the links layer.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import select
import termios
import tty
from collections.abc import Callable
from pathlib import Path

from smoothjog.core.errors import LinkError

#: Most bytes taken from the master in one read.
READ_CHUNK_BYTES = 4096
#: How often a port whose slave nobody holds looks whether a program has opened it.
OPEN_POLL_S = 0.05


class PtyPort:
    """A raw pty with an optional stable symlink; bytes from the far end go to on_data."""

    def __init__(
        self,
        on_data: Callable[[bytes], None],
        *,
        link_path: Path | None = None,
        hold_slave: bool = True,
        on_open: Callable[[], None] | None = None,
        on_close: Callable[[], None] | None = None,
        poll_s: float = OPEN_POLL_S,
    ) -> None:
        """Prepare; open() makes the pty (and the symlink) on the running loop.

        on_open and on_close are called when a program opens and closes the slave; they are
        only ever called with hold_slave=False (a held slave is always open).
        """
        self.on_data = on_data
        self.link_path = link_path
        self.hold_slave = hold_slave
        self.on_open = on_open
        self.on_close = on_close
        self.poll_s = poll_s
        #: The slave's path (/dev/pts/N) once open() has run.
        self.path: str | None = None
        self._master = -1
        self._slave = -1
        self._loop: asyncio.AbstractEventLoop | None = None
        self._symlink_made = False
        self._reading = False
        self._peer = False
        self._poller: asyncio.TimerHandle | None = None

    @property
    def peer_open(self) -> bool:
        """True while a program has the slave open (always, for a held slave)."""
        return self._master >= 0 and (self.hold_slave or self._peer)

    def open(self) -> str:
        """Make the pty and the symlink, start reading; returns the slave's path."""
        loop = asyncio.get_running_loop()
        master, slave = os.openpty()
        # Raw mode: no echo, no CR/LF translation; the bytes are the controller's bytes.
        tty.setraw(slave, termios.TCSANOW)
        os.set_blocking(master, False)
        self._loop = loop
        self._master = master
        self.path = os.ttyname(slave)
        if self.hold_slave:
            self._slave = slave
        else:
            os.close(slave)  # the sender's open is seen as POLLHUP going away
        try:
            self._make_symlink()
        except BaseException:
            self.close()
            raise
        if self.hold_slave:
            self._start_reading()
        else:
            self._watch_for_open()
        return self.path

    def write(self, data: bytes) -> bool:
        """Write data to whoever has the port open; False (nothing written) if nobody does.

        A reader that does not keep up loses output, as a serial line with no listener would.
        """
        if not self.peer_open:
            return False
        try:
            os.write(self._master, data)
        except (BlockingIOError, OSError):
            return False
        return True

    def close(self) -> None:
        """Stop reading, close the pty, remove the symlink (closing twice is harmless)."""
        if self._poller is not None:
            self._poller.cancel()
            self._poller = None
        if self._master >= 0:
            if self._reading and self._loop is not None:
                self._loop.remove_reader(self._master)
            self._reading = False
            os.close(self._master)
            self._master = -1
        if self._slave >= 0:
            os.close(self._slave)
            self._slave = -1
        self._peer = False
        if self._symlink_made and self.link_path is not None:
            with contextlib.suppress(FileNotFoundError):
                self.link_path.unlink()
            self._symlink_made = False

    # ----------------------------------------------------------------- internals
    def _make_symlink(self) -> None:
        link = self.link_path
        if link is None:
            return
        assert self.path is not None
        if link.is_symlink():
            link.unlink()
        elif link.exists():
            raise LinkError(f"--link {link} exists and is not a symlink; choose another path")
        try:
            link.symlink_to(self.path)
        except OSError as exc:
            raise LinkError(f"cannot create --link {link}: {exc.strerror}") from None
        self._symlink_made = True

    def _start_reading(self) -> None:
        assert self._loop is not None
        self._loop.add_reader(self._master, self._on_readable)
        self._reading = True

    def _on_readable(self) -> None:
        """Bytes from whoever has the pty open, or (not held) the sign that they closed it."""
        try:
            data = os.read(self._master, READ_CHUNK_BYTES)
        except BlockingIOError:
            return
        except OSError:
            # EIO: nobody has the slave open. A held slave never gives it; otherwise the
            # sender closed the port: stop reading (the loop would be woken for it forever).
            if not self.hold_slave:
                self._peer_closed()
            return
        if data:
            self.on_data(data)

    def _hung_up(self) -> bool:
        poller = select.poll()
        poller.register(self._master, select.POLLIN)
        return any(event & select.POLLHUP for _fd, event in poller.poll(0))

    def _watch_for_open(self) -> None:
        """Look every poll_s whether a program opened the slave."""
        self._poller = None
        if self._master < 0 or self._loop is None:
            return
        if self._hung_up():
            self._poller = self._loop.call_later(self.poll_s, self._watch_for_open)
            return
        # Whatever was written while nobody listened is stale for the new opener.
        termios.tcflush(self._master, termios.TCOFLUSH)
        self._peer = True
        self._start_reading()
        if self.on_open is not None:
            self.on_open()

    def _peer_closed(self) -> None:
        assert self._loop is not None
        if self._reading:
            self._loop.remove_reader(self._master)
            self._reading = False
        was_open, self._peer = self._peer, False
        with contextlib.suppress(OSError):
            termios.tcflush(self._master, termios.TCOFLUSH)
        if was_open and self.on_close is not None:
            self.on_close()
        self._watch_for_open()

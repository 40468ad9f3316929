"""Machine control beside the jog engine: unlock, home, reset, work zero, WCS, overrides, console.

Any input that offers more than jogging (the pendant today) asks this one object. Every line it
writes goes through the host's ledger as the `console` owner, so its RX bytes are counted with the
engine's and its reply comes back to it alone. Nothing here runs while a jog moves: a command
refused for that says so in words ("press STOP first"), and while a command is in flight new jogs
are refused too (`busy_reason`), because a `$J=` written behind `$H` would be read, and run, the
moment homing ends (lines are not read during homing, firmware-facts §1.4).

A line that may change what the engine relies on is allowed (it is the user's machine) and is
followed by reading the machine again: after `$N=value` the settings (`$$`) and the engine's
limits, after G-code the parser modes (`$G`) and offsets (`$#`), which the pendant shows.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass
from typing import Final

from smoothjog.core import realtime
from smoothjog.core.codes import describe_error
from smoothjog.core.errors import SmoothjogError
from smoothjog.core.firmware import for_model
from smoothjog.core.ledger import CONSOLE
from smoothjog.core.realtime import OVERRIDE_KINDS, OVERRIDE_STEPS, OVERRIDES
from smoothjog.core.responses import ErrorReply
from smoothjog.host import Host
from smoothjog.links.base import encode_line

#: Lines that end quickly; a longer wait means the controller is stuck or the line is a dwell.
LINE_TIMEOUT_S: Final = 30.0
#: A homing cycle seeks the whole travel at `$25` and then creeps at `$24`; two minutes covers
#: an 800 mm router at 2000 mm/min with room to spare. The reply `ok` comes when homing ends.
HOME_TIMEOUT_S: Final = 120.0
#: After a soft reset: the banner, then the host reads the settings again.
RESET_TIMEOUT_S: Final = 10.0
#: The work coordinate systems every Grbl has (G10 L20 P1..P6).
WCS_WORDS: Final = ("G54", "G55", "G56", "G57", "G58", "G59")
#: Machine states in which nothing may be sent but a stop: the machine is moving.
MOVING_STATES: Final = frozenset({"Run", "Jog", "Home"})
#: How far below the top of Z travel "safe height" is when soft limits give the top, in mm.
SAFE_Z_BELOW_TOP_MM: Final = 1.0
#: Without soft limits the top of Z is unknown: go up this far above work zero instead (an
#: assumption: a clamp or vise is seldom taller; the user can change it in [pendant] safe_z_mm).
DEFAULT_SAFE_Z_WORK_MM: Final = 10.0


_SETTING_LINE = re.compile(r"^\s*\$(\d+|[A-Za-z][\w/]*)\s*=", re.ASCII)
_GCODE_LINE = re.compile(r"^\s*[GMTgmt]|^\s*[Nn]\d", re.ASCII)


class ControlRefused(SmoothjogError):  # noqa: N818 -- a refusal in words, as InputRefused
    """A machine command cannot run now, or is malformed; the text says why and what to do."""


@dataclass(frozen=True)
class CommandResult:
    """What one command did: the line or byte sent, what the controller printed, and its verdict."""

    command: str
    ok: bool
    lines: tuple[str, ...] = ()
    error: str | None = None


class MachineControl:
    """The machine commands of one session, over its host; one command runs at a time."""

    def __init__(self, host: Host, *, safe_z_work_mm: float = DEFAULT_SAFE_Z_WORK_MM) -> None:
        """Commands for host (started, with its engine); safe_z_work_mm is used without soft
        limits."""
        self.host = host
        self.safe_z_work_mm = safe_z_work_mm
        #: The command in flight, in words ("homing"), or None.
        self.running: str | None = None

    # ----------------------------------------------------------------- when
    def refusal(self, *, locked_ok: bool = False) -> str | None:
        """Why no command may start now, in words, or None when one may.

        While another program holds the machine (the jog lock: a sender's job through the
        proxy, a CNCjs job) a line would land in the middle of its job and change it, so lines
        wait too, in the lock's words; locked_ok lets through what cannot change a job (an
        override byte, the reset that ends it).
        """
        host = self.host
        if host.link_error is not None:
            return "the connection to the controller is lost"
        if self.running is not None:
            return f"wait: {self.running} has not finished"
        state = host.model.state
        if host.model.jog_lock is not None and not locked_ok:
            return host.model.jog_lock
        if host.rehandshaking:
            return "the controller restarted: wait while smoothjog reads its settings again"
        if host.busy() or state in MOVING_STATES:
            return "the machine is moving: press STOP and wait until it stands still"
        return None

    def busy_reason(self) -> str | None:
        """Why a new jog must wait for a command, or None."""
        return None if self.running is None else f"{self.running} is running"

    @property
    def homing_enabled(self) -> bool:
        """`$22=1`: only then does `$H` exist."""
        return self.host.model.settings.homing

    # ----------------------------------------------------------------- the commands
    async def unlock(self) -> CommandResult:
        """`$X`: leave Alarm without homing. Soft limits then trust a position that may be wrong."""
        return await self._line("$X", "unlocking")

    async def home(self) -> CommandResult:
        """`$H`: run the homing cycle; the reply comes when it ends (two minutes at most)."""
        if not self.homing_enabled:
            raise ControlRefused(
                "homing is not enabled on this controller ($22=0): there are no switches to "
                "home to; set $22=1 only if the machine has them"
            )
        return await self._line("$H", "homing", timeout_s=HOME_TIMEOUT_S, reread=True)

    async def soft_reset(self) -> CommandResult:
        """Ctrl-X: the controller restarts; the host reads its settings again before any jog."""
        async with self._running("resetting", locked_ok=True):
            host = self.host
            before = host.model.reset_count
            host.send_realtime(CONSOLE, realtime.RESET)
            loop = asyncio.get_running_loop()
            end_s = loop.time() + RESET_TIMEOUT_S
            while host.model.reset_count == before or host.rehandshaking:
                if host.link_error is not None:
                    return CommandResult("Ctrl-X", False, error=str(host.link_error))
                if loop.time() > end_s:
                    return CommandResult(
                        "Ctrl-X",
                        False,
                        error=f"the controller did not restart within {RESET_TIMEOUT_S:g} s",
                    )
                await asyncio.sleep(0.02)
            if host.error is not None:
                return CommandResult("Ctrl-X", False, error=str(host.error))
            return CommandResult("Ctrl-X", True)

    async def set_work_zero(self, axes: Sequence[str]) -> CommandResult:
        """`G10 L20 P0 X0 ...`: the machine's place now becomes work zero of the active WCS."""
        known = self.host.model.axis_letters
        if not axes:
            raise ControlRefused("name at least one axis to zero")
        for axis in axes:
            if axis not in known:
                raise ControlRefused(f"this machine has no {axis} axis (it has {', '.join(known)})")
        words = "".join(f"{axis}0" for axis in axes)
        return await self._line(f"G10L20P0{words}", "setting work zero", reread=True)

    async def select_wcs(self, word: str) -> CommandResult:
        """Make G54..G59 the active work coordinate system."""
        if word not in WCS_WORDS:
            raise ControlRefused(f"{word!r} is not one of {', '.join(WCS_WORDS)}")
        return await self._line(word, f"selecting {word}", reread=True)

    async def override(self, kind: str, step: str) -> CommandResult:
        """A feed or rapid override byte; the next reports' `Ov:` shows the new value."""
        byte = OVERRIDES.get((kind, step))
        if byte is None:
            steps = OVERRIDE_STEPS.get(kind)
            if steps is None:
                raise ControlRefused(
                    f"no override {kind!r}; the overrides are {', '.join(OVERRIDE_KINDS)}"
                )
            raise ControlRefused(f"{kind} override has no step {step!r}; use {', '.join(steps)}")
        reason = self.refusal(locked_ok=True)
        if reason is not None:
            raise ControlRefused(reason)
        self.host.send_realtime(CONSOLE, byte)
        return CommandResult(f"0x{byte[0]:02X}", True)

    async def hold(self) -> CommandResult:
        """Feed hold (`!`): allowed at any time, as a stop is; a jog is better ended by STOP."""
        self.host.send_realtime(CONSOLE, realtime.FEED_HOLD)
        return CommandResult("!", True)

    async def resume(self) -> CommandResult:
        """Cycle start (`~`) after a feed hold; refused in any other state, where it would start
        lines nobody is watching (or do nothing)."""
        state = self.host.model.state or "an unknown state"
        if not state.startswith("Hold"):
            raise ControlRefused(f"nothing to resume: the machine is in {state}, not in Hold")
        # A hold during a jog cancels the jog (it ends Idle, not Hold), so this never restarts
        # jog lines; it resumes what the hold paused, a program's motion.
        self.host.send_realtime(CONSOLE, realtime.CYCLE_START)
        return CommandResult("~", True)

    async def console(self, line: str) -> CommandResult:
        """Send one line the user typed; settings and modes are read again when it changed them."""
        text = line.strip()
        if not text:
            raise ControlRefused("type a line to send, for example $G or G0 X10")
        limit = for_model(self.host.model).max_line_chars
        if len(text) > limit:
            raise ControlRefused(
                f"the line is {len(text)} characters; this controller reads at most {limit}"
            )
        try:
            encode_line(text)
        except SmoothjogError as exc:
            raise ControlRefused(str(exc)) from None
        return await self._line(text, "a console line", reread=True)

    def work_zero_targets(self) -> list[dict[str, float]]:
        """Go to work zero in three straight moves: Z up to a safe height, X and Y, then Z down.

        Targets are machine positions (the engine jogs with G53). Z never goes down on the way
        across: the safe height is the higher of where Z is and the safe plane.
        """
        model = self.host.model
        letters = model.axis_letters
        mpos, wco = model.mpos_mm, model.wco_mm
        if mpos is None or wco is None or len(wco) != len(mpos):
            raise ControlRefused(
                "the work offset is not known yet; wait for the next status report"
            )
        zero = {axis: wco[i] for i, axis in enumerate(letters)}
        moves: list[dict[str, float]] = []
        if "Z" in letters:
            z = letters.index("Z")
            envelope = model.soft_limit_envelope()
            if envelope is not None:
                safe_z = envelope.max_mm[z] - SAFE_Z_BELOW_TOP_MM
            else:
                safe_z = wco[z] + self.safe_z_work_mm
            safe_z = max(safe_z, mpos[z])
            if safe_z > mpos[z]:
                moves.append({"Z": safe_z})
        across = {a: v for a, v in zero.items() if a != "Z"}
        if across:
            moves.append(across)
        if "Z" in zero:
            moves.append({"Z": zero["Z"]})
        return moves

    # ----------------------------------------------------------------- internals
    @contextlib.asynccontextmanager
    async def _running(self, what: str, *, locked_ok: bool = False) -> AsyncIterator[None]:
        """Mark a command as running for its whole length; refuse it when another may not."""
        reason = self.refusal(locked_ok=locked_ok)
        if reason is not None:
            raise ControlRefused(reason)
        self.running = what
        try:
            yield
        finally:
            self.running = None

    async def _line(
        self, text: str, what: str, *, timeout_s: float = LINE_TIMEOUT_S, reread: bool = False
    ) -> CommandResult:
        async with self._running(what):
            host = self.host
            try:
                lines, reply = await host.console(text, timeout_s=timeout_s)
            except SmoothjogError as exc:
                return CommandResult(text, False, error=str(exc))
            if isinstance(reply, ErrorReply):
                return CommandResult(text, False, tuple(lines), describe_error(reply.code))
            if reread:
                await self._read_back(text)
            return CommandResult(text, True, tuple(lines))

    async def _read_back(self, text: str) -> None:
        """Read again what the line may have changed, so the engine and the page stay true."""
        host = self.host
        try:
            if _SETTING_LINE.match(text):
                await host.reread_settings()
            elif _GCODE_LINE.match(text) or text.upper().startswith("$H"):
                await host.console("$G", timeout_s=LINE_TIMEOUT_S)
                if host.model.state in ("Idle", "Alarm"):
                    # `$#` is answered only at rest (firmware-facts §5.3).
                    await host.console("$#", timeout_s=LINE_TIMEOUT_S)
        except SmoothjogError:
            # The command itself succeeded; the page shows the last modes it knows.
            pass

"""Machine commands beside the jog engine: unlock, home, reset, work zero, WCS, overrides, console.

Every input that offers more than jogging (the pendant, a device's buttons) runs the commands
of the catalogue (authority/commands.py) here, and the session's MotionGate says when each may
run. Every line goes through the host's ledger as the `console` owner, so its RX bytes are
counted with the engine's and its reply comes back to it alone. While a line command is in
flight new jogs wait (a `$J=` written behind `$H` would run the moment homing ends, lines are
not read during homing, firmware-facts §1.4); a reset never waits for anything.

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

from smoothjog.authority.commands import HOME_TIMEOUT_S, LINE_TIMEOUT_S, command
from smoothjog.authority.gate import MotionGate
from smoothjog.core import realtime
from smoothjog.core.codes import describe_error
from smoothjog.core.errors import SmoothjogError
from smoothjog.core.firmware import for_model
from smoothjog.core.ledger import CONSOLE
from smoothjog.core.realtime import OVERRIDE_KINDS, OVERRIDE_STEPS, OVERRIDES
from smoothjog.core.responses import ErrorReply
from smoothjog.core.states import LineKind, is_homing, line_kind, moves
from smoothjog.host import Host
from smoothjog.links.base import encode_line

#: After a soft reset: the banner, then the host reads the settings again.
RESET_TIMEOUT_S: Final = 10.0
#: After a limit alarm, a reset with no banner by then is sent once more (docs/firmware-facts.md
#: §5.6a: Grbl 1.1h ignores one that arrives before its wait loop begins).
RESET_AGAIN_S: Final = 0.75
#: The work coordinate systems every Grbl has (G10 L20 P1..P6).
WCS_WORDS: Final = ("G54", "G55", "G56", "G57", "G58", "G59")
#: How far below the top of Z travel "safe height" is when soft limits give the top, in mm.
SAFE_Z_BELOW_TOP_MM: Final = 1.0
#: Without soft limits the top of Z is unknown: go up this far above work zero instead (an
#: assumption: a clamp or vise is seldom taller; the user can change it in [pendant] safe_z_mm).
DEFAULT_SAFE_Z_WORK_MM: Final = 10.0
#: Longest wait for a status report asked just before a console line is judged.
FRESH_STATUS_S: Final = 0.3
#: A startup line that moves is stored only when the same line comes again within this time.
CONFIRM_S: Final = 15.0

_STARTUP_LINE = re.compile(r"^\s*\$N\d\s*=(?P<stored>.*)$", re.ASCII | re.IGNORECASE)


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
    """The machine commands of one session, over its host; one line command runs at a time."""

    def __init__(
        self,
        host: Host,
        *,
        gate: MotionGate | None = None,
        safe_z_work_mm: float = DEFAULT_SAFE_Z_WORK_MM,
    ) -> None:
        """Commands for host (started, with its engine), asking gate (the session's, or a new
        one) when each may run; safe_z_work_mm is used without soft limits."""
        self.host = host
        self.gate = gate if gate is not None else MotionGate(host)
        self.safe_z_work_mm = safe_z_work_mm
        self._resetting = False
        #: A startup line that moves, refused once, and when: sent again in time, it is stored.
        self._unconfirmed: tuple[str, float] | None = None

    def attach(self, host: Host) -> None:
        """Drive a new host (the link was lost and opened again); the gate follows it."""
        self.host = host
        self.gate.attach(host)

    @property
    def running(self) -> str | None:
        """The command in flight, in words ("homing"), or None."""
        return self.gate.running

    # ----------------------------------------------------------------- when
    def refusal(self, *, locked_ok: bool = False) -> str | None:
        """Why no line command may start now, in words, or None (see MotionGate.busy_refusal)."""
        return self.gate.busy_refusal(locked_ok=locked_ok)

    @property
    def homing_enabled(self) -> bool:
        """`$22=1`: only then does `$H` exist."""
        return self.host.model.settings.homing

    # ----------------------------------------------------------------- one dispatcher
    async def run(
        self,
        name: str,
        *,
        axes: Sequence[str] = (),
        wcs: str = "",
        kind: str = "",
        step: str = "",
        line: str = "",
    ) -> CommandResult:
        """Run the catalogue's command name with its arguments (goto_zero is the caller's:
        its moves are jogs, submitted through the arbiter)."""
        if name == "unlock":
            return await self.unlock()
        if name == "home":
            return await self.home()
        if name == "reset":
            return await self.soft_reset()
        if name == "zero":
            return await self.set_work_zero(axes or self.host.model.axis_letters)
        if name == "wcs":
            return await self.select_wcs(wcs)
        if name == "override":
            return await self.override(kind or "feed", step or "reset")
        if name == "hold":
            return await self.hold()
        if name == "resume":
            return await self.resume()
        if name == "console":
            return await self.console(line)
        raise ControlRefused(f"unknown command {name!r}")

    # ----------------------------------------------------------------- the commands
    async def unlock(self) -> CommandResult:
        """`$X`: leave Alarm without homing. Soft limits then trust a position that may be wrong."""
        return await self._line("unlock", "$X")

    async def home(self) -> CommandResult:
        """`$H`: run the homing cycle; the reply comes when it ends (two minutes at most)."""
        if not self.homing_enabled:
            raise ControlRefused(
                "homing is not enabled on this controller ($22=0): there are no switches to "
                "home to; set $22=1 only if the machine has them"
            )
        return await self._line("home", "$H", timeout_s=HOME_TIMEOUT_S, reread=True)

    async def soft_reset(self) -> CommandResult:
        """Ctrl-X, at once, whatever runs: the controller restarts and the host reads its
        settings again before any jog. Lines still waiting for a reply fail with the banner."""
        host = self.host
        if host.link_error is not None:
            raise ControlRefused(str(host.link_error))
        if self._resetting:
            raise ControlRefused("wait: resetting has not finished")
        self._resetting = True
        try:
            return await self._reset(host)
        finally:
            self._resetting = False

    async def _reset(self, host: Host) -> CommandResult:
        before = host.model.reset_count
        host.send_realtime(CONSOLE, realtime.RESET)
        loop = asyncio.get_running_loop()
        end_s = loop.time() + RESET_TIMEOUT_S
        # Grbl 1.1h drops a Ctrl-X that lands just before it enters its limit-alarm wait (it
        # clears the reset flag there): once that window is over, one more goes.
        again_s: float | None = loop.time() + RESET_AGAIN_S if host.reset_needed else None
        while host.model.reset_count == before or host.rehandshaking:
            if again_s is not None and loop.time() >= again_s and host.model.reset_count == before:
                again_s = None
                host.send_realtime(CONSOLE, realtime.RESET)
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
        return await self._line("zero", f"G10L20P0{words}", reread=True)

    async def select_wcs(self, word: str) -> CommandResult:
        """Make G54..G59 the active work coordinate system."""
        if word not in WCS_WORDS:
            raise ControlRefused(f"{word!r} is not one of {', '.join(WCS_WORDS)}")
        return await self._line("wcs", word, reread=True)

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
        self._require("override")
        self.host.send_realtime(CONSOLE, byte)
        return CommandResult(f"0x{byte[0]:02X}", True)

    async def hold(self) -> CommandResult:
        """Feed hold (`!`) for a running program; a jog is better ended by STOP, which knows."""
        self._require("hold")
        self.host.send_realtime(CONSOLE, realtime.FEED_HOLD)
        return CommandResult("!", True)

    async def resume(self) -> CommandResult:
        """Cycle start (`~`) after a feed hold or a closed door; refused in any other state, where
        it would start lines nobody is watching (or do nothing)."""
        self._require("resume")
        # A hold during a jog cancels the jog (it ends Idle, not Hold), so this never restarts
        # jog lines; it resumes what the hold paused, a program's motion.
        self.host.send_realtime(CONSOLE, realtime.CYCLE_START)
        return CommandResult("~", True)

    async def console(self, line: str) -> CommandResult:
        """Send one line the user typed, if the controller takes it in its state now (read
        fresh); settings and modes are read again when it changed them."""
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
        self._require("console")
        await self._fresh_status()
        self._require("console", line=text)
        self._confirm_startup_line(text)
        return await self._line("console", text, reread=True)

    def work_zero_targets(self) -> list[dict[str, float]]:
        """Go to work zero in three straight moves: Z up to a safe height, X and Y, then Z down.

        Targets are machine positions (the engine jogs with G53). Z never goes down on the way
        across: the safe height is the higher of where Z is and the safe plane. Refused in words
        when the moves may not start now.
        """
        self._require("goto_zero")
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
    def _require(self, name: str, line: str | None = None) -> None:
        """Refuse the command in words unless the gate lets it run now."""
        reason = self.gate.command_refusal(name, line)
        if reason is not None:
            raise ControlRefused(reason)

    async def _fresh_status(self) -> None:
        """Ask `?` and wait (briefly) for its report, so a console line is judged on the state
        now, not on a report up to a poll period old."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(FRESH_STATUS_S):
                await self.gate.next_report()

    def _confirm_startup_line(self, text: str) -> None:
        """A startup line that moves runs at every reset and power-up: store it only when the
        user sends the same line again, knowingly."""
        match = _STARTUP_LINE.match(text)
        if match is None or not moves(match["stored"]):
            return
        now_s = asyncio.get_running_loop().time()
        pending = self._unconfirmed
        if pending is not None and pending[0] == text and now_s - pending[1] <= CONFIRM_S:
            self._unconfirmed = None
            return
        self._unconfirmed = (text, now_s)
        raise ControlRefused(
            "this startup line moves the machine at every reset and power-up; send the same line"
            f" again within {CONFIRM_S:g} s to store it anyway"
        )

    @contextlib.asynccontextmanager
    async def _running(self, name: str) -> AsyncIterator[None]:
        """Mark a command as running for its whole length; refuse it when it may not run."""
        self._require(name)
        self.gate.begin(command(name).doing)
        try:
            yield
        finally:
            self.gate.end()

    async def _line(
        self, name: str, text: str, *, timeout_s: float = LINE_TIMEOUT_S, reread: bool = False
    ) -> CommandResult:
        async with self._running(name):
            host = self.host
            self.gate.motion_line_sent(text)
            try:
                lines, reply = await host.console(text, timeout_s=timeout_s)
            except SmoothjogError as exc:
                return CommandResult(text, False, error=str(exc))
            finally:
                self.gate.motion_line_answered()
            if isinstance(reply, ErrorReply):
                return CommandResult(text, False, tuple(lines), describe_error(reply.code))
            if reread:
                await self._read_back(text)
            return CommandResult(text, True, tuple(lines))

    async def _read_back(self, text: str) -> None:
        """Read again what the line may have changed, so the engine and the page stay true."""
        host = self.host
        kind = line_kind(text)
        try:
            if kind is LineKind.SYSTEM and "=" in text:
                await host.reread_settings()
            elif kind is LineKind.GCODE or is_homing(text):
                await host.console("$G", timeout_s=LINE_TIMEOUT_S)
                if host.model.state in ("Idle", "Alarm"):
                    # `$#` is answered only at rest (firmware-facts §5.3).
                    await host.console("$#", timeout_s=LINE_TIMEOUT_S)
        except SmoothjogError:
            # The command itself succeeded; the page shows the last modes it knows.
            pass

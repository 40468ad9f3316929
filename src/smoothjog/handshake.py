"""Connect to a controller: ask `$I`, `$$`, `$G`, `$#` and `?`, fold the answers into a model.

Queries go one at a time (send-response, firmware-facts §5.1): send a line, feed every line that
comes back to the model, stop at its `ok` or `error:N`. Things a real controller does meanwhile are
expected: a banner before the first answer (the reset that opening a USB port causes), a banner in
the middle (a reset: the handshake starts over, once), `[MSG:...]` chatter, an Alarm state in which
some queries get `error:8`/`error:9` (noted, not fatal). An `ok` that arrives without the content
its query must produce is a stale reply to a line sent before a reset, and is skipped.

A query refused with `error:8` because the controller is busy (a startup line that moves after a
reset, another program's jog) is asked again once a status report shows Idle or Alarm, for at most
BUSY_WAIT_S in all; `read_controller` says which queries stayed unread.
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass
from typing import Protocol

from smoothjog.core.codes import ERR_IDLE_ERROR, describe_alarm, describe_error
from smoothjog.core.errors import ConnectError
from smoothjog.core.machine import MachineModel
from smoothjog.core.realtime import STATUS_QUERY
from smoothjog.core.responses import (
    Banner,
    BuildOptions,
    Empty,
    ErrorReply,
    GcodeModes,
    Ok,
    Parameter,
    Response,
    SettingLine,
    StatusReport,
    Unparsed,
    VersionInfo,
    parse_response,
)
from smoothjog.core.states import ACCEPTED_IN, SUSPENDED_STATES, LineKind
from smoothjog.core.units import ALL_AXES

logger = logging.getLogger(__name__)

DEFAULT_TIMEOUT_S = 5.0
#: Lines that are not Grbl at all, in a row, before giving up early (wrong baud rate, a modem).
FOREIGN_LINES_LIMIT = 20
#: How long to collect lines that were already waiting before the first query.
SETTLE_S = 0.1
#: How long a `?` may take when a query went unanswered and the state may say why (s).
STATUS_CHECK_S = 1.0
#: Banners survived during one handshake (see handshake()).
MAX_RESETS = 2
#: How long, in all, queries refused with error:8 (the controller busy) are asked again (s).
BUSY_WAIT_S = 5.0
#: How often a busy controller's state is asked while waiting for it to rest (s).
BUSY_POLL_S = 0.1
#: States in which Grbl answers `$I`, `$$` and `$#` (`system.c:system_execute_line`).
ANSWERING_STATES = ACCEPTED_IN[LineKind.SYSTEM]
#: A status report is not made in some states (homing, after a limit alarm: firmware-facts §5.2).


@dataclass(frozen=True, slots=True)
class Query:
    """A send-response query and the response type whose arrival makes its `ok` genuine."""

    line: str
    expects: tuple[type[Response], ...]


#: What a connect asks, in order (firmware-facts §5.3).
QUERIES: tuple[Query, ...] = (
    Query("$I", (VersionInfo, BuildOptions)),
    Query("$$", (SettingLine,)),
    Query("$G", (GcodeModes,)),
    Query("$#", (Parameter,)),
)


class QueryLink(Protocol):
    """What the handshake talks through: a Link, or the host's port that routes by owner."""

    async def send_line(self, text: str) -> None:
        """Send one line (the `\\n` is added)."""

    def send_realtime(self, byte: bytes) -> None:
        """Send one realtime byte."""

    async def read_line(self) -> bytes:
        """The next line meant for the handshake; LinkError once the peer is gone."""

    def describe(self) -> str:
        """Where the controller is, for messages."""


class ControllerSuspendedError(ConnectError):
    """The controller is in Hold, Door or Sleep and reads no line until someone resumes it."""

    def __init__(self, message: str, state: str) -> None:
        super().__init__(message)
        self.state = state


class ControllerResetError(ConnectError):
    """A banner arrived while a query was waiting: the controller reset and lost the query."""

    def __init__(self, banner: Banner, where: str) -> None:
        """Remember the banner that announced the reset."""
        super().__init__(
            f"{where} reset ({banner.raw!r}) while answering a query: check its power supply"
            " and the USB cable, and that no other program resets it"
        )
        self.banner = banner


@dataclass(frozen=True)
class Unread:
    """A query the controller refused to the end: its line, the error code, the last state seen."""

    line: str
    code: int
    state: str | None


@dataclass
class HandshakeResult:
    """The model the handshake filled, and the queries that stayed unread."""

    model: MachineModel
    unread: list[Unread]

    def unread_line(self, line: str) -> Unread | None:
        """The record of query line when it stayed unread, else None."""
        return next((u for u in self.unread if u.line == line), None)


@dataclass
class QueryResult:
    """The final reply to one query and everything that came before it."""

    line: str
    reply: Ok | ErrorReply
    responses: list[Response]


class Querier:
    """Send-response queries over a link, feeding every received line to a model."""

    def __init__(
        self, link: QueryLink, model: MachineModel, *, timeout_s: float, feed: bool = True
    ) -> None:
        """Query over link into model; each query must be answered within timeout_s.

        feed=False when the caller (the host) folds every received line into the model itself.
        """
        self.link = link
        self.model = model
        self.feed = feed
        self.timeout_s = timeout_s
        self.heard_grbl = False
        self.answered = 0
        self.foreign: list[bytes] = []
        self._foreign_run = 0
        #: The state of the last status report read.
        self.last_state: str | None = None
        self.busy_wait_s = BUSY_WAIT_S
        # When asking busy-refused queries again stops (None: none was refused yet).
        self._busy_until_s: float | None = None

    async def settle(self, quiet_s: float = SETTLE_S) -> list[Response]:
        """Take in the lines already waiting (e.g. a banner) until quiet_s passes without any."""
        seen: list[Response] = []
        while True:
            try:
                raw = await asyncio.wait_for(self.link.read_line(), quiet_s)
            except TimeoutError:
                return seen
            seen.append(self._take(raw))

    async def ask(self, query: Query) -> QueryResult:
        """Send one query and wait for its genuine ok/error; ControllerResetError on a banner."""
        await self.link.send_line(query.line)
        return await self._collect(query.line, query.expects)

    async def ask_when_idle(self, query: Query) -> QueryResult:
        """ask(), asked again while the controller refuses it with error:8 (busy) and comes to
        rest (Idle or Alarm) within the handshake's busy budget."""
        result = await self.ask(query)
        while _busy_refusal(result.reply) and await self._wait_for_rest():
            result = await self.ask(query)
        return result

    async def _wait_for_rest(self) -> bool:
        """Ask `?` until a report shows Idle or Alarm (True) or the busy budget is spent."""
        loop = asyncio.get_running_loop()
        if self._busy_until_s is None:
            self._busy_until_s = loop.time() + self.busy_wait_s
        while loop.time() < self._busy_until_s:
            await asyncio.sleep(BUSY_POLL_S)
            status = await self.ask_status(max(self._busy_until_s - loop.time(), 0.0))
            if status is not None and status.state in SUSPENDED_STATES:
                raise self._suspended(status)
            if status is not None and status.state in ANSWERING_STATES:
                return True
        return False

    async def ask_status(self, timeout_s: float | None = None) -> StatusReport | None:
        """Send `?` and wait for the status report; None when none comes in time."""
        self.link.send_realtime(STATUS_QUERY)
        loop = asyncio.get_running_loop()
        deadline_s = loop.time() + (self.timeout_s if timeout_s is None else timeout_s)
        while True:
            response = await self._next(deadline_s)
            if response is None:
                return None
            if isinstance(response, Banner):
                raise ControllerResetError(response, self.link.describe())
            if isinstance(response, StatusReport):
                return response

    async def _collect(self, line: str, expects: tuple[type[Response], ...]) -> QueryResult:
        """Read until the reply that ends this query."""
        loop = asyncio.get_running_loop()
        deadline_s = loop.time() + self.timeout_s
        # A query still unanswered after STATUS_CHECK_S asks `?` once: a controller someone
        # put in a feed hold (a `!` just after a reset) answers that and reads no line, and the
        # user hears it now rather than at the end of the timeout.
        check_s: float | None = loop.time() + min(STATUS_CHECK_S, self.timeout_s)
        responses: list[Response] = []
        content = False
        stale_ok = False
        while True:
            response = await self._next(deadline_s if check_s is None else check_s)
            if response is None and check_s is not None and loop.time() < deadline_s:
                check_s = None
                self.link.send_realtime(STATUS_QUERY)
                continue
            if (
                isinstance(response, StatusReport)
                and check_s is None
                and response.state in SUSPENDED_STATES
            ):
                raise self._suspended(response)
            if response is None:
                if stale_ok:
                    # Only bare oks came: a firmware that answers this query with nothing.
                    return QueryResult(line, Ok(), responses)
                raise await self._no_answer_why(line)
            if isinstance(response, Banner):
                raise ControllerResetError(response, self.link.describe())
            if isinstance(response, ErrorReply):
                self.answered += 1
                return QueryResult(line, response, responses)
            if isinstance(response, Ok):
                if content or not expects:
                    self.answered += 1
                    return QueryResult(line, response, responses)
                stale_ok = True
                logger.debug("skipped an ok without content while waiting for %s", line)
                continue
            responses.append(response)
            content = content or isinstance(response, expects)

    async def _next(self, deadline_s: float) -> Response | None:
        """The next parsed line, folded into the model; None once the deadline passes."""
        remaining_s = deadline_s - asyncio.get_running_loop().time()
        if remaining_s <= 0:
            return None
        try:
            raw = await asyncio.wait_for(self.link.read_line(), remaining_s)
        except TimeoutError:
            return None
        return self._take(raw)

    def _take(self, raw: bytes) -> Response:
        """Parse a line, fold it into the model, and watch for a peer that is not Grbl."""
        response = parse_response(raw)
        if self.feed:
            self.model.apply(response)
        if isinstance(response, StatusReport):
            self.last_state = response.state
        if isinstance(response, Unparsed):
            self.foreign.append(raw)
            self._foreign_run += 1
            if self._foreign_run >= FOREIGN_LINES_LIMIT:
                raise self._not_grbl()
        elif not isinstance(response, Empty):
            self.heard_grbl = True
            self._foreign_run = 0
        return response

    async def _no_answer_why(self, line: str) -> ConnectError:
        """The error for a query that got no reply: a status report may say why."""
        try:
            status = await asyncio.wait_for(self.ask_status(), min(STATUS_CHECK_S, self.timeout_s))
        except (TimeoutError, ControllerResetError):
            status = None
        if status is not None and status.state in SUSPENDED_STATES:
            return self._suspended(status)
        return self._no_answer(line)

    def _suspended(self, status: StatusReport) -> ControllerSuspendedError:
        """The error for a controller in a state where it reads no line."""
        # A feed hold (someone's `!` or a hold button), an open door or sleep: Grbl's main loop
        # reads no line until it is resumed (firmware-facts §3.2, §3.3).
        shown = status.state if status.substate is None else f"{status.state}:{status.substate}"
        return ControllerSuspendedError(
            f"{self.link.describe()} reports {shown} and reads no line in that state:"
            " resume it (cycle start, ~) or reset it, then connect again",
            shown,
        )

    def _no_answer(self, line: str) -> ConnectError:
        """The error for a query that got no reply in time."""
        where = self.link.describe()
        if self.foreign and not self.heard_grbl:
            return self._not_grbl()
        if self.heard_grbl:
            return ConnectError(
                f"{where} did not answer {line!r} within {self.timeout_s} s: the controller may"
                " be busy or in a critical alarm; reset it and try again"
            )
        baud_hint = ", and is the baud rate right" if "baud" in where else ""
        return ConnectError(
            f"no answer from {where} within {self.timeout_s} s: is it a Grbl controller{baud_hint}?"
        )

    def _not_grbl(self) -> ConnectError:
        """The error for a peer whose lines are not Grbl's."""
        where = self.link.describe()
        sample = self.foreign[-1][:40]
        baud_hint = " or the baud rate is wrong" if "baud" in where else ""
        return ConnectError(
            f"{where} answers, but not like a Grbl controller (it sent {sample!r}): this is the"
            f" wrong device{baud_hint}"
        )


def _busy_refusal(reply: Ok | ErrorReply) -> bool:
    """True for error:8: the controller refused the query because it was not at rest."""
    return isinstance(reply, ErrorReply) and reply.code == ERR_IDLE_ERROR


async def handshake(
    link: QueryLink,
    *,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    model: MachineModel | None = None,
    feed: bool = True,
) -> MachineModel:
    """Ask the controller who and where it is; return the model built from its answers.

    feed=False leaves folding the received lines into the model to the caller (the host).
    """
    result = await read_controller(link, timeout_s=timeout_s, model=model, feed=feed)
    return result.model


async def read_controller(
    link: QueryLink,
    *,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    model: MachineModel | None = None,
    feed: bool = True,
    busy_wait_s: float = BUSY_WAIT_S,
) -> HandshakeResult:
    """handshake(), also saying which queries the controller refused to the end.

    busy_wait_s bounds, in all, the asking again of queries refused because it was busy.
    """
    target = model if model is not None else MachineModel()
    querier = Querier(link, target, timeout_s=timeout_s, feed=feed)
    querier.busy_wait_s = busy_wait_s
    await querier.settle()
    resets = resets_after_answers = 0
    while True:
        try:
            unread = await _run_queries(querier)
        except ControllerResetError:
            # A banner before any answer is most likely the boot after opening the port (it came
            # later than open() waited), a banner after answers is a reset: the handshake
            # survives one of each, and a controller that keeps resetting is an error.
            resets += 1
            resets_after_answers += querier.answered > 0
            if resets > MAX_RESETS or resets_after_answers > 1:
                raise
            querier.answered = 0
            logger.info("controller reset during the handshake; starting over")
            continue
        return HandshakeResult(target, unread)


async def _run_queries(querier: Querier) -> list[Unread]:
    """All queries in order, then the status report; the queries that stayed unread."""
    unread: list[Unread] = []
    for query in QUERIES:
        result = await querier.ask_when_idle(query)
        if isinstance(result.reply, ErrorReply):
            # Refused to the end (a controller busy for longer than the budget): the model keeps
            # what it had for this query (firmware-facts §1.2, §5.3).
            logger.info("%s answered %s", query.line, describe_error(result.reply.code))
            unread.append(Unread(query.line, result.reply.code, querier.last_state))
    status = await querier.ask_status()
    if status is None:
        # Grbl makes no report while homing or after a limit alarm (firmware-facts §5.2): go on
        # without.
        logger.info("no status report within %s s", querier.timeout_s)
    return unread


# --- the readable summary -------------------------------------------------------------------

#: What each state means to someone at the machine (firmware-facts §5.4).
STATE_MEANINGS: dict[str, str] = {
    "Idle": "ready",
    "Run": "running a program",
    "Hold": "feed hold: send ~ to resume",
    "Jog": "jogging",
    "Home": "homing",
    "Alarm": "locked: nothing moves until you home ($H) or unlock ($X)",
    "Door": "safety door open",
    "Check": "check mode: G-code is parsed, nothing moves",
    "Sleep": "sleeping: reset to wake",
    "Tool": "waiting for a tool change",
}


def _fmt_number(value: float) -> str:
    """A number without a pointless fraction."""
    return f"{value:.0f}" if value == int(value) else f"{value:g}"


def _fmt_position(letters: tuple[str, ...], values_mm: tuple[float, ...] | None) -> str:
    """`X 1.000  Y 2.000 ...` in mm, or a note that it is unknown."""
    if values_mm is None:
        return "unknown (no status report with it yet)"
    named = zip(letters + ALL_AXES[len(letters) :], values_mm, strict=False)
    return "  ".join(f"{letter} {value:.3f}" for letter, value in named) + " mm"


def _state_line(model: MachineModel) -> str:
    """The state and, for Alarm, why and what to do."""
    if model.state is None:
        return "unknown (the controller sent no status report)"
    state = model.state if model.substate is None else f"{model.state}:{model.substate}"
    text = f"{state}: {STATE_MEANINGS.get(model.state, 'a state smoothjog does not know')}"
    if model.state == "Alarm" and model.last_alarm is not None:
        text += f"\n{'':14}{describe_alarm(model.last_alarm)}"
    return text


def format_summary(model: MachineModel) -> str:
    """One readable block describing the controller and the machine behind it."""
    settings = model.settings.for_axes(model.n_axes)
    letters = model.axis_letters
    version = model.version or "unknown version"
    build = f", build {model.build}" if model.build else ""
    options = f", options {model.option_codes}" if model.option_codes else ""
    lines = [
        f"{'Controller':14}{model.firmware} {version}{build}{options}",
        f"{'Planner':14}{model.planner_blocks} blocks, RX buffer {model.rx_buffer_bytes} bytes",
        f"{'Axis':14}{'max rate':>14}{'acceleration':>16}{'travel':>12}",
    ]
    for letter, rate, accel, travel in zip(
        letters,
        settings.max_rate_mm_min,
        settings.accel_mm_s2,
        settings.max_travel_mm,
        strict=False,
    ):
        lines.append(
            f"{'  ' + letter:14}{_fmt_number(rate) + ' mm/min':>14}"
            f"{_fmt_number(accel) + ' mm/s²':>16}{_fmt_number(travel) + ' mm':>12}"
        )
    envelope = model.soft_limit_envelope()
    soft = "off"
    if envelope is not None:
        spans = ", ".join(
            f"{letter} {_fmt_number(lo)}..{_fmt_number(hi)}"
            for letter, lo, hi in zip(letters, envelope.min_mm, envelope.max_mm, strict=False)
        )
        soft = f"on ({spans} mm, machine coordinates)"
    lines.append(f"{'Soft limits':14}{soft}")
    lines.append(
        f"{'Homing':14}{'on' if settings.homing else 'off'}"
        f"; hard limits {'on' if settings.hard_limits else 'off'}"
    )
    frame = "MPos" if settings.status_mask & 1 else "WPos"
    units = "inches ($13=1), shown here in mm" if settings.report_inches else "mm"
    lines.append(f"{'Reports':14}{frame}, {units}")
    lines.append(f"{'State':14}{_state_line(model)}")
    lines.append(f"{'MPos':14}{_fmt_position(letters, model.mpos_mm)}")
    lines.append(f"{'WPos':14}{_fmt_position(letters, model.wpos_mm)}")
    return "\n".join(lines)

"""The one host driver: a link, the line ledger, the machine model, and every owner on the wire.

Everything smoothjog says to a controller goes through one `Host`, in real time or (with the loop
of vclock.py) in virtual time against the simulator; there is no second driver. Three things run
on the event loop:

- the reader: every received line is parsed once, folded into the machine model once, and then
  routed: an `ok`/`error` goes to the owner of the oldest unanswered line (the ledger decides),
  and so does the output of a query (`[GC:...]`, `$N=...`, `[VER:]`, ...), which Grbl prints
  just before that line's `ok`; status reports, `ALARM`, `[MSG:]` and banners go to everyone.
  It runs inside the link's read callback (a task only for a link that cannot call back);
- the ticker: polls the jog engine when something it can see happened (a line arrived, a new
  intent, its own deadline) and writes what it returns. It is a plain callback scheduled with
  call_soon / call_at, not a task: a held jog wakes it about a hundred times a second;
- a re-handshake task when a banner says the controller reset mid-session.

Owners other than the engine (the handshake, a user's console, a foreign sender) write through
`write_line`, which waits for room in the controller's RX buffer; the engine checks the room
itself (it sizes what it sends by it) and records its lines in the ledger as it makes them.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Protocol

from smoothjog.core.codes import alarm_info, error_info
from smoothjog.core.engine import (
    EngineEvent,
    EngineLimits,
    EngineView,
    Jogger,
    JogTuning,
    Output,
    SendLine,
    SendRealtime,
)
from smoothjog.core.errors import ConnectError, LinkError, SmoothjogError
from smoothjog.core.firmware import firmware_facts
from smoothjog.core.intents import ContinuousIntent, Intent, StopIntent
from smoothjog.core.ledger import CONSOLE, ENGINE, HANDSHAKE, Entry, Ledger, foreign
from smoothjog.core.machine import KeepOut, MachineModel
from smoothjog.core.realtime import CYCLE_START, JOG_CANCEL, RESET, STATUS_QUERY
from smoothjog.core.responses import (
    AlarmReply,
    Banner,
    BuildOptions,
    ErrorReply,
    Feedback,
    GcodeModes,
    HelpReply,
    NamedSetting,
    Ok,
    Parameter,
    Response,
    SettingLine,
    StartupLineResult,
    StatusReport,
    VersionInfo,
    parse_response,
)
from smoothjog.core.states import REST_STATES, SUSPENDED_STATES, is_homing
from smoothjog.handshake import (
    ControllerSuspendedError,
    HandshakeResult,
    read_controller,
)
from smoothjog.links.base import Link, encode_line

logger = logging.getLogger(__name__)

#: While a controller that restarted is held (Hold, Door, Sleep), how often to ask whether
#: someone resumed it.
RESUME_POLL_S = 0.25

#: Longest the re-handshake waits for the engine to see a restarted controller at rest (it
#: then reads the settings anyway, and the engine's owed cancel follows them as before).
RESTART_SETTLE_S = 2.0


class JogEngine(Protocol):
    """What the host drives: smoothjog's Jogger, or a reference method in bench/."""

    def set_intent(self, intent: Intent, now_s: float) -> None:
        """Take the newest intent (raises JogBuildError for an invalid one)."""

    def on_reply(self, entry: Entry, resp: Ok | ErrorReply, now_s: float) -> bool:
        """The reply to one of the engine's own lines; True to be polled at once."""

    def on_response(self, resp: Response, now_s: float) -> bool:
        """Any other line from the controller (already in the model); True to be polled now."""

    def poll(self, now_s: float) -> list[Output]:
        """What to send now; lines are already recorded in the ledger."""

    def next_deadline_s(self, now_s: float) -> float:
        """The latest time to be polled again."""

    def busy(self) -> bool:
        """True while the engine still has work in hand."""

    def reset_outputs(self) -> list[Output]:
        """What to send the moment a banner arrives, before the re-handshake's first line."""

    def restart_outputs(self, now_s: float) -> list[Output]:
        """Realtime bytes to send while a restarted controller's settings wait to be read."""

    def restart_settled(self) -> bool:
        """True once nothing sent before a reset can still start the machine."""

    def restart_wire_clear(self, now_s: float) -> None:
        """Every line written before the reset has now left the host."""

    def reset_machine(self, limits: EngineLimits) -> None:
        """Start over after a re-handshake (the controller was reset)."""


#: Builds the engine once the handshake has filled the model.
EngineFactory = Callable[[MachineModel, Ledger], JogEngine]

#: Called with every received line after it was routed: (response, time).
LineListener = Callable[[Response, float], None]

#: Called with every received line and where it was routed: (raw line, response, entry). For a
#: reply the entry is the line it answers (None: no line waited for it); for query output the
#: line whose query printed it; None for a line that goes to everyone. (Query output that came
#: with no line waiting is nobody's and is not given to these listeners.)
RoutedListener = Callable[[bytes, Response, Entry | None], None]

#: What a query prints before its `ok`: it belongs to the owner of the oldest unanswered line
#: (`$G`, `$#` and `[PRB:]`, `$$`, `$N`, `$I`, `$`, `[echo:]`, `$H`'s startup lines).
OWNED_OUTPUT = (
    GcodeModes,
    Parameter,
    SettingLine,
    NamedSetting,
    VersionInfo,
    BuildOptions,
    Feedback,
    HelpReply,
    StartupLineResult,
)

#: The jog-lock source of a relay's reports (a CNCjs job), see Host.set_jog_lock.
RELAY_LOCK = "relay"

#: Longest a Ctrl-X counts as pending without the banner that ends it (Host.reset_pending).
RESET_PENDING_S = 2.0

#: The jog-lock source of settings that could not be read (Host.set_jog_lock).
SETTINGS_LOCK = "settings"


class ResetNeededError(ConnectError):
    """The controller raised a critical alarm and reads no line until it is reset."""

    def __init__(self, code: int, text: str, *, sent: bool = True) -> None:
        """The error for console line text, left unanswered by ALARM:code (sent=False: held
        back, since it would never be answered)."""
        info = alarm_info(code)
        what = "got no reply" if sent else "was not sent"
        super().__init__(
            f"{text!r} {what}: the controller raised ALARM:{code} ({info.name.lower()}:"
            f" {info.meaning}) and answers no line until it is reset: press Reset (Ctrl-X)"
        )
        self.code = code


class _QueryPort:
    """What the handshake talks to: lines out through the ledger, lines in as the host routes.

    It has the shape of a Link (send_line, send_realtime, read_line, describe), so the one
    handshake serves a bare link (smoothjog info, tests) and the host alike.
    """

    def __init__(self, host: Host) -> None:
        self.host = host
        #: Lines routed to the handshake; None marks the end of the link.
        self.queue: asyncio.Queue[bytes | None] = asyncio.Queue()

    def describe(self) -> str:
        return self.host.link.describe()

    async def send_line(self, text: str) -> None:
        await self.host.write_line(HANDSHAKE, text)

    def send_realtime(self, byte: bytes) -> None:
        self.host.send_realtime(HANDSHAKE, byte)

    async def read_line(self) -> bytes:
        raw = await self.queue.get()
        if raw is None:
            raise self.host.link_error or LinkError(f"{self.describe()} is closed")
        return raw


class Host:
    """One controller connection: its link, ledger and model, and the owners writing to it."""

    def __init__(
        self,
        link: Link,
        *,
        tuning: JogTuning | None = None,
        keepouts: Sequence[KeepOut] = (),
        handshake_timeout_s: float = 5.0,
        on_event: Callable[[EngineEvent], None] | None = None,
        engine_factory: EngineFactory | None = None,
    ) -> None:
        """Prepare a host over an opened link; call start() next."""
        self.link = link
        self.tuning = tuning or JogTuning()
        if self.tuning.byte_s is None and link.byte_time_s() is not None:
            # The engine sizes its blocks, polls and report ages by the wire it really has.
            self.tuning = dataclasses.replace(self.tuning, byte_s=link.byte_time_s())
        idle_s = link.idle_poll_s()
        if idle_s is not None and idle_s > self.tuning.poll_idle_s:
            self.tuning = dataclasses.replace(self.tuning, poll_idle_s=idle_s)
        self.keepouts = tuple(keepouts)
        self.handshake_timeout_s = handshake_timeout_s
        self.on_event = on_event
        self.engine_factory = engine_factory
        self.model = MachineModel()
        self.ledger = Ledger()
        #: The engine the host drives (None before start() or for a host without one).
        self.driver: JogEngine | None = None
        self.link_error: LinkError | None = None
        #: An unexpected failure inside the host (it stopped driving the machine).
        self.error: BaseException | None = None
        #: Set by abandon(): smoothjog is gone as if its process died; the controller runs on.
        self.abandoned = False
        self._loop: asyncio.AbstractEventLoop | None = None
        # The ticker: _tick runs from the loop (call_soon on a poke, call_at at the engine's
        # deadline), not as a task waiting on an event, which costs two loop passes a wake-up.
        self._ticking = False
        self._tick_soon = False
        self._tick_owed = False  # a writer held the lock: tick when it lets go
        self._deferred = False  # engine lines wait for the link in a writer task
        self._timer: asyncio.TimerHandle | None = None
        self._reading = False
        self._room: asyncio.Event | None = None
        self._lost: asyncio.Event | None = None
        self._write_lock: asyncio.Lock | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._rehandshake_task: asyncio.Task[None] | None = None
        #: Set at every received line while the re-handshake waits on the engine (_settle_restart).
        self._line_heard: asyncio.Event | None = None
        self._port: _QueryPort | None = None
        self._listeners: list[LineListener] = []
        self._routed_listeners: list[RoutedListener] = []
        #: A banner came and no reply yet: startup lines run now, on nobody's query.
        self._after_banner = False
        #: Why jogging waits, by who said so; model.jog_lock shows the first.
        self._jog_locks: dict[str, str] = {}
        #: When somebody sent Ctrl-X, until the banner says the controller restarted.
        self._reset_sent_s: float | None = None
        #: Who sent that Ctrl-X (a ledger owner: the console for the user, a proxied sender).
        self._reset_by: str | None = None
        #: Whose Ctrl-X the last banner answered (None: nobody's here, an outside reset).
        self.last_reset_by: str | None = None
        #: The unanswered `$H` line, whoever sent it (the model shows Home until its reply).
        self._homing_entry: Entry | None = None
        self._reply_handlers: dict[str, Callable[[Entry, Ok | ErrorReply, float], None]] = {
            CONSOLE: _resolve_console_reply,
        }

    # ----------------------------------------------------------------- lifecycle
    async def start(self, *, jog: bool = True) -> MachineModel:
        """Start reading, run the connect handshake, then (jog=True) start driving the engine."""
        self._loop = asyncio.get_running_loop()
        self._room = asyncio.Event()
        self._lost = asyncio.Event()
        self._write_lock = asyncio.Lock()
        self._reading = True
        if self.link.attach_relay(self._on_wire_line, self._on_jog_lock, self._on_relay_moved):
            self.ledger.relayed = True
        # Lines come straight from the link's read callback where it can give them (one task
        # switch fewer per line); a reader task otherwise.
        if not self.link.subscribe(self._on_link_line, self._on_link_end):
            self._tasks.append(asyncio.create_task(self._reader(), name="smoothjog-reader"))
        try:
            await self._handshake()
            if jog:
                self.model.set_keep_outs(self.keepouts)  # refuses a zone in words
                self.driver = self._make_engine()
        except BaseException:
            await self._cancel_tasks()
            raise
        if jog:
            self._ticking = True
            self._poke()
        return self.model

    def _make_engine(self) -> JogEngine:
        if self.engine_factory is not None:
            return self.engine_factory(self.model, self.ledger)
        return Jogger(self.model, EngineLimits.from_model(self.model), self.tuning, self.ledger)

    async def close(self, *, stop_timeout_s: float = 2.0) -> None:
        """Stop any jog with the full handshake (bounded in time), then close the link."""
        if self.driver is not None and self.link_error is None and not self.abandoned:
            with contextlib.suppress(SmoothjogError, ValueError):
                self.set_intent(StopIntent())
            with contextlib.suppress(TimeoutError, LinkError):
                await self.wait_idle(stop_timeout_s)
        await self._cancel_tasks()
        await self.link.close()

    def abandon(self) -> None:
        """Stop reading and writing at once, sending nothing (a client that dies mid-jog)."""
        self.abandoned = True
        self._stop_driving()
        for task in self._all_tasks():
            task.cancel()

    def _stop_driving(self) -> None:
        """No more ticks and no more lines read (the tasks are cancelled by the caller)."""
        self._ticking = False
        self._reading = False
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self.link.unsubscribe()

    def _all_tasks(self) -> list[asyncio.Task[None]]:
        extra = [self._rehandshake_task] if self._rehandshake_task is not None else []
        return self._tasks + extra

    async def _cancel_tasks(self) -> None:
        self._stop_driving()
        tasks = self._all_tasks()
        for task in tasks:
            task.cancel()
        # A task that died earlier has its error stored in self.error already.
        await asyncio.gather(*tasks, return_exceptions=True)
        self._tasks = []
        self._rehandshake_task = None

    # ----------------------------------------------------------------- inputs
    def set_intent(self, intent: Intent) -> None:
        """Hand the engine the newest intent; raises JogBuildError for an invalid one."""
        self._engine().set_intent(intent, self.now_s())
        self._poke()

    def jog(self, axes: Mapping[str, float], speed: float) -> None:
        """Shorthand for a continuous intent."""
        self.set_intent(ContinuousIntent(dict(axes), speed))

    def set_speed_ratios(self, ratios: Mapping[str, float]) -> None:
        """Per-axis speed ratios in (0, 1]."""
        self._jogger().set_speed_ratios(ratios)

    # ----------------------------------------------------------------- other owners
    async def write_line(self, owner: str, text: str, *, tag: object = None) -> Entry:
        """Send a line for owner once the controller's RX buffer has room; return its entry.

        A line the link would refuse raises RefusedError before anything is recorded, so the
        ledger never counts bytes that were not sent.
        """
        assert self._room is not None
        assert self._write_lock is not None
        encode_line(text)
        while True:
            if self.link_error is not None:
                raise self.link_error
            if self.ledger.fits(text):
                break
            self._room.clear()
            await self._room.wait()
        async with self._write_lock:
            entry = self.ledger.record_line(owner, text, self.now_s(), tag)
            self._note_homing(entry)
            await self.link.send_line(text)
        self._after_writer()
        return entry

    def _after_writer(self) -> None:
        """A writer let go of the lock: run the tick that waited for it."""
        if self._tick_owed:
            self._tick_owed = False
            self._poke()

    def send_realtime(self, owner: str, byte: bytes) -> None:
        """Send a realtime byte for owner, ahead of any line the link still holds."""
        self.ledger.record_realtime(owner, byte)
        self.link.send_realtime(byte)
        if byte == RESET and self._loop is not None:
            self._reset_sent_s = self._loop.time()
            self._reset_by = owner

    def _reset_announced_by(self, now_s: float) -> str | None:
        """Whose Ctrl-X (within RESET_PENDING_S) a banner now answers, or None: a reset nobody
        on this host asked for (a reset pin, another program's port, a crash)."""
        sent_s, by = self._reset_sent_s, self._reset_by
        self._reset_by = None
        if sent_s is None or now_s - sent_s > RESET_PENDING_S:
            return None
        return by

    @property
    def reset_needed(self) -> bool:
        """True from a critical alarm (ALARM:1 or 2 on Grbl 1.1h) until the next banner: the
        controller reads no line until it is reset (firmware-facts §5.6a)."""
        return self.model.reset_needed

    @property
    def reset_pending(self) -> bool:
        """True from a Ctrl-X until the banner (at most RESET_PENDING_S): a line written now
        would reach the controller while it restarts, and run after it (no reply is owed to
        the ledger's lines meanwhile: the banner forgets them)."""
        sent_s = self._reset_sent_s
        if sent_s is None or self._loop is None:
            return False
        if self._loop.time() - sent_s > RESET_PENDING_S:
            self._reset_sent_s = None  # no banner came: the controller did not restart
            return False
        return True

    async def query(self, text: str, *, timeout_s: float = 5.0) -> list[Response]:
        """Send a console line; return what the controller printed up to and with its reply.

        That is the line's own output and what went to everyone meanwhile (status reports,
        `[MSG:]`), never another owner's query output.
        """
        printed, reply = await self._ask(text, timeout_s)
        return [*(resp for _raw, resp in printed), reply]

    async def console(
        self, text: str, *, timeout_s: float = 5.0
    ) -> tuple[list[str], Ok | ErrorReply]:
        """Send a console line; return the lines printed up to its reply (as text) and the reply.

        Status reports and the reply itself are left out of the lines; they are what `query`
        returns parsed.
        """
        printed, reply = await self._ask(text, timeout_s)
        lines = [
            raw.decode("ascii", "replace").rstrip("\r\n")
            for raw, resp in printed
            if not isinstance(resp, StatusReport)
        ]
        return lines, reply

    async def _ask(
        self, text: str, timeout_s: float
    ) -> tuple[list[tuple[bytes, Response]], Ok | ErrorReply]:
        """Send a console line; (what it printed or everyone got, in order; its reply)."""
        loop = self._running_loop()
        alarm = self.model.critical_alarm
        if alarm is not None:
            raise ResetNeededError(alarm, text, sent=False)  # no reply would ever come
        done: asyncio.Future[Ok | ErrorReply] = loop.create_future()
        seen: list[tuple[bytes, Response]] = []

        def collect(raw: bytes, resp: Response, route: Entry | None) -> None:
            if done.done() or isinstance(resp, Ok | ErrorReply):
                return
            if route is not None and route.tag is not done:
                return  # another owner's query printed it
            seen.append((raw, resp))

        self._routed_listeners.append(collect)
        try:
            await self.write_line(CONSOLE, text, tag=done)
            async with asyncio.timeout(timeout_s):
                reply = await done
        except TimeoutError:
            raise ConnectError(
                f"{self.link.describe()} did not answer {text!r} within {timeout_s} s"
            ) from None
        finally:
            self._routed_listeners.remove(collect)
        return seen, reply

    async def reread_settings(self, *, timeout_s: float = 5.0) -> None:
        """Read `$$` again and give the engine the limits it now implies (only while idle)."""
        printed = await self.query("$$", timeout_s=timeout_s)
        if isinstance(printed[-1], Ok) and any(isinstance(r, SettingLine) for r in printed):
            self.set_jog_lock(SETTINGS_LOCK, None)  # read at last
        driver = self.driver
        if driver is not None and not driver.busy():
            driver.reset_machine(EngineLimits.from_model(self.model, self.keepouts))
            self._poke()

    @property
    def rehandshaking(self) -> bool:
        """True while the settings are read again after a mid-session reset."""
        return self._rehandshake_task is not None

    def add_reply_handler(
        self, owner: str, handler: Callable[[Entry, Ok | ErrorReply, float], None]
    ) -> None:
        """Give owner's replies to handler (a foreign sender's forwarder, say)."""
        self._reply_handlers[owner] = handler

    def add_line_listener(self, listener: LineListener) -> None:
        """Call listener(response, now_s) after every received line."""
        self._listeners.append(listener)

    def add_routed_listener(self, listener: RoutedListener) -> None:
        """Call listener(raw, response, entry) for every received line, with its route.

        entry is the ledger line the line belongs to: for an `ok`/`error` the line it answers,
        for query output the line whose query printed it (its owner asked for it); None for a
        line that goes to everyone (status reports, ALARM, [MSG:], banners, anything unparsed).
        Query output that came with no line waiting (the ledger lost its place) is nobody's
        and is not given. A forwarder gives each owner what is its own and everyone's.
        """
        self._routed_listeners.append(listener)

    def set_jog_lock(self, source: str, reason: str | None) -> None:
        """Say why jogging must wait (reason in words), or that it may go on (None), for source.

        Several sources may hold the machine at once (a relay's CNCjs job, a proxied sender's
        job); `model.jog_lock` shows the oldest reason still standing, and the engine refuses
        jogs with it and stops a running jog with its full handshake.
        """
        before = next(iter(self._jog_locks.values()), None)
        if reason is None:
            self._jog_locks.pop(source, None)
        else:
            self._jog_locks[source] = reason
        combined = next(iter(self._jog_locks.values()), None)
        if combined != before:
            logger.info("jogging %s", f"waits: {combined}" if combined else "may go on again")
        self.model.jog_lock = combined
        self._poke()

    def add_listener(self, callback: Callable[[], None]) -> None:
        """Call callback (no arguments) after every received line: the pendant's change signal."""
        self._listeners.append(lambda _resp, _now: callback())

    # ----------------------------------------------------------------- observation
    @property
    def engine(self) -> Jogger | None:
        """smoothjog's own engine, when that is what the host drives."""
        return self.driver if isinstance(self.driver, Jogger) else None

    def now_s(self) -> float:
        """The host's clock (the event loop's)."""
        return self._running_loop().time()

    def view(self) -> EngineView:
        """The engine's snapshot now."""
        return self._jogger().view(self.now_s())

    def busy(self) -> bool:
        """True while the engine has anything queued, streaming or stopping."""
        return self._engine().busy()

    def at_rest(self) -> bool:
        """True when the engine has nothing in hand and the controller reports rest."""
        return not self.busy() and self.model.state in REST_STATES

    async def wait_idle(self, timeout_s: float) -> None:
        """Wait until the engine is idle and the controller at rest; TimeoutError if not."""
        async with asyncio.timeout(timeout_s):
            while True:
                if self.link_error is not None:
                    raise self.link_error  # a controller that is gone is not idle
                if self.at_rest():
                    return
                await asyncio.sleep(0.01)

    # ----------------------------------------------------------------- internals
    def _running_loop(self) -> asyncio.AbstractEventLoop:
        if self._loop is None:
            raise RuntimeError("Host.start() has not run")
        return self._loop

    def _engine(self) -> JogEngine:
        if self.driver is None:
            raise RuntimeError("Host.start() has not run (or was started without jogging)")
        return self.driver

    def _jogger(self) -> Jogger:
        engine = self.engine
        if engine is None:
            raise RuntimeError("this host drives no smoothjog engine")
        return engine

    def _poke(self) -> None:
        """Tick as soon as the loop is free (once, however many pokes come meanwhile)."""
        if self._ticking and not self._tick_soon and self._loop is not None:
            self._tick_soon = True
            self._loop.call_soon(self._tick)

    async def _handshake(self) -> None:
        """Read the controller into the model (at the start, or again after a reset)."""
        port = _QueryPort(self)
        self._port = port
        try:
            result = await read_controller(
                port, timeout_s=self.handshake_timeout_s, model=self.model, feed=False
            )
        finally:
            self._port = None
        # A relay's own unseen lines (CNCjs's `$G` poll) take RX bytes smoothjog cannot count.
        self.ledger.capacity_bytes = self.model.rx_buffer_bytes - self.link.rx_reserve_bytes()
        again = self.rehandshaking
        self.set_jog_lock(SETTINGS_LOCK, _settings_unread_reason(result, again=again))

    async def _reader(self) -> None:
        """For a link that cannot deliver lines by callback."""
        with self._stops_the_host():
            while True:
                raw = await self.link.read_line()
                self._on_line(raw, self.now_s())

    def _on_link_line(self, raw: bytes) -> None:
        """A line from the link's read callback."""
        if self._reading:
            # What _stops_the_host does, written out: this runs for every line received, and a
            # generator-based context manager costs more than the rest of the call around it.
            try:
                self._on_line(raw, self.now_s())
            except Exception as exc:
                self._stopped_by(exc)

    def _on_wire_line(self, text: str, writer: str) -> None:
        """A relay put a line on the wire: confirm an own one or count a foreign writer's."""
        if self._reading:
            self._note_homing(self.ledger.on_echo(text, foreign(writer), self.now_s()))

    def _note_homing(self, entry: Entry) -> None:
        """A `$H` line (anyone's) is on its way: the model shows Home until its reply."""
        if entry.owner != ENGINE and is_homing(entry.text):
            self._homing_entry = entry
            self.model.homing_sent()
            self._poke()  # the engine polls `?` at the moving rate from now on

    def _homing_reply(self, entry: Entry | None, resp: Ok | ErrorReply) -> None:
        """A reply came while a `$H` waits: end the Home shown at its own (or once it is gone)."""
        homing = self._homing_entry
        if homing is None:
            return
        if entry is not homing and any(e is homing for e in self.ledger.outstanding()):
            return
        self._homing_entry = None
        self.model.homing_answered(entry is homing and isinstance(resp, Ok))
        engine = self.engine
        if engine is not None:
            engine.ask_status()  # the state after the cycle, at once

    def _on_alarm(self, alarm: AlarmReply) -> None:
        """An ALARM:N arrived (already in the model): console lines that it leaves unanswered
        until a reset fail now, in words, rather than at their timeout."""
        if not self.model.reset_needed:
            return  # the controller goes on reading lines: their replies come
        _fail_console_entries(
            self.ledger.outstanding(CONSOLE), lambda entry: ResetNeededError(alarm.code, entry.text)
        )

    def _on_relay_moved(self) -> None:
        """The relay saw the controller change (another client moved it): ask for a report."""
        engine = self.engine
        if engine is not None and self._reading:
            engine.ask_status()
            self._poke()

    def _on_jog_lock(self, reason: str | None) -> None:
        """Another program took or gave back the machine (a CNCjs job began or ended)."""
        self.set_jog_lock(RELAY_LOCK, reason)

    def _on_link_end(self, error: LinkError) -> None:
        """The link is gone (or was closed under the host)."""
        if self._reading and self.link_error is None:
            self.link_error = error
            logger.error("%s", error)
            self._ended()

    @contextlib.contextmanager
    def _stops_the_host(self) -> Iterator[None]:
        """Around a task's body: a lost link or a bug ends the host in words, never silently."""
        try:
            yield
        except Exception as exc:
            self._stopped_by(exc)

    def _stopped_by(self, exc: Exception) -> None:
        """What a lost link (LinkError) or a bug (anything else) raised ends the host in words."""
        if isinstance(exc, LinkError):
            self.link_error = exc
            logger.error("%s", exc)
            self._ended()
        else:  # a bug must stop the machine, not vanish quietly
            self._fail(exc)

    def _on_line(self, raw: bytes, now_s: float) -> None:
        """Parse, fold into the model, route by owner, fan out; wake the ticker."""
        resp = parse_response(raw)
        self.model.apply(resp)
        poke = True
        port = self._port
        driver = self.driver
        route: Entry | None = None
        orphan = False
        if isinstance(resp, Ok | ErrorReply):
            entry = route = self.ledger.on_reply()
            self._after_banner = False
            if self._homing_entry is not None:
                self._homing_reply(entry, resp)
            assert self._room is not None
            self._room.set()
            if entry is None:
                if port is not None:
                    port.queue.put_nowait(raw)  # the handshake skips stale replies itself
                else:
                    logger.info("a reply arrived with no line waiting for one: %s", raw)
            elif entry.owner == HANDSHAKE:
                if port is not None:
                    port.queue.put_nowait(raw)
            elif entry.owner == ENGINE and driver is not None:
                # The engine says whether the reply needs a poll; other lines always get one.
                poke = driver.on_reply(entry, resp, now_s)
            else:
                handler = self._reply_handlers.get(entry.owner)
                if handler is not None:
                    handler(entry, resp, now_s)
        else:
            if isinstance(resp, OWNED_OUTPUT) and not (
                # Startup lines run at a reset, before any line is read: nobody's query.
                self._after_banner and isinstance(resp, StartupLineResult)
            ):
                route = self.ledger.oldest()
                # With no line waiting the output is nobody's (a reply that came twice, say):
                # the routed listeners, which hand out what is each owner's, do not get it.
                orphan = route is None
            if isinstance(resp, AlarmReply):
                self._on_alarm(resp)
            if isinstance(resp, Banner):
                self._on_banner(now_s)
            if driver is not None and not driver.on_response(resp, now_s):
                poke = False  # a routine report: the engine's own deadline comes soon enough
            if isinstance(resp, Banner) and driver is not None:
                # Written now, ahead of the re-handshake's lines (a cancel for jog lines still
                # on their way to the restarted controller).
                for output in driver.reset_outputs():
                    if isinstance(output, SendRealtime):
                        self.send_realtime(ENGINE, output.byte)
            if port is not None and (route is None or route.owner == HANDSHAKE):
                port.queue.put_nowait(raw)  # not another owner's query output
            if isinstance(resp, Banner) and driver is not None and port is None:
                self._start_rehandshake()
        if self._line_heard is not None:
            self._line_heard.set()
        # Copied (a listener may remove itself) only when there is anyone to call.
        if self._routed_listeners and not orphan:
            for routed in list(self._routed_listeners):
                try:
                    routed(raw, resp, route)
                except Exception:  # a listener's bug must not stop the machine's driver
                    logger.exception("a routed line listener failed")
        if self._listeners:
            for listener in list(self._listeners):
                try:
                    listener(resp, now_s)
                except Exception:  # a listener's bug must not stop the machine's driver
                    logger.exception("a line listener failed")
        self._flush_events()
        if poke:
            self._poke()

    def _on_banner(self, now_s: float) -> None:
        """The controller restarted: its buffers are empty and every line unanswered is lost."""
        self._after_banner = True
        self.last_reset_by = self._reset_announced_by(now_s)
        self._reset_sent_s = None
        self._homing_entry = None
        engine = self.engine
        if engine is not None:
            # Asked for by the user: the engine tells it as news, not as a fault.
            engine.reset_expected = self.last_reset_by == CONSOLE
        dropped = self.ledger.reset()
        if dropped:
            logger.info("the controller reset with %d lines unanswered", len(dropped))
        _fail_console_entries(dropped)
        assert self._room is not None
        self._room.set()

    def _start_rehandshake(self) -> None:
        """The controller reset mid-session: read its settings again before any jog."""

        async def run() -> None:
            told = False
            released = False
            try:
                await self._settle_restart()
                while True:
                    try:
                        await self._handshake()
                        break
                    except ControllerSuspendedError as exc:
                        # Someone held the controller just after it restarted (a hold button,
                        # another program's `!`, a door). It reads no line until resumed, and
                        # resuming is for a person to do, never smoothjog: stay connected, say
                        # so once, and read the settings once it runs again.
                        if not told:
                            told = True
                            self._tell(
                                "fault",
                                f"the controller restarted and is in {exc.state}: it reads no"
                                " line until it is resumed",
                                "resume it (cycle start, ~) or reset it; smoothjog reads its"
                                " settings again then, and jogs after that",
                            )
                        await self._until_resumed()
                    except ConnectError:
                        # A Grbl 1.1h that reports Idle and answers no line may be suspended by
                        # a 0x85 that reached it as a jog ended (firmware-facts §3.8; one sent
                        # for lines that started it after the reset can land there): `~`
                        # releases it and does nothing in a plain Idle. Once; then give up.
                        facts = firmware_facts(self.model.firmware).jog_cancel
                        if released or not facts.late_cancel_suspends or self.model.state != "Idle":
                            raise
                        released = True
                        logger.info("the restarted controller answers no line: sending ~")
                        self.send_realtime(HANDSHAKE, CYCLE_START)
                self._engine().reset_machine(EngineLimits.from_model(self.model, self.keepouts))
            except SmoothjogError as exc:  # e.g. a controller that keeps resetting
                self._fail(exc)
            finally:
                if self._rehandshake_task is asyncio.current_task():
                    self._rehandshake_task = None
                self._poke()

        if self._rehandshake_task is not None:
            # Another reset while waiting for a held controller: read the settings afresh.
            self._rehandshake_task.cancel()
        self._rehandshake_task = asyncio.get_running_loop().create_task(
            run(), name="smoothjog-rehandshake"
        )

    async def _settle_restart(self) -> None:
        """Before the settings are read again: let the engine watch the restarted controller
        until no jog line sent before the reset can still start it (Jogger.restart_settled),
        writing only the realtime bytes it asks for (`?`, 0x85). Bounded by RESTART_SETTLE_S."""
        engine = self._engine()
        deadline_s = self.now_s() + RESTART_SETTLE_S
        heard = asyncio.Event()
        self._line_heard = heard
        # Lines the link still holds (a stalled wire) or the deferred writer still writes left
        # before the banner's `?`s, which overtake them: the count starts once they are out.
        queued = self._lines_held()
        try:
            while not engine.restart_settled() or queued:
                if self.link_error is not None:
                    raise self.link_error
                now_s = self.now_s()
                if now_s >= deadline_s:
                    logger.info("the restarted controller was not seen at rest; reading it anyway")
                    return
                if queued and not self._lines_held():
                    queued = False
                    engine.restart_wire_clear(now_s)
                for output in engine.restart_outputs(now_s):
                    if isinstance(output, SendRealtime):
                        self.send_realtime(ENGINE, output.byte)
                heard.clear()
                wake_s = min(engine.next_deadline_s(now_s), deadline_s)
                # A received line (a report that shows a jog running) or the engine's deadline.
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout_at(wake_s):  # the loop's clock is now_s's
                        await heard.wait()
        finally:
            if self._line_heard is heard:  # a second banner's watch may have its own by now
                self._line_heard = None

    def _lines_held(self) -> bool:
        """True while lines written before now are not yet handed to the wire."""
        return self.link.queued_bytes > 0 or self._deferred

    async def _until_resumed(self) -> None:
        """Ask `?` until the controller reports a state other than Hold, Door or Sleep."""
        while True:
            await asyncio.sleep(RESUME_POLL_S)
            if self.link_error is not None:
                raise self.link_error
            if self.model.state not in SUSPENDED_STATES:
                return
            self.send_realtime(HANDSHAKE, STATUS_QUERY)

    def _tell(self, kind: str, text: str, hint: str = "") -> None:
        """Tell the user something the host itself found, on the engine's event path."""
        engine = self.engine
        if engine is None:
            logger.warning("%s%s", text, f" ({hint})" if hint else "")
            return
        engine.events.append(EngineEvent(self.now_s(), kind, text, hint))
        self._flush_events()

    async def wait_lost(self) -> None:
        """Return once the link is lost or the host failed (link_error is then set)."""
        assert self._lost is not None, "Host.start() has not run"
        await self._lost.wait()

    def _ended(self) -> None:
        """The link is gone: wake everyone who waits so they see the error."""
        if self._lost is not None:
            self._lost.set()
        if self._port is not None:
            self._port.queue.put_nowait(None)
        if self._room is not None:
            self._room.set()
        self._poke()

    def _fail(self, exc: BaseException) -> None:
        """Something broke inside the host: stop the machine if possible and say so."""
        self.error = exc
        logger.error("smoothjog stopped driving the controller: %s", exc)
        with contextlib.suppress(LinkError, ValueError):
            # Cancel whatever jog runs: the engine can no longer finish its handshake.
            self.send_realtime(ENGINE, JOG_CANCEL)
        if self.link_error is None:
            self.link_error = LinkError(f"the session stopped: {exc}")
        self._ended()

    def _tick(self) -> None:
        """Poll the engine, write what it returns, and arm the timer for its next deadline."""
        self._tick_soon = False
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if not self._ticking or self.link_error is not None:
            return
        assert self._write_lock is not None
        if self._rehandshake_task is not None:
            self._arm(self.now_s() + 0.01)
            return
        if self._write_lock.locked() or self._deferred:
            # Another owner is between recording its line and writing it: an engine line
            # written now would reach the wire out of the ledger's order. Tick after it.
            self._tick_owed = True
            return
        engine = self._engine()
        # _stops_the_host written out, as in _on_link_line: a held jog ticks ~100 times a second.
        try:
            now = self.now_s()
            outputs = engine.poll(now)
            if outputs:
                self._write_now(outputs)
            self._flush_events()
            self._arm(engine.next_deadline_s(now))
        except Exception as exc:
            self._stopped_by(exc)

    def _write_now(self, outputs: Sequence[Output]) -> None:
        """Hand outputs to the link in order, in one write where the link can batch them."""
        self.link.cork()
        try:
            for index, output in enumerate(outputs):
                if isinstance(output, SendLine):
                    if not self.link.send_line_nowait(output.text):
                        # The link's own queue is past its high-water mark (a stalled wire):
                        # write the rest in order once it drains, holding the lock.
                        self._write_later(outputs[index:])
                        break
                else:
                    self.send_realtime(ENGINE, output.byte)
        finally:
            self.link.uncork()

    def _arm(self, deadline_s: float) -> None:
        if self._ticking and self._loop is not None:
            self._timer = self._loop.call_at(deadline_s, self._tick)

    def _write_later(self, outputs: Sequence[Output]) -> None:
        """Write outputs in order, waiting for the link; ticks wait until they are out."""
        assert self._write_lock is not None
        lock = self._write_lock
        self._deferred = True  # until the task holds the lock, nothing else may write

        async def write() -> None:
            try:
                async with lock:
                    with self._stops_the_host():
                        for output in outputs:
                            if isinstance(output, SendLine):
                                await self.link.send_line(output.text)
                            else:
                                self.send_realtime(ENGINE, output.byte)
            finally:
                self._deferred = False
            self._tick_owed = True
            self._after_writer()

        task = asyncio.get_running_loop().create_task(write(), name="smoothjog-writer")
        self._tasks.append(task)
        task.add_done_callback(self._forget_task)

    def _forget_task(self, task: asyncio.Task[None]) -> None:
        if task in self._tasks:
            self._tasks.remove(task)

    def _flush_events(self) -> None:
        engine = self.engine
        if engine is None or not engine.events:
            return
        events, engine.events = engine.events, []
        for event in events:
            log = logger.warning if event.kind == "fault" else logger.info
            log("%s%s", event.text, f" ({event.hint})" if event.hint else "")
            if self.on_event is not None:
                try:
                    self.on_event(event)
                except Exception:  # a listener's bug must not stop the machine's driver
                    logger.exception("an event listener failed")


def _settings_unread_reason(result: HandshakeResult, *, again: bool) -> str | None:
    """Why jogging must wait when `$$` stayed unread (the jog lock's words), else None."""
    unread = result.unread_line("$$")
    if unread is None:
        return None
    state = f" while it was in {unread.state}" if unread.state else ""
    name = error_info(unread.code).name.lower()
    why = f"$$ was refused with error:{unread.code} ({name}){state}"
    if again:
        return (
            f"smoothjog could not read the controller's settings again after its reset: {why};"
            " reset it or reconnect"
        )
    return f"smoothjog could not read the controller's settings: {why}; reconnect once it is idle"


def _resolve_console_reply(entry: Entry, resp: Ok | ErrorReply, now_s: float) -> None:
    """A console line was answered: wake the query() that sent it."""
    future = entry.tag
    if isinstance(future, asyncio.Future) and not future.done():
        future.set_result(resp)


def _lost_to_reset(entry: Entry) -> Exception:
    """What a console line's query() gets when a reset dropped the line."""
    return ConnectError(f"the controller reset before it answered {entry.text!r}")


def _fail_console_entries(
    entries: Sequence[Entry], error: Callable[[Entry], Exception] = _lost_to_reset
) -> None:
    """Console lines that will never be answered (lost to a reset, or left by a critical
    alarm): their query() gets error(entry) instead of a hang."""
    for entry in entries:
        future = entry.tag
        if entry.owner == CONSOLE and isinstance(future, asyncio.Future) and not future.done():
            future.set_exception(error(entry))

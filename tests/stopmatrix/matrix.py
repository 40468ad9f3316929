"""The STOP matrix's cells, the two places they run, and what each cell measured.

Two lanes run side by side, each with its own `smoothjog sim` process (a machine of its own):

- the session lane: smoothjog's side in this process, as `cli/pendant.py`'s run_session builds
  it (a Host over the serial link to the simulator's pty, SessionBackend, one Arbiter, the
  pendant app, the proxy's sender pty), with two Chromium pages (the first controls, the second
  watches) and a gamepad; it runs every source but SIGINT;
- the signal lane: the real `smoothjog proxy` command, started afresh for each cell (SIGINT ends
  it), with the two pages opened on its pendant and the sender on its pty.

Between cells the machine is brought back to rest and placed through a session of the test's
own (never through a page). A cell starts its motion from the controlling page (or the sender),
waits until the page shows it moving and it has run a while, gives the stop, waits until the
machine is still, keeps the controlling input held for HOLD_S more, then releases it. The
simulators' traces are read when they stop, at the end; judge() then judges every cell.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import re
import signal
import time
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any, Final

from aiohttp import web

from smoothjog.authority.arbiter import Arbiter
from smoothjog.control import MachineControl
from smoothjog.host import Host
from smoothjog.links.serial import SerialLink
from smoothjog.proxy import PtySender, SenderProxy
from smoothjog.sim.motion import TraceSegment
from smoothjog.web.server import HUB_KEY, create_app
from smoothjog.web.session_backend import SessionBackend
from tests.stopmatrix.harness import (
    DESKTOP,
    INIT_SCRIPT,
    MOVING_SELECTOR,
    PAD_INFO,
    REST_MM,
    SEGMENT_S,
    Child,
    MachineOps,
    PageProbe,
    Sender,
    SimProcess,
    StopButton,
    accel_along,
    fastest_near,
    path_mm,
    position_at,
    reset_port,
    stop_bound_mm,
    trace_gaps,
)

#: The input stays held this long after the machine came to rest (s).
HOLD_S: Final = 2.0
#: A motion runs this long after the page shows it moving before the stop (s).
RUN_S: Final = 0.6
#: Homing: Z seeks and pulls off first (about 0.7 s), then X and Y seek; stop during that.
HOMING_RUN_S: Final = 1.3
#: After the command exits, its last stop may still be slowing the machine down (s): v/a is at
#: most 0.17 s here, plus 50 ms of committed segments.
SETTLE_S: Final = 0.5
#: Motions stay near this X, Y (mm, machine) and go at most BOX_MM away.
CENTER_MM: Final = (-200.0, -200.0)
BOX_MM: Final = 100.0
X_MM_S: Final = 5000.0 / 60.0


class Source(StrEnum):
    """Who gives the stop."""

    CONTROLLER = "controller-STOP"
    WATCHER = "watcher-STOP"
    ESCAPE = "watcher-Escape"
    DEVICE = "device-button"
    SIGINT = "SIGINT"


class Motion(StrEnum):
    """What moves the machine when the stop comes."""

    JOG = "held-jog"
    STEP = "step"
    GOTO = "goto-zero"
    CONSOLE = "console-G1"
    SENDER = "sender-job"
    HOMING = "homing"


#: Sources whose stop the held jog's input did not give: the server latches its jog, so its
#: heartbeat is forced on through the hold (the page itself stops beating once it hears).
LATCHED: Final = frozenset({Source.WATCHER, Source.ESCAPE, Source.DEVICE})

#: What the stop message says was done, by motion (MotionGate: cancel, hold, reset).
STOP_WORDS: Final = {
    Motion.JOG: "the jog was cancelled",
    Motion.STEP: "the jog was cancelled",
    Motion.GOTO: "the jog was cancelled",
    Motion.CONSOLE: "feed hold",
    Motion.SENDER: "feed hold",
    Motion.HOMING: "ended with a reset",
}
#: The realtime bytes that stop the machine, by name.
STOP_BYTES: Final = {b"\x85": "0x85", b"!": "!", b"\x18": "Ctrl-X"}
#: How the arbiter refuses the jog of an input someone else stopped (its latch).
LATCH_WORDS: Final = "release the controls and press again"

#: The speed each motion runs at (mm/s): the bound uses it (or the trace's, if faster).
NOMINAL_MM_S: Final = {
    Motion.JOG: X_MM_S,  # the page at 100 %, X only
    Motion.STEP: 0.5 * X_MM_S,  # the pendant's STEP_SPEED
    Motion.GOTO: 0.5 * X_MM_S,  # the pendant's GOTO_SPEED
    Motion.CONSOLE: 3000.0 / 60.0,  # G1 ... F3000
    Motion.SENDER: 3000.0 / 60.0,  # the job's F3000
    Motion.HOMING: 2000.0 / 60.0,  # $25 homing seek
}


@dataclass(frozen=True)
class Cell:
    """One stop source against one motion."""

    source: Source
    motion: Motion

    @property
    def id(self) -> str:
        """The test id."""
        return f"{self.source}-{self.motion}"


CELLS: Final = tuple(Cell(s, m) for s in Source for m in Motion)


@dataclass
class Outcome:
    """What one cell did and saw while it ran (the trace is judged later)."""

    cell: Cell
    errors: list[str] = field(default_factory=list)
    t_start_s: float | None = None
    t_given_s: float | None = None
    t_gate_s: float | None = None
    gate_text: str | None = None
    #: When smoothjog handed the controller's link its stop byte (0x85, `!`, Ctrl-X) after the
    #: stop, and which (the session lane only: the command's link is not in reach).
    t_byte_s: float | None = None
    byte: str | None = None
    t_rest_s: float | None = None
    t_release_s: float | None = None
    #: The beginning every page's message must have ("stopped by pendant "), and the name of
    #: who stopped it that must follow it ("#2 127.0.0.1", the pad's device name).
    expected_by: str = "stopped by "
    expected_who: str = ""
    messages: dict[str, list[tuple[float, str]]] = field(default_factory=dict)
    #: What the server answered the heartbeat forced on after the stop (LATCHED sources), or
    #: None when none was forced.
    refusals: list[str] | None = None


@dataclass
class Verdict:
    """A cell judged against the simulator's ground truth."""

    outcome: Outcome
    speed_mm_s: float = 0.0
    measured_mm_s: float = 0.0
    accel_mm_s2: float = 0.0
    bound_mm: float = 0.0
    #: The brief's bound exactly: v²/2a + v x one status period.
    strict_bound_mm: float = 0.0
    moved_before_mm: float = 0.0
    dist_mm: float | None = None
    dist_from_gate_mm: float | None = None
    rest_window_mm: float | None = None
    #: When the machine began to slow down (or stopped dead) after the stop, in the trace.
    t_slowing_s: float | None = None
    #: Of dist_mm, what a reset's untraced partial segment moved (the position jumped).
    untraced_mm: float = 0.0
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """No problem found."""
        return not self.problems


# ------------------------------------------------------------------------------ plans
@dataclass(frozen=True)
class Plan:
    """How a cell's motion goes from where the machine is: toward the middle of the box."""

    motion: Motion
    sx: float
    sy: float

    @property
    def key(self) -> str:
        """The held key of a jog."""
        return "ArrowLeft" if self.sx < 0 else "ArrowRight"

    def jog_message(self) -> dict[str, object]:
        """The held jog as the page sends it (and its link worker repeats it)."""
        return {"type": "jog", "axes": {"X": self.sx, "Y": 0.0, "Z": 0.0}, "speed": 1.0}

    def setup_line(self, pos: tuple[float, ...]) -> str | None:
        """The work offset this motion needs (G10 L2: G54 at machine coordinates)."""
        x, y, z = pos[:3]
        if self.motion is Motion.GOTO:
            return f"G10L2P1X{x + 120 * self.sx:.3f}Y{y + 120 * self.sy:.3f}Z{z:.3f}"
        if self.motion is Motion.CONSOLE:
            # `G1X-150` (work) then ends 150 mm from here, toward the middle.
            return f"G10L2P1X{x + 150 * self.sx + 150:.3f}"
        return None

    def program(self) -> tuple[str, ...]:
        """The sender's job: a 120 mm square at F3000, relative, toward the middle first."""
        x, y = f"{120 * self.sx:.0f}", f"{120 * self.sy:.0f}"
        nx, ny = f"{-120 * self.sx:.0f}", f"{-120 * self.sy:.0f}"
        return ("G21G91", f"G1X{x}F3000", f"G1Y{y}", f"G1X{nx}", f"G1Y{ny}", "G90")


def plan_for(motion: Motion, pos: tuple[float, ...]) -> Plan:
    """Each motion heads toward the middle of the box."""
    sx = -1.0 if pos[0] > CENTER_MM[0] else 1.0
    sy = -1.0 if pos[1] > CENTER_MM[1] else 1.0
    return Plan(motion, sx, sy)


def in_box(pos: tuple[float, ...]) -> bool:
    """Close enough to the middle for every motion to stay inside the machine."""
    return all(abs(p - c) <= BOX_MM for p, c in zip(pos[:2], CENTER_MM, strict=True))


async def park(ops: MachineOps) -> None:
    """A last short move: the trace then shows where the last cell really left the machine (a
    reset's partial segment is not traced; the next segment's start is where it ended)."""
    await ops.settle(alarm_ok=False)
    plan = plan_for(Motion.GOTO, ops.mpos())
    x, y = ops.mpos()[:2]
    await ops.goto({"X": x + 5.0 * plan.sx, "Y": y + 5.0 * plan.sy})


async def prepare(ops: MachineOps, motion: Motion) -> Plan:
    """Rest, out of Hold and (but for homing) Alarm, in the box, with the work offset needed."""
    await ops.settle(alarm_ok=motion is Motion.HOMING)
    if ops.host.model.state == "Alarm":
        return plan_for(motion, ops.mpos())  # homing again from where the last one stopped
    if not in_box(ops.mpos()):
        await ops.goto({"X": CENTER_MM[0], "Y": CENTER_MM[1]})
    plan = plan_for(motion, ops.mpos())
    line = plan.setup_line(ops.mpos())
    if line is not None:
        await ops.line(line)
    await ops.until(ops.still, "rest after the setup", 10.0)
    return plan


# ------------------------------------------------------------------------------ one cell
class Lane:
    """Where cells run: a machine, the two pages, a sender port; subclasses add the rest."""

    name = "lane"

    def __init__(self, folder: Path, machine: Path, browser: Any) -> None:
        """Name the files; nothing starts before setup()."""
        self.folder = folder
        self.sim = SimProcess(machine, folder / "sim-pty", folder / "trace.jsonl")
        self.sender_link = folder / "sender-pty"
        self.browser = browser
        self.ctrl: PageProbe | None = None
        self.watch: PageProbe | None = None
        self.outcomes: list[Outcome] = []

    async def new_page(self, role: str) -> PageProbe:
        """A page in a browser context of its own (its own storage), with the probe script."""
        context = await self.browser.new_context(viewport=DESKTOP, locale="en-US")
        await context.add_init_script(INIT_SCRIPT)
        return PageProbe(await context.new_page(), role)

    async def open_pages(self, url: str) -> tuple[PageProbe, PageProbe]:
        """The controller page first (the first input controls), then the watcher."""
        if self.ctrl is None:
            self.ctrl = await self.new_page("controller")
            self.watch = await self.new_page("watcher")
        assert self.watch is not None
        await self.ctrl.open(url)
        await self.ctrl.page.fill("#speed", "100")  # jogs at full speed: the brief's profile
        await self.watch.open(url)
        return self.ctrl, self.watch

    # -- hooks --------------------------------------------------------------------------------
    async def before(self, cell: Cell) -> Plan:
        """Prepare the machine and the pages for cell."""
        raise NotImplementedError

    async def give_stop(self, cell: Cell, outcome: Outcome) -> None:
        """Give the stop of cell's source; sets outcome.t_given_s."""
        raise NotImplementedError

    async def until_still(self, outcome: Outcome) -> None:
        """Wait until the machine is still (as smoothjog or the command's exit tells)."""
        raise NotImplementedError

    async def after(self, cell: Cell, outcome: Outcome) -> None:
        """Note what smoothjog's own side said; make sure nothing moves any more."""

    # -- the cell -----------------------------------------------------------------------------
    async def run(self, cell: Cell) -> Outcome:
        """Run one cell; failures are noted in the outcome, never raised."""
        outcome = Outcome(cell)
        self.outcomes.append(outcome)
        sender: Sender | None = None
        streaming: asyncio.Task[None] | None = None
        plan: Plan | None = None
        try:
            plan = await self.before(cell)
            ctrl, watch = self.pages()
            for probe in (ctrl, watch):
                await probe.clear()
            outcome.t_start_s = time.monotonic()
            if cell.motion is Motion.SENDER:
                sender = Sender(self.sender_link)
                await sender.open()
                streaming = asyncio.create_task(sender.stream(plan.program()))
            else:
                await start_motion(ctrl, plan)
            await self.wait_running(cell, outcome)
            await self.give_stop(cell, outcome)
            beating = cell.motion is Motion.JOG and cell.source in LATCHED
            if beating:
                await ctrl.beat(plan.jog_message())
            await self.until_still(outcome)
            outcome.t_rest_s = time.monotonic()
            await asyncio.sleep(HOLD_S)  # the input is still held: nothing may move
            outcome.t_release_s = time.monotonic()
            if beating:
                await ctrl.unbeat()
                outcome.refusals = await ctrl.errors()
            if cell.motion is Motion.JOG:
                await ctrl.page.keyboard.up(plan.key)
            await collect_messages(outcome, (ctrl, watch))
        except Exception as exc:  # the cell fails with the reason; the others go on
            outcome.errors.append(f"{type(exc).__name__}: {exc}")
        finally:
            if plan is not None and cell.motion is Motion.JOG and self.ctrl is not None:
                with contextlib.suppress(Exception):
                    await self.ctrl.unbeat()
                    await self.ctrl.page.keyboard.up(plan.key)
            if streaming is not None:
                streaming.cancel()
                await asyncio.gather(streaming, return_exceptions=True)
            if sender is not None:
                sender.close()
            try:
                await self.after(cell, outcome)
            except Exception as exc:
                outcome.errors.append(f"after the cell: {type(exc).__name__}: {exc}")
        return outcome

    def pages(self) -> tuple[PageProbe, PageProbe]:
        """Both pages (opened)."""
        assert self.ctrl is not None
        assert self.watch is not None
        return self.ctrl, self.watch

    async def wait_running(self, cell: Cell, outcome: Outcome) -> None:
        """Until the page shows the machine moving, then a while longer."""
        ctrl, _ = self.pages()
        try:
            await ctrl.page.wait_for_selector(MOVING_SELECTOR, timeout=8_000)
        except Exception:
            outcome.errors.append("the controller page never showed the machine moving")
        await asyncio.sleep(HOMING_RUN_S if cell.motion is Motion.HOMING else RUN_S)


async def start_motion(ctrl: PageProbe, plan: Plan) -> None:
    """Start a motion from the controlling page."""
    page = ctrl.page
    if plan.motion is Motion.JOG:
        await page.wait_for_selector("body:not(.jog-disabled)", timeout=10_000)
        await ctrl.blur()
        await page.keyboard.down(plan.key)
    elif plan.motion is Motion.STEP:
        await page.wait_for_selector("body:not(.jog-disabled)", timeout=10_000)
        await ctrl.send({"type": "step", "axis": "X", "dist_mm": 100.0 * plan.sx})
    elif plan.motion is Motion.GOTO:
        await page.click("button[data-cmd=goto_zero]", timeout=10_000)
    elif plan.motion is Motion.CONSOLE:
        await page.wait_for_selector("#console-send:not([disabled])", timeout=10_000)
        await page.fill("#console-input", "G1X-150F3000")
        await page.press("#console-input", "Enter")
    elif plan.motion is Motion.HOMING:
        await page.click("#m-home", timeout=10_000)


async def page_stop(probe: PageProbe, source: Source) -> float:
    """Press STOP (or Escape) on a page; the time the page saw it, on time.monotonic()."""
    if source is Source.ESCAPE:
        await probe.page.keyboard.press("Escape")
        return await probe.mark("escape")
    await probe.page.click("#stop", timeout=3_000)
    return await probe.mark("click")


async def collect_messages(outcome: Outcome, probes: tuple[PageProbe, ...]) -> None:
    """Every page's `stopped` messages (waiting a little for each page to have one)."""
    end = time.monotonic() + 2.0
    for probe in probes:
        got = await probe.stopped()
        while not got and time.monotonic() < end:
            await asyncio.sleep(0.05)
            got = await probe.stopped()
        outcome.messages[probe.role] = got


# ------------------------------------------------------------------------------ the lanes
class SessionLane(Lane):
    """smoothjog's side in this process, built as run_session builds it; a gamepad beside."""

    name = "session"

    async def setup(self) -> None:
        """Simulator, host, proxy, pendant, pages, gamepad; the machine homed and placed."""
        await self.sim.start()
        link = SerialLink(str(self.sim.link), wait_banner_s=1.0)
        await link.open()
        self.bytes_sent: list[tuple[float, bytes]] = []
        send_realtime = link.send_realtime

        def spy(byte: bytes) -> None:
            self.bytes_sent.append((time.monotonic(), byte))
            send_realtime(byte)

        setattr(link, "send_realtime", spy)  # noqa: B010 -- the instance's method is wrapped
        self.host = Host(link)
        self.proxy = SenderProxy()
        self.proxy.attach(self.host)
        await self.host.start()
        self.proxy.started(self.host)
        self.backend = SessionBackend(self.host)
        self.arbiter = Arbiter(self.backend)
        self.app = create_app(self.backend, token=None, arbiter=self.arbiter)
        self.runner = web.AppRunner(self.app, access_log=None)
        await self.runner.setup()
        site = web.TCPSite(self.runner, "127.0.0.1", 0)
        await site.start()
        port = int(self.runner.addresses[0][1])
        self.pty = PtySender(self.proxy, self.sender_link)
        self.pty.open()
        self.forwarder = asyncio.create_task(self.proxy.run())
        self.ops = MachineOps(self.host, self.backend.control)
        await self.ops.settle(alarm_ok=False)  # homes the machine from power-up
        await self.ops.goto({"X": CENTER_MM[0], "Y": CENTER_MM[1]})
        await self.open_pages(f"http://127.0.0.1:{port}/")
        self.pad = StopButton()
        self.pad_task = asyncio.create_task(self.arbiter.run_input(self.pad.input))

    async def teardown(self) -> list[TraceSegment]:
        """Everything closed; the simulator's trace."""
        with contextlib.suppress(Exception):
            await park(self.ops)
        self.pad.source.close()
        await asyncio.gather(self.pad_task, return_exceptions=True)
        await self.runner.cleanup()
        self.forwarder.cancel()
        await asyncio.gather(self.forwarder, return_exceptions=True)
        self.pty.close()
        await self.host.close()
        return await self.sim.stop()

    def page_names(self) -> tuple[str, str]:
        """The names the arbiter gives the controller page and the watcher page."""
        hub = self.app[HUB_KEY]
        controller = hub.controller
        assert controller is not None
        watchers = [c.name for c in hub.clients if c is not controller]
        return controller.name, watchers[0]

    async def before(self, cell: Cell) -> Plan:
        """Prepare the machine through the test's own calls to the session."""
        plan = await prepare(self.ops, cell.motion)
        self.last_stop = self.backend.gate.last_stop
        return plan

    async def give_stop(self, cell: Cell, outcome: Outcome) -> None:
        """Press the source's STOP."""
        ctrl, watch = self.pages()
        ctrl_name, watch_name = self.page_names()
        if cell.source is Source.DEVICE:
            outcome.expected_by = "stopped by gamepad "
            outcome.expected_who = PAD_INFO.name
            outcome.t_given_s = self.pad.press()
            return
        probe = ctrl if cell.source is Source.CONTROLLER else watch
        outcome.expected_by = "stopped by pendant "
        outcome.expected_who = ctrl_name if cell.source is Source.CONTROLLER else watch_name
        outcome.t_given_s = await page_stop(probe, cell.source)

    async def until_still(self, outcome: Outcome) -> None:
        """smoothjog's view says still (reports, the engine)."""
        try:
            await self.ops.until(self.ops.still, "rest after the stop", 5.0)
        except TimeoutError as exc:
            outcome.errors.append(str(exc))

    async def after(self, cell: Cell, outcome: Outcome) -> None:
        """The gate's record of the stop; stop for good what a failed stop left moving."""
        record = self.backend.gate.last_stop
        if record is not None and record is not self.last_stop:
            outcome.t_gate_s = record.t_s
            outcome.gate_text = record.text
        given = outcome.t_given_s
        stops = [(t, b) for t, b in self.bytes_sent if b in STOP_BYTES]
        if given is not None and (first := next((x for x in stops if x[0] >= given), None)):
            outcome.t_byte_s, outcome.byte = first[0], STOP_BYTES[first[1]]
        if not self.ops.still():
            self.backend.gate.stop("the stop matrix's cleanup")


class SignalLane(Lane):
    """The real `smoothjog proxy`, one process per cell, ended by SIGINT."""

    name = "signal"

    async def setup(self) -> None:
        """Simulator up, machine homed and placed."""
        await self.sim.start()
        async with self.session() as ops:
            await ops.settle(alarm_ok=False)
            await ops.goto({"X": CENTER_MM[0], "Y": CENTER_MM[1]})
        self.child: Child | None = None

    async def teardown(self) -> list[TraceSegment]:
        """The simulator's trace."""
        with contextlib.suppress(Exception):
            await asyncio.to_thread(reset_port, self.sim.link)
            async with self.session() as ops:
                await park(ops)
        return await self.sim.stop()

    @contextlib.asynccontextmanager
    async def session(self) -> Any:
        """A short session of the test's own on the simulator (between two commands)."""
        link = SerialLink(str(self.sim.link), wait_banner_s=0.3)
        await link.open()
        host = Host(link)
        try:
            await host.start()
            yield MachineOps(host, MachineControl(host))
        finally:
            await host.close()

    async def before(self, cell: Cell) -> Plan:
        """Prepare the machine, start the command, open the pages on its pendant."""
        # A stop by feed hold leaves the controller in Hold, where smoothjog refuses to connect
        # (ControllerSuspendedError): reset it first, as its message tells the user to.
        await asyncio.to_thread(reset_port, self.sim.link)
        async with self.session() as ops:
            plan = await prepare(ops, cell.motion)
        child = await Child.start(
            "proxy",
            "--port",
            str(self.sim.link),
            "--link",
            str(self.sender_link),
            "--http-port",
            "0",
            "--timeout",
            "2",
        )
        self.child = child
        line = await child.wait_line(lambda x: x.startswith("smoothjog pendant: http"), 30.0)
        match = re.search(r"http://\S+", line)
        assert match is not None
        await self.open_pages(match[0])
        return plan

    async def give_stop(self, cell: Cell, outcome: Outcome) -> None:
        """Ctrl-C to the command."""
        assert self.child is not None
        outcome.expected_by = "stopped by a signal to smoothjog"
        outcome.t_given_s = self.child.signal(signal.SIGINT)

    async def until_still(self, outcome: Outcome) -> None:
        """The command has ended (it stops the machine before it lets go of it)."""
        assert self.child is not None
        code = await self.child.wait(15.0)
        if code != 0:
            outcome.errors.append(f"smoothjog proxy exited {code}: {self.child.stderr[-5:]}")
        # A hold the command gave may still be slowing the machine down as it exits.
        await asyncio.sleep(SETTLE_S)

    async def after(self, cell: Cell, outcome: Outcome) -> None:
        """The command is gone for good; what it said about the stop."""
        child, self.child = self.child, None
        if child is None:
            return
        if child.proc.returncode is None:
            await child.stop()
        said = [line for line in child.stderr if "stopped by" in line]
        outcome.gate_text = said[-1] if said else None


# ------------------------------------------------------------------------------ judging
def judge(outcome: Outcome, trace: list[TraceSegment]) -> Verdict:
    """A cell against the ground truth: moving when stopped, stopped within the bound, still
    for HOLD_S while held, every page told who stopped it."""
    verdict = Verdict(outcome)
    problems = verdict.problems
    problems.extend(outcome.errors)
    t_given, t_release = outcome.t_given_s, outcome.t_release_s
    if t_given is None or t_release is None or outcome.t_start_s is None:
        problems.append("the cell did not run to its end")
        return verdict
    verdict.moved_before_mm = path_mm(trace, outcome.t_start_s, t_given)
    if verdict.moved_before_mm < 1.0:
        problems.append("the machine was not moving when the stop was given")
    seg = fastest_near(trace, t_given - 0.1, t_given)
    verdict.measured_mm_s = seg.speed_mm_s if seg is not None else 0.0
    verdict.accel_mm_s2 = accel_along(seg) if seg is not None else 500.0
    verdict.speed_mm_s = max(NOMINAL_MM_S[outcome.cell.motion], verdict.measured_mm_s)
    verdict.bound_mm = stop_bound_mm(verdict.speed_mm_s, verdict.accel_mm_s2)
    verdict.strict_bound_mm = stop_bound_mm(verdict.speed_mm_s, verdict.accel_mm_s2, 0.0)
    verdict.dist_mm = path_mm(trace, t_given, t_release)
    verdict.t_slowing_s = slowing_from(trace, t_given, verdict.measured_mm_s)
    verdict.untraced_mm = sum(
        mm for t_s, mm in trace_gaps(trace) if t_given <= t_s + SEGMENT_S <= t_release
    )
    if outcome.t_gate_s is not None:
        verdict.dist_from_gate_mm = path_mm(trace, outcome.t_gate_s, t_release)
    verdict.rest_window_mm = path_mm(trace, t_release - HOLD_S, t_release, gaps_late=False)
    if verdict.dist_mm > verdict.bound_mm:
        at = position_at(trace, t_given)
        problems.append(
            f"moved {verdict.dist_mm:.2f} mm after the stop (from {at}), more than"
            f" {verdict.bound_mm:.2f} mm"
        )
    if verdict.rest_window_mm > REST_MM:
        problems.append(
            f"moved {verdict.rest_window_mm:.2f} mm in the last {HOLD_S:g} s the input was held"
        )
    what = STOP_WORDS[outcome.cell.motion]
    for role in ("controller", "watcher"):
        texts = [text for _, text in outcome.messages.get(role, [])]
        by, who = outcome.expected_by, outcome.expected_who
        if not any(text.startswith(by) and who in text.split(":")[0] for text in texts):
            problems.append(f"the {role} page was not told {by}{who}...: {texts}")
        elif not any(what in text for text in texts):
            problems.append(f"the {role} page was not told {what!r}: {texts}")
    if outcome.refusals is not None and not any(LATCH_WORDS in t for t in outcome.refusals):
        problems.append(f"the heartbeat held on after the stop was not refused: {outcome.refusals}")
    return verdict


def slowing_from(trace: list[TraceSegment], t_s: float, speed_mm_s: float) -> float | None:
    """The first moment from t_s on that the machine runs slower than speed_mm_s, or stops
    (None: it never moved after t_s)."""
    last_end: float | None = None
    for seg in trace:
        if seg.t1_s <= t_s:
            last_end = seg.t1_s
            continue
        if last_end is not None and seg.t0_s > last_end + 1e-6:
            return max(last_end, t_s)  # it stood still before this segment
        if seg.speed_mm_s < 0.98 * speed_mm_s:
            return max(seg.t0_s, t_s)
        last_end = seg.t1_s
    return last_end


async def run_lanes(
    cells: list[Cell], folder: Path, machine: Path, browser: Any
) -> dict[str, Verdict]:
    """Run the cells (the signal lane's beside the session lane's) and judge them all."""
    signal_cells = [c for c in cells if c.source is Source.SIGINT]
    session_cells = [c for c in cells if c.source is not Source.SIGINT]
    lanes: list[tuple[SessionLane | SignalLane, list[Cell]]] = []
    if session_cells:
        (folder / "session").mkdir()
        lanes.append((SessionLane(folder / "session", machine, browser), session_cells))
    if signal_cells:
        (folder / "signal").mkdir()
        lanes.append((SignalLane(folder / "signal", machine, browser), signal_cells))

    async def run_lane(lane: SessionLane | SignalLane, mine: list[Cell]) -> list[TraceSegment]:
        await lane.setup()
        try:
            for cell in mine:
                await lane.run(cell)
        finally:
            trace = await lane.teardown()
        return trace

    traces = await asyncio.gather(*(run_lane(lane, mine) for lane, mine in lanes))
    verdicts: dict[str, Verdict] = {}
    for (lane, _), trace in zip(lanes, traces, strict=True):
        for outcome in lane.outcomes:
            verdicts[outcome.cell.id] = judge(outcome, trace)
        dump(lane.outcomes, lane.folder / "outcomes.json")
    return verdicts


def dump(outcomes: list[Outcome], path: Path) -> None:
    """What each cell saw, beside the trace, for a closer look at a failure."""
    rows = [dataclasses.asdict(o) for o in outcomes]
    path.write_text(json.dumps(rows, indent=1, default=str), encoding="utf-8")


def order(cells: list[Cell]) -> list[Cell]:
    """Motions in Motion's order (homing last: each homing cell starts in the Alarm the one
    before left), sources in Source's order within each."""
    motions, sources = list(Motion), list(Source)
    return sorted(cells, key=lambda c: (motions.index(c.motion), sources.index(c.source)))


def _ms(t1_s: float | None, t0_s: float | None) -> str:
    return "-" if t1_s is None or t0_s is None else f"{(t1_s - t0_s) * 1e3:.0f}"


def table(verdicts: dict[str, Verdict]) -> str:
    """The matrix as text: pass/fail and the distance after the stop per cell (mm), with where
    the time before the machine slowed down went (ms): from the stop given to smoothjog's gate
    (gate), from there to the stop byte on the controller's link (byte, the session lane
    only), and from that (else from the gate, else from the stop given) to the machine running
    slower in the trace (slow)."""
    lines = [
        f"{'cell':26} {'ok':4} {'after':>6} {'bound':>6} {'strict':>6} {'v mm/s':>6}"
        f" {'gate':>4} {'byte':>9} {'slow':>4} {'rest':>5}  problems"
    ]
    for cell in CELLS:
        v = verdicts.get(cell.id)
        if v is None:
            continue
        o = v.outcome
        dist = "-" if v.dist_mm is None else f"{v.dist_mm:.2f}"
        rest = "-" if v.rest_window_mm is None else f"{v.rest_window_mm:.3f}"
        byte = "-" if o.byte is None else f"{o.byte}@{_ms(o.t_byte_s, o.t_gate_s)}"
        slow = _ms(v.t_slowing_s, o.t_byte_s or o.t_gate_s or o.t_given_s)
        if cell.motion is Motion.HOMING:
            slow = "dead"  # a reset stops the steps at once (its last segment is untraced)
        lines.append(
            f"{cell.id:26} {'pass' if v.ok else 'FAIL':4} {dist:>6} {v.bound_mm:6.2f}"
            f" {v.strict_bound_mm:6.2f} {v.measured_mm_s:6.2f} {_ms(o.t_gate_s, o.t_given_s):>4}"
            f" {byte:>9} {slow:>4} {rest:>5}  {'; '.join(v.problems)}"
        )
    return "\n".join(lines)


__all__ = ["CELLS", "Cell", "Motion", "Source", "Verdict", "order", "run_lanes", "table"]

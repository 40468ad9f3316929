"""Outside events: every sign that someone else acted on the controller, as one ordered table.

Someone else may hold (`!`, a hold button), cancel (0x85), reset (0x18), open the door or move
the machine while smoothjog jogs. Grbl shows `Jog` through an outside hold or 0x85 and may never
show Idle: when that stop ends, the lines still in its buffer start the machine again
(firmware-facts §3.1, §3.7). So the engine reads signs: each SIGNS entry names the evidence it
reads, the verdict it gives (one Verdict type), and the reaction the phase machine takes; its
place in the table is its precedence. The incident behind each entry, and the test that fails
without it, are in docs/jogging.md, "Outside events: the sign table".

What happens when someone else presses feed hold during a jog: a hold in `Jog` acts as a jog
cancel. If its input shows in `Pn`, "hold-or-door-input" abandons the path at once. Otherwise
the first report that shows the machine resting or braking where the path sent says it cannot
(rest-inside-block, rest-short-of-acked-path, slowed-inside-block, slowed-since-last-report,
lag-behind-estimate), or the controller leaving a line unread (line-unread), gives the verdict;
the reaction STOP_AND_CANCEL says so, latches the held stick until it is pressed again, runs the
stop handshake and cancels each left-over line as a report shows it running.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum

from smoothjog.core import increments as inc
from smoothjog.core.engine import bounds
from smoothjog.core.engine.clearance import Clearance, Suspect
from smoothjog.core.engine.limits import JOG_STATES, JogTuning, state_reason
from smoothjog.core.engine.lines import LineTag, kind
from smoothjog.core.engine.records import Phase
from smoothjog.core.engine.tracker import PathSeg, PathTracker
from smoothjog.core.ledger import ENGINE, Entry
from smoothjog.core.responses import StatusReport
from smoothjog.core.units import Vec, mm_min_to_mm_s, mm_s_to_mm_min

#: A report that puts the machine this much further behind the estimate than its age can
#: explain is not running what was sent (the estimate follows the planner to well under this).
OUTSIDE_LAG_MM = bounds.OUTSIDE_LAG_MM
#: ... or this long at the commanded speed, if more: an outside stop pauses a jog at least
#: 50 ms (two $1 delays, firmware-facts §3.7); turns and queue ends lag up to 0.7 mm.
OUTSIDE_LAG_S = 0.03
#: ... but never more than this: a hold at full speed must be seen within its deceleration.
OUTSIDE_LAG_CAP_MM = 1.0
#: The least distance a `FS:0` report may leave to the end of the queue with nothing outside.
FS_LEAD_FLOOR_MM = 0.1
#: A stop this many steps (of the worst axis) off the path sent was not smoothjog's doing: the
#: fuzz's worst tracked-minus-real without outside events is under one step.
OFF_PATH_STOP_STEPS = 5.0
#: Reports, each asked for after the one before arrived, that find the controller not reading
#: a jog line it holds before the engine calls it an outside stop.
UNREAD_REPORTS = 2


class Reaction(Enum):
    """What the phase machine does on a verdict, in words."""

    STOP_AND_CANCEL = (
        "say who stopped it; latch a held stick until it is pressed again; stop and sync;"
        " cancel each left-over line that a report shows running"
    )
    DESYNC = "as STOP_AND_CANCEL, unless the same report shows a Run race (then settle)"
    ABANDON_AND_LATCH = (
        "say which input; forget the path; owe a cancel for unanswered lines; latch the stick"
    )
    ABANDON = "say why; forget the path; owe a cancel for unanswered lines"
    RECORD = "say so, and record the stop as after an outside stop"


class Stage(Enum):
    """When a sign is read."""

    MOTION = "a status report, as its position corrects the estimate"
    STATE = "the same report, after the Run-race check"
    STOP_END = "the Idle report that ends a stop"


@dataclass(frozen=True)
class Verdict:
    """Someone else acted: which sign saw it, how it showed (words), and the reaction."""

    sign: str
    how: str
    reaction: Reaction


@dataclass(frozen=True)
class Evidence:
    """What one status report shows, with what the engine knew when it came."""

    report: StatusReport
    asked_s: float | None  # when its `?` was written (None: not known)
    now_s: float
    mpos: Vec | None
    phase: Phase
    #: The queue runs as sent: jogging, or smoothjog's own stop still before its 0x85.
    runs_as_sent: bool
    off_path: bool  # the report lies off every jog sent
    predicted_mm: float  # the estimate at now_s before the report corrected it
    estimate_before_mm: float  # the estimate as the last poll left it
    commanded: inc.VectorMove
    jog_unbraked: bool
    others_poll: bool  # another program asks `?` too
    relayed: bool
    oldest: Entry | None  # the oldest line on the wire, anyone's
    rtt_s: float
    report_wire_s: float
    pressed: str  # hold or door inputs active now that were not at rest
    jogs_unanswered: bool

    @property
    def judging_the_run(self) -> bool:
        """The lag signs apply: a Jog report with a position on the path while the queue runs
        as sent."""
        return (
            self.mpos is not None
            and not self.off_path
            and self.report.state == "Jog"
            and self.runs_as_sent
        )


@dataclass(frozen=True)
class Sign:
    """One entry of the table."""

    name: str
    stage: Stage
    evidence: str
    reaction: Reaction
    read: Callable[[Signs, Evidence], str | None]
    #: Read at every report, even after an earlier entry gave the verdict (it counts reports).
    every_report: bool = False


class Signs:
    """The signs' memory across reports, and the table read in order."""

    def __init__(self, track: PathTracker, tuning: JogTuning, clearance: Clearance) -> None:
        """Nothing remembered."""
        self.track = track
        self.tuning = tuning
        self.clearance = clearance
        #: The commanded move a Jog report last showed running at its speed.
        self.seen_at_speed: inc.VectorMove | None = None
        #: A report of this run showed the machine at its commanded speed, with no stall since.
        self.cruised = False
        #: A Jog report at FS:0 inside a block: when it was built at the latest, where it put
        #: the machine, and the block.
        self.rest_inside: Suspect | None = None
        #: The last Jog report's place and FS (mm/s), where the acknowledged jogs then ended,
        #: and the jog it was on.
        self.prev_jog_report: tuple[float, float, float, PathSeg] | None = None
        #: The oldest line watched for being left unread, when the last report that asked
        #: after it came, and how many did.
        self._unread_entry: Entry | None = None
        self._unread_seen_s = -math.inf
        self._unread_reports = 0

    def forget_run(self) -> None:
        """A new run, or one no longer judged: what was seen of the last one goes."""
        self.seen_at_speed = None
        self.cruised = False
        self.rest_inside = None
        self.prev_jog_report = None

    def held_up(self) -> None:
        """A reply came late (a stall): the machine may have run short and slowed, which is
        no outside stop. Judge only once a report shows it at speed again."""
        self.seen_at_speed = None
        self.cruised = False

    def read(self, stage: Stage, ev: Evidence) -> Verdict | None:
        """The first verdict of the stage's signs in table order (those read at every report
        are read after it too)."""
        if (
            stage is Stage.MOTION
            and ev.mpos is not None
            and not ev.off_path
            and not ev.judging_the_run
        ):
            self.forget_run()
        verdict: Verdict | None = None
        for sign in SIGNS:
            if sign.stage is not stage or (verdict is not None and not sign.every_report):
                continue
            how = sign.read(self, ev)
            if how is not None and verdict is None:
                verdict = Verdict(sign.name, how, sign.reaction)
        return verdict

    # ------------------------------------------------------------------ the report signs
    def _step_mm(self) -> float:
        return 1.0 / min(self.track.steps_per_mm)

    def rest_inside_block(self, ev: Evidence) -> str | None:
        """FS:0 well inside an acknowledged block, and a report built after the committed
        segments surely ran still finds the machine short of that block's end.

        The planner plans rest only at a block's end (or a reversal), which the machine reaches
        within the committed lead; only someone else's stop rests it inside a block. Not used
        while another program polls `?` (its report may answer ours early).
        """
        if not ev.judging_the_run:
            return None
        track = self.track
        x_mm = track.x_reported_mm
        if x_mm is None or ev.others_poll:
            self.rest_inside = None
            return None
        margin_mm = max(OUTSIDE_LAG_MM, 4.0 * self._step_mm())
        if self.rest_inside is not None:
            built_s, rest_mm, seg = self.rest_inside
            if track.seg_at(rest_mm) is not seg or x_mm >= seg.x1_mm - margin_mm:
                self.rest_inside = None  # a new path, or it ran on to the block's end
            elif ev.asked_s is not None and ev.asked_s - built_s >= 2.0 * self.tuning.committed_s:
                self.rest_inside = None
                return (
                    f"it rested {seg.x1_mm - rest_mm:.2f} mm before the end of a jog it was"
                    " sent and did not run on to it"
                )
            else:
                return None
        if ev.report.feed != 0.0:
            return None
        here = track.seg_at(x_mm)
        if (
            here is not None
            and here.acked
            and x_mm - here.x0_mm > margin_mm
            and here.x1_mm - x_mm > margin_mm
        ):
            # Built at the latest when its last byte left the controller.
            self.rest_inside = (ev.now_s - ev.report_wire_s, x_mm, here)
        return None

    def rest_short_of_acked_path(self, ev: Evidence) -> str | None:
        """FS:0 in Jog with acknowledged path ahead, beyond what the committed segments still
        cover: a turn never slows the planner to 0 and a queue run dry rests at its end.

        Away from a junction the planner passes at no speed (a reversal let run) and from a
        queue that ends at a boundary (a slow jog's committed segments run on there).
        """
        if not ev.judging_the_run:
            return None
        track, move, feed = self.track, ev.commanded, ev.report.feed
        cmd_mm_min = mm_s_to_mm_min(move.speed_mm_s)
        acked_end_mm = bounds.acked_end_mm(track)
        here = track.seg_at(track.x_est_mm)
        seg_mm_min = mm_s_to_mm_min(here.speed_mm_s) if here is not None else cmd_mm_min
        if feed is not None and feed >= 0.95 * min(cmd_mm_min, seg_mm_min):
            self.cruised = True
            return None
        if feed != 0.0 or ev.asked_s is None or acked_end_mm is None:
            return None
        step_mm = self._step_mm()
        rest_ahead_mm = bounds.rest_ahead_mm(track, acked_end_mm, step_mm, cruised=self.cruised)
        v_mm_s = max(move.speed_mm_s, track.v_est_mm_s)
        lead_s = 2.0 * self.tuning.committed_s
        # What the committed segments may still cover after FS reads 0: at most ½·a·t² at the
        # end of a braking, never more than the whole stop, at least FS_LEAD_FLOOR_MM.
        committed_mm = max(
            min(0.5 * move.accel_mm_s2 * lead_s**2, inc.stop_distance_mm(v_mm_s, move.accel_mm_s2)),
            FS_LEAD_FLOOR_MM,
        )
        margin_mm = max(OUTSIDE_LAG_MM, 3.0 * step_mm)
        if (
            rest_ahead_mm is not None
            and rest_ahead_mm > committed_mm + margin_mm
            and not bounds.near_a_junction_at_rest(track, track.x_est_mm, self.tuning)
            and not bounds.running_out_at_a_boundary(
                track, self.clearance, committed_mm + v_mm_s * lead_s + margin_mm
            )
        ):
            return f"it stood still {rest_ahead_mm:.2f} mm short of the path it was sent"
        return None

    def slowed_inside_block(self, ev: Evidence) -> str | None:
        """FS below the slowest the block the machine is in can run at the reported place:
        min(v, √(2a·x), √(2a·(L − x − lead))), however late the link was."""
        feed = ev.report.feed
        if not ev.judging_the_run or feed is None:
            return None
        return bounds.slowed_inside_a_block(self.track, self.tuning, feed, self._step_mm())

    def slowed_since_last_report(self, ev: Evidence) -> str | None:
        """FS below the slowest the jogs acknowledged by the last report allow from that
        report's place and feed on (not used through a relay)."""
        if not ev.judging_the_run:
            return None
        feed = ev.report.feed
        if feed is None:
            self.prev_jog_report = None
            return None
        prev, self.prev_jog_report = self.prev_jog_report, None
        track = self.track
        x_mm = track.x_reported_mm
        held_end_mm = bounds.acked_end_mm(track)
        if x_mm is None or held_end_mm is None or ev.relayed:
            return None
        here = track.seg_at(x_mm)
        if here is None:
            return None
        self.prev_jog_report = (x_mm, mm_min_to_mm_s(feed), held_end_mm, here)
        if prev is None:
            return None
        return bounds.slowed_since(track, self.tuning, prev, x_mm, feed, self._step_mm())

    def lag_behind_estimate(self, ev: Evidence) -> str | None:
        """A cruise seen at its speed, now slower and further behind the estimate than the
        report's age explains, with more acknowledged path ahead than it needs to stop."""
        if not ev.judging_the_run:
            return None
        track, move, feed, asked_s = self.track, ev.commanded, ev.report.feed, ev.asked_s
        cmd_mm_min = mm_s_to_mm_min(move.speed_mm_s)
        if self.seen_at_speed != move:  # by value: an input re-sends the same stick
            if feed is not None and feed >= 0.95 * cmd_mm_min:
                self.seen_at_speed = move
            return None
        if (feed is not None and feed >= 0.9 * cmd_mm_min) or asked_s is None:
            return None
        here = track.seg_at(track.x_est_mm)
        if here is None or here.unit_vec is None or bounds.near_a_slow_junction(track, move):
            # Only a cruise is judged (the same unclipped increment repeated): at a turn, a
            # slide or a speed change the estimate follows less closely. Judge again at speed.
            self.seen_at_speed = None
            return None
        acked_end_mm = bounds.acked_end_mm(track)
        if acked_end_mm is None:
            return None
        step_mm = self._step_mm()
        # A machine braking for the end of the acknowledged jogs has no more ahead of it than
        # it needs to stop from the speed it reports.
        speed_mm_s = mm_min_to_mm_s(feed) if feed is not None else track.v_est_mm_s
        age_s = max(ev.now_s - asked_s, 0.0)
        ahead_mm = acked_end_mm - track.x_est_mm
        needed_mm = (
            inc.stop_distance_mm(speed_mm_s, move.accel_mm_s2)
            + speed_mm_s * age_s
            + max(OUTSIDE_LAG_MM, 3.0 * step_mm)
        )
        if ahead_mm <= needed_mm:
            return None
        lag_mm = ev.predicted_mm - track.x_est_mm
        # A report built any time since its `?` may be this much older than now.
        allowed_mm = max(track.v_est_mm_s, move.speed_mm_s) * max(ev.now_s - asked_s, 0.0)
        if feed == 0.0:
            # At rest with path acknowledged ahead: a few steps of estimate error are all.
            margin_mm = 3.0 * step_mm
        else:
            margin_mm = max(
                OUTSIDE_LAG_MM,
                2.0 * step_mm,
                min(move.speed_mm_s * OUTSIDE_LAG_S, OUTSIDE_LAG_CAP_MM),
            )
        if lag_mm > allowed_mm + margin_mm:
            return f"it fell {lag_mm:.2f} mm behind the path it was sent"
        return None

    def line_unread(self, ev: Evidence) -> str | None:
        """The controller answers `?` twice in a row in Jog (each asked after the line was in,
        the second after the first came back; three with other pollers) while one of
        smoothjog's jog lines sits unread, and the jog brakes or rests below its speed.

        The engine keeps planner blocks free, so Grbl reads a jog line at once except in the
        suspend loop of a hold or cancel. Counts every report; its verdict needs a position.
        """
        oldest = ev.oldest
        if (
            oldest is None
            or oldest.owner != ENGINE
            or kind(oldest) != "jog"
            or not oldest.on_wire
            or not ev.runs_as_sent
        ):
            self._unread_entry = None
            return None
        if oldest is not self._unread_entry:
            self._unread_entry = oldest
            self._unread_reports = 0
            tag = oldest.tag
            assert isinstance(tag, LineTag)
            # A report asked before the line reached the controller and was parsed can come
            # back ahead of its `ok` though nothing is wrong: the usual round trip (a low
            # percentile, which a stall does not inflate) covers that.
            self._unread_seen_s = (
                tag.written_by_s + ev.rtt_s if oldest.echo_s is None else oldest.echo_s
            )
        if ev.asked_s is None or ev.asked_s <= self._unread_seen_s:
            return None
        self._unread_reports += 1
        self._unread_seen_s = ev.now_s
        if ev.report.state != "Jog" or self._unread_reports < UNREAD_REPORTS + ev.others_poll:
            return None
        # A planner filled after all (a turn from fast to slow) leaves a line unread with the
        # machine running on at speed: only a jog braking or at rest below its speed, away
        # from a junction it may rest at, is judged.
        feed = ev.report.feed
        cmd_mm_min = mm_s_to_mm_min(ev.commanded.speed_mm_s)
        if (
            ev.jog_unbraked
            or (feed is not None and feed >= 0.95 * cmd_mm_min)
            or bounds.near_a_junction_at_rest(self.track, ev.estimate_before_mm, self.tuning)
        ):
            return None
        if ev.mpos is None:
            return None
        unread_ms = (ev.now_s - oldest.sent_s) * 1000.0
        return f"the controller left a jog line unread for {unread_ms:.0f} ms while answering `?`"

    def off_path(self, ev: Evidence) -> str | None:
        """The report lies off every jog sent while jogging: something moved or stopped the
        machine, and Grbl re-synced its G91 origin."""
        if ev.off_path and ev.phase is Phase.JOGGING:
            return "it left the path smoothjog sent"
        return None

    # ------------------------------------------------------------------ the state signs
    def hold_or_door_input(self, ev: Evidence) -> str | None:
        """A hold or door input that read inactive at rest is active during motion (Grbl acts
        on changes only, firmware-facts §5.4: one active all along is no press)."""
        if ev.pressed and ev.phase in (Phase.JOGGING, Phase.STEPPING, Phase.SETTLING):
            return f"the controller's {ev.pressed} input was pressed: the controller is stopping"
        return None

    def idle_short_of_path_end(self, ev: Evidence) -> str | None:
        """Idle while jogging, short of both the path's end and the acknowledged jogs' end (a
        queue that ran dry rests at the latter; the lines on their way start it again)."""
        track, mpos = self.track, ev.mpos
        if not (
            ev.report.state == "Idle"
            and ev.phase is Phase.JOGGING
            and track.moving_since_ack
            and track.path
            and mpos is not None
        ):
            return None
        at_end, at_planned_end = bounds.at_path_ends(track, mpos)
        if not at_end and not at_planned_end:
            return "it came to rest short of the path's end"
        return None

    def left_jog_states(self, ev: Evidence) -> str | None:
        """A state that reads no jog (Hold, Door, Alarm, Check, Sleep...) while not idle."""
        state = ev.report.state
        if state not in JOG_STATES and state != "Run" and ev.phase is not Phase.IDLE:
            return f"jogging stopped: {state_reason(state)}"
        return None


def stop_off_path(err_steps: float, *, owed: bool, path_faulted: bool) -> Verdict | None:
    """A stop that ends more than OFF_PATH_STOP_STEPS off the path sent, with no outside stop
    seen and no fault that already said why: every line smoothjog sends stops on its path."""
    if err_steps > OFF_PATH_STOP_STEPS and not owed and not path_faulted:
        return Verdict("stop-off-path", "", Reaction.RECORD)
    return None


def who_stopped(report: StatusReport) -> str:
    """Who stopped the jog, as far as the report's Pn tells."""
    pins = report.pins or ""
    if "H" in pins:
        return "the controller's feed-hold input"
    if "D" in pins:
        return "the controller's door input"
    return "a feed hold or jog cancel from outside smoothjog (a button, another program)"


#: The table: precedence is the order within a stage.
SIGNS: tuple[Sign, ...] = (
    Sign(
        "rest-inside-block",
        Stage.MOTION,
        "FS:0 inside an acknowledged block, then a later report still short of its end",
        Reaction.STOP_AND_CANCEL,
        Signs.rest_inside_block,
    ),
    Sign(
        "rest-short-of-acked-path",
        Stage.MOTION,
        "FS:0 in Jog with acknowledged path ahead beyond the committed segments",
        Reaction.STOP_AND_CANCEL,
        Signs.rest_short_of_acked_path,
    ),
    Sign(
        "slowed-inside-block",
        Stage.MOTION,
        "FS below min(v, √(2a·x), √(2a·(L−x−lead))) in the block at the reported place",
        Reaction.STOP_AND_CANCEL,
        Signs.slowed_inside_block,
    ),
    Sign(
        "slowed-since-last-report",
        Stage.MOTION,
        "FS below what the jogs acknowledged by the last report allow from its place and feed",
        Reaction.STOP_AND_CANCEL,
        Signs.slowed_since_last_report,
    ),
    Sign(
        "lag-behind-estimate",
        Stage.MOTION,
        "a cruise seen at speed, now slower and further behind than the report's age explains",
        Reaction.STOP_AND_CANCEL,
        Signs.lag_behind_estimate,
    ),
    Sign(
        "line-unread",
        Stage.MOTION,
        "two `?` answered in Jog (three with other pollers) while a jog line sits unread",
        Reaction.STOP_AND_CANCEL,
        Signs.line_unread,
        every_report=True,
    ),
    Sign(
        "off-path",
        Stage.MOTION,
        "the reported position lies off every jog sent, while jogging",
        Reaction.DESYNC,
        Signs.off_path,
    ),
    Sign(
        "hold-or-door-input",
        Stage.STATE,
        "Pn shows H or D that was not active at rest, during motion",
        Reaction.ABANDON_AND_LATCH,
        Signs.hold_or_door_input,
    ),
    Sign(
        "idle-short-of-path-end",
        Stage.STATE,
        "Idle while jogging, short of the path's end and of the acknowledged jogs' end",
        Reaction.STOP_AND_CANCEL,
        Signs.idle_short_of_path_end,
    ),
    Sign(
        "left-jog-states",
        Stage.STATE,
        "a state other than Idle, Jog or Run while the engine is not idle",
        Reaction.ABANDON,
        Signs.left_jog_states,
    ),
)

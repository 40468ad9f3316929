"""The machine model: what the host knows of the controller, built only from parsed responses.

Everything here is held in machine millimetres (positions, offsets, envelope) and mm/min (feeds),
whatever `$13` says: reports in inches are converted on the way in (firmware-facts §5.5). The model
is changed only by `MachineModel.apply(response)` and a few pure setters, so the handshake, the
session and the tests all drive it the same way.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

from smoothjog.core.defaults import (
    ACCEL_SETTING,
    AXIS_GROUP_SETTINGS,
    DEFAULT_ACCEL_MM_S2,
    DEFAULT_AXES,
    DEFAULT_JUNCTION_DEVIATION_MM,
    DEFAULT_MAX_RATE_MM_MIN,
    DEFAULT_MAX_TRAVEL_MM,
    DEFAULT_PULL_OFF_MM,
    DEFAULT_STATUS_MASK,
    DEFAULT_STEPS_PER_MM,
    MAX_RATE_SETTING,
    MAX_TRAVEL_SETTING,
    STEPS_PER_MM_SETTING,
)
from smoothjog.core.errors import ConfigError, CoreError
from smoothjog.core.firmware import (
    FIRMWARES,
    FirmwareName,
    for_model,
    named_by_info,
    named_by_version,
)
from smoothjog.core.gcode import TravelBox
from smoothjog.core.responses import (
    AlarmReply,
    Banner,
    BuildOptions,
    ErrorReply,
    Feedback,
    GcodeModes,
    HelpReply,
    Message,
    NamedSetting,
    Ok,
    Parameter,
    Response,
    SettingLine,
    StatusReport,
    VersionInfo,
)
from smoothjog.core.units import ALL_AXES, Vec, inch_to_mm

_MAX_AXES = len(ALL_AXES)
#: The planner a host assumes until `[OPT:]` or an Idle `Bf` says otherwise: the smallest any
#: family ships with (Grbl's 15 usable blocks, firmware-facts §4.1, §7). Assuming too few only
#: lengthens increments; assuming too many (grblHAL's 100 on a 35-block build) makes them too
#: short for the stopping distance to fit in the queue (firmware-facts §4.3).
SMALLEST_USABLE_BLOCKS = min(facts.planner_usable_blocks for facts in FIRMWARES.values())


#: Said while jogging is allowed on a machine that looks unhomed (MPos 0 after an unlock).
UNHOMED_WARNING = (
    "the machine looks unhomed (MPos 0 after an unlock): soft limits count from where it was"
    " switched on; jog it off a limit switch if you must, then home it with $H"
)


@dataclass(frozen=True, slots=True)
class KeepOut:
    """A named box in machine mm that jogs must not enter (a vise, a clamp, a probe dock).

    The corners may name fewer axes than the machine has: the zone is then unbounded along the
    others, so a zone given in X and Y blocks every Z height above that area. Bounds may be
    infinite. `source` names the config file the zone came from, for messages only.
    """

    name: str
    min_mm: Vec
    max_mm: Vec
    source: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        """Refuse zones whose corners disagree in length or are inside out."""
        if len(self.min_mm) != len(self.max_mm):
            raise CoreError(
                f"keep-out zone {self.name!r} has corners with {len(self.min_mm)} and "
                f"{len(self.max_mm)} axes; give both corners the same number of coordinates"
            )
        for i, (lo, hi) in enumerate(zip(self.min_mm, self.max_mm, strict=True)):
            if not lo <= hi:
                raise CoreError(
                    f"keep-out zone {self.name!r} runs from {lo} to {hi} mm on axis {_letter(i)}; "
                    "the minimum must not exceed the maximum (swap them)"
                )

    @property
    def box(self) -> TravelBox:
        """The zone as a box over the axes it names (both faces inclusive)."""
        return TravelBox(self.min_mm, self.max_mm)

    @property
    def where(self) -> str:
        """Where the zone was written, as messages name it: `FILE: [keepout 'vise']`."""
        section = f"[keepout {self.name!r}]"
        return f"{self.source}: {section}" if self.source else section

    def contains(self, point_mm: Sequence[float]) -> bool:
        """True when the point lies inside or on the zone; axes the zone lacks are free."""
        return all(
            lo <= p <= hi for lo, hi, p in zip(self.min_mm, self.max_mm, point_mm, strict=False)
        )

    def crosses(self, start_mm: Sequence[float], end_mm: Sequence[float]) -> bool:
        """True when the straight move from start to end touches the zone anywhere."""
        # Slab test: clip the segment's parameter t in [0, 1] against each axis's slab. Axes the
        # zone does not name are left out by zip, which is what "unbounded" means there.
        t_lo, t_hi = 0.0, 1.0
        for lo, hi, a, b in zip(self.min_mm, self.max_mm, start_mm, end_mm, strict=False):
            d = b - a
            if d == 0.0:
                if not lo <= a <= hi:
                    return False
                continue
            # An infinite bound gives t = ±inf with the right sign (positions are finite, so no
            # inf - inf), which the min/max below treat as a face that is never reached.
            t0, t1 = (lo - a) / d, (hi - a) / d
            t_lo, t_hi = max(t_lo, min(t0, t1)), min(t_hi, max(t0, t1))
            if t_lo > t_hi:
                return False
        return True


def _letter(index: int) -> str:
    """The axis letter of an index, or a number past the ninth axis."""
    return ALL_AXES[index] if index < _MAX_AXES else f"#{index}"


@dataclass(frozen=True, slots=True)
class Settings:
    """The `$$` settings a jog host needs, typed; unknown ones take the 1.1h defaults
    (firmware-facts §0)."""

    status_mask: int = DEFAULT_STATUS_MASK  # $10: bit0 MPos (else WPos), bit1 Bf
    junction_deviation_mm: float = DEFAULT_JUNCTION_DEVIATION_MM  # $11
    report_inches: bool = False  # $13
    soft_limits: bool = False  # $20
    hard_limits: bool = False  # $21
    homing: bool = False  # $22
    homing_dir_mask: int = 0  # $23: bit i set = axis i homes toward negative (firmware-facts §2)
    pull_off_mm: float = DEFAULT_PULL_OFF_MM  # $27
    steps_per_mm: Vec = (DEFAULT_STEPS_PER_MM,) * DEFAULT_AXES
    max_rate_mm_min: Vec = (DEFAULT_MAX_RATE_MM_MIN,) * DEFAULT_AXES
    accel_mm_s2: Vec = (DEFAULT_ACCEL_MM_S2,) * DEFAULT_AXES
    max_travel_mm: Vec = (DEFAULT_MAX_TRAVEL_MM,) * DEFAULT_AXES
    # Every numbered line as printed (grblHAL/FluidNC extras included), sorted by number.
    raw: tuple[tuple[int, str], ...] = ()
    # `$Name=value` lines (FluidNC's named settings), in arrival order.
    named: tuple[tuple[str, str], ...] = ()

    @property
    def n_axes(self) -> int:
        """How many axes the per-axis groups ($100...) cover."""
        return len(self.steps_per_mm)

    def raw_value(self, number: int) -> str | None:
        """The text of setting $number as the controller printed it, if it did."""
        return dict(self.raw).get(number)

    def with_line(self, number: int, text: str) -> Settings:
        """A copy with `$number=text` added or replaced."""
        raw = dict(self.raw)
        raw[number] = text
        return Settings.from_raw(raw, self.named)

    def with_named(self, name: str, text: str) -> Settings:
        """A copy with the named setting `$name=text` added or replaced."""
        named = dict(self.named)
        named[name] = text
        return Settings.from_raw(dict(self.raw), tuple(named.items()))

    @classmethod
    def from_raw(cls, raw: Mapping[int, str], named: tuple[tuple[str, str], ...] = ()) -> Settings:
        """Type the numbered settings; a missing or non-numeric value keeps its default."""
        values: dict[int, float] = {}
        for number, text in raw.items():
            try:
                number_value = float(text)
            except ValueError:
                continue
            if math.isfinite(number_value):
                values[number] = number_value

        def flag(number: int) -> bool:
            # grblHAL packs more flags into $20/$22 (firmware-facts §7); bit 0 is still the enable.
            return int(values.get(number, 0.0)) & 1 == 1

        n_axes = _axis_count(values)

        def group(base: int, default: float) -> Vec:
            return tuple(values.get(base + i, default) for i in range(n_axes))

        return cls(
            status_mask=int(values.get(10, DEFAULT_STATUS_MASK)),
            junction_deviation_mm=values.get(11, DEFAULT_JUNCTION_DEVIATION_MM),
            report_inches=flag(13),
            soft_limits=flag(20),
            hard_limits=flag(21),
            homing=flag(22),
            homing_dir_mask=int(values.get(23, 0.0)),
            pull_off_mm=values.get(27, DEFAULT_PULL_OFF_MM),
            steps_per_mm=group(STEPS_PER_MM_SETTING, DEFAULT_STEPS_PER_MM),
            max_rate_mm_min=group(MAX_RATE_SETTING, DEFAULT_MAX_RATE_MM_MIN),
            accel_mm_s2=group(ACCEL_SETTING, DEFAULT_ACCEL_MM_S2),
            max_travel_mm=group(MAX_TRAVEL_SETTING, DEFAULT_MAX_TRAVEL_MM),
            raw=tuple(sorted(raw.items())),
            named=named,
        )

    def for_axes(self, n_axes: int) -> Settings:
        """A copy whose per-axis tuples have exactly n_axes entries (defaults fill the gap)."""

        def fit(values: Vec, default: float) -> Vec:
            return tuple(values[:n_axes]) + (default,) * max(0, n_axes - len(values))

        return replace(
            self,
            steps_per_mm=fit(self.steps_per_mm, DEFAULT_STEPS_PER_MM),
            max_rate_mm_min=fit(self.max_rate_mm_min, DEFAULT_MAX_RATE_MM_MIN),
            accel_mm_s2=fit(self.accel_mm_s2, DEFAULT_ACCEL_MM_S2),
            max_travel_mm=fit(self.max_travel_mm, DEFAULT_MAX_TRAVEL_MM),
        )


def _axis_count(values: Mapping[int, float]) -> int:
    """Axes covered by the per-axis groups: the longest run from $100, $110, $120 or $130."""
    longest = 0
    for base in AXIS_GROUP_SETTINGS:
        count = 0
        # grblHAL and FluidNC number up to 9 axes as $100..$108 (firmware-facts §7).
        while count < _MAX_AXES and base + count in values:
            count += 1
        longest = max(longest, count)
    return longest if longest > 0 else DEFAULT_AXES


@dataclass(frozen=True, slots=True)
class ModalState:
    """The parser modes from the last `[GC:]` line that matter to a jog host."""

    units: str = "G21"  # G20 inches / G21 mm
    distance: str = "G90"  # G90 absolute / G91 incremental
    wcs: str = "G54"  # G54..G59 (grblHAL adds G59.1..G59.3)
    feed_mm_min: float = 0.0
    tool: int = 0
    words: tuple[str, ...] = ()


_REPLIES = (
    Ok,
    ErrorReply,
    AlarmReply,
    StatusReport,
    SettingLine,
    NamedSetting,
    VersionInfo,
    BuildOptions,
    GcodeModes,
    Parameter,
    HelpReply,
)
_WCS_WORDS = frozenset({"G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3"})


@dataclass(slots=True)
class MachineModel:
    """What the host knows of the controller; change it only through apply() and the setters."""

    firmware: FirmwareName = "grbl"
    version: str | None = None
    build: str | None = None
    option_codes: str = ""
    settings: Settings = field(default_factory=Settings)
    state: str | None = None  # None until a status report (or after a reset)
    substate: int | None = None
    mpos_mm: Vec | None = None
    wpos_mm: Vec | None = None
    wco_mm: Vec | None = None  # the last WCO received: reports carry it only now and then
    feed_mm_min: float | None = None
    spindle_rpm: float | None = None
    buffer: tuple[int, int] | None = None  # last Bf: (planner blocks free, RX bytes free)
    overrides: tuple[int, int, int] = (100, 100, 100)  # (feed %, rapid %, spindle %)
    pins: str = ""
    accessories: str = ""
    line_number: int | None = None
    modal: ModalState = field(default_factory=ModalState)
    offsets_mm: dict[str, Vec] = field(default_factory=dict)  # `$#`: G54..G92, TLO, PRB
    probe_ok: bool | None = None
    reset_count: int = 0
    last_alarm: int | None = None
    last_error: int | None = None
    last_message: str | None = None
    keep_outs: tuple[KeepOut, ...] = ()
    #: Why jogging must wait, when the reason is another program's and the controller's state
    #: may not show it (a CNCjs job between two of its lines reports Idle); None: no such reason.
    jog_lock: str | None = None
    #: Status reports whose axis count differed from the controller's (damaged on the wire).
    damaged_reports: int = 0
    _axis_letters: tuple[str, ...] | None = field(default=None, init=False, repr=False)
    _opt_blocks: int | None = field(default=None, init=False, repr=False)
    _opt_rx_bytes: int | None = field(default=None, init=False, repr=False)
    # The largest Bf free-block count of an Idle report since the last banner (None: none yet).
    _idle_planner_free_max: int | None = field(default=None, init=False, repr=False)
    _report_axes: int | None = field(default=None, init=False, repr=False)
    # Any reply seen: a banner after this is a reset, not the power-up one.
    _talked: bool = field(default=False, init=False, repr=False)
    # The critical alarm the controller waits in for a reset (None: none since the banner).
    _critical_alarm: int | None = field(default=None, init=False, repr=False)
    # A `$H` line is unanswered (homing_sent), and the state the reports showed before it.
    _homing: bool = field(default=False, init=False, repr=False)
    _state_before_homing: str | None = field(default=None, init=False, repr=False)

    # --- derived facts ---------------------------------------------------------------------

    @property
    def n_axes(self) -> int:
        """Axis count: from status reports when seen, else from the `$$` groups, else 3."""
        if self._axis_letters is not None:
            return len(self._axis_letters)
        if self._report_axes is not None:
            return self._report_axes
        return self.settings.n_axes

    @property
    def axis_letters(self) -> tuple[str, ...]:
        """The axis letters in report order (X Y Z A B C U V W unless set)."""
        if self._axis_letters is not None:
            return self._axis_letters
        return ALL_AXES[: self.n_axes]

    @property
    def reset_needed(self) -> bool:
        """True from a critical `ALARM:N` (Grbl 1.1h: 1 hard limit, 2 soft limit) until the next
        banner: the controller reads no line until it is reset (firmware-facts §5.6a)."""
        return self._critical_alarm is not None

    @property
    def critical_alarm(self) -> int | None:
        """The code of the alarm that makes reset_needed True, else None."""
        return self._critical_alarm

    @property
    def homing_force_set_origin(self) -> bool:
        """Built with HOMING_FORCE_SET_ORIGIN: option letter `Z` in `[OPT:]` (firmware-facts §2)."""
        # option_codes holds one character per option, punctuation included (`VZL+*$#`), so
        # this is a test for the letter, never for a substring of some longer word.
        return "Z" in self.option_codes

    @property
    def planner_blocks(self) -> int:
        """Planner size as the firmware states it: [OPT:] when known, else the smallest likely."""
        if self._opt_blocks is not None:
            return self._opt_blocks
        # Unknown (no `$I` yet, or an [OPT:] of letters only, as FluidNC prints): never a family's
        # default such as grblHAL's 100, which a build may have lowered (`$398`, firmware-facts §7).
        return SMALLEST_USABLE_BLOCKS + for_model(self).planner_blocks_hidden

    @property
    def planner_usable_blocks(self) -> int:
        """Blocks a host can fill: the largest Idle `Bf` seen, else what [OPT:] implies."""
        # In Idle the planner is empty, so Bf's first value is every block a host can fill
        # (firmware-facts §4.4; FluidNC's is planner_blocks - 1, §7). That measurement beats the
        # stated size both ways: a smaller one lowers it, a larger one raises it. Outside Idle
        # blocks may be queued and Bf only bounds the size from below, so it is not used. The
        # largest Idle value is kept because a report can catch a line just being planned.
        if self._idle_planner_free_max is not None:
            return self._idle_planner_free_max
        return self.planner_blocks - for_model(self).planner_blocks_hidden

    @property
    def rx_buffer_bytes(self) -> int:
        """The controller's line-receive buffer in bytes: [OPT:] when known, else its default."""
        if self._opt_rx_bytes is not None:
            return self._opt_rx_bytes
        return for_model(self).rx_buffer_bytes

    def axis_max_rate_mm_min(self) -> Vec:
        """`$110...` per axis in mm/min."""
        return self.settings.for_axes(self.n_axes).max_rate_mm_min

    def axis_accel_mm_s2(self) -> Vec:
        """`$120...` per axis in mm/s²."""
        return self.settings.for_axes(self.n_axes).accel_mm_s2

    def steps_per_mm(self) -> Vec:
        """`$100...` per axis in steps/mm."""
        return self.settings.for_axes(self.n_axes).steps_per_mm

    def soft_limit_envelope(self) -> TravelBox | None:
        """The box a jog target must stay in when soft limits are on ($20=1), else None."""
        if not self.settings.soft_limits:
            return None
        settings = self.settings.for_axes(self.n_axes)
        lows: list[float] = []
        highs: list[float] = []
        for axis, travel_mm in enumerate(settings.max_travel_mm):
            # Facts §2: the default build keeps all of machine space negative, so every axis
            # runs -$13x <= t <= 0. Only a HOMING_FORCE_SET_ORIGIN build (`Z`) flips an axis
            # whose $23 bit is set (homes toward negative) to 0 <= t <= +$13x; axes with the
            # bit clear stay -$13x..0 even in that build. Both ends are inclusive.
            flipped = self.homing_force_set_origin and bool(settings.homing_dir_mask >> axis & 1)
            span_mm = abs(travel_mm)
            lows.append(0.0 if flipped else -span_mm)
            highs.append(span_mm if flipped else 0.0)
        return TravelBox(tuple(lows), tuple(highs))

    def looks_unhomed(self) -> bool:
        """True when soft limits are on and MPos is exactly 0 on every axis (power-up, $X)."""
        # Grbl keeps no "homed" flag (firmware-facts §2): after power-up and $X, MPos is 0,0,0, the
        # corner of the default envelope, where every + jog gets error:15. A homed default build
        # sits at -$27 or -$13x+$27 instead. With HOMING_FORCE_SET_ORIGIN a homed machine is at 0
        # too, so the two cannot be told apart and this says False rather than cry wolf.
        if not self.settings.soft_limits or self.homing_force_set_origin:
            return False
        mpos = self.mpos_mm
        # count(), not a generator: the engine asks before every line it sends.
        return mpos is not None and mpos.count(0.0) == len(mpos)

    def keep_out_at(self, point_mm: Sequence[float]) -> KeepOut | None:
        """The first keep-out zone containing the point, if any."""
        return next((zone for zone in self.keep_outs if zone.contains(point_mm)), None)

    # --- pure setters -----------------------------------------------------------------------

    def homing_sent(self) -> None:
        """A `$H` line went to the controller: the state is Home until its reply.

        Grbl 1.1h reads no line and makes no status report during the cycle; it answers a `?`
        asked meanwhile once, as the cycle ends, still in Home (firmware-facts §5.6a). A report of
        Idle or Alarm while the line waits was therefore made before the line was read.
        """
        if not self._homing:
            self._state_before_homing = self.state
        self._homing = True
        self.state, self.substate = "Home", None

    def homing_answered(self, ok: bool) -> None:
        """The `$H` line got its reply: ok after the cycle (Grbl set Idle just before it), an
        error when it never began (the state is then the one before it). The host asks for a
        report at once, which shows where another firmware ended (grblHAL may stay in Alarm)."""
        if not self._homing:
            return
        self._homing = False
        if self.state == "Home":
            self.state = "Idle" if ok else self._state_before_homing

    def set_keep_outs(self, zones: Sequence[KeepOut]) -> None:
        """Replace the keep-out zones (from the config); one naming an axis the machine lacks
        is refused."""
        n_axes = self.n_axes
        for zone in zones:
            named = len(zone.min_mm)
            if named > n_axes:
                # Fewer axes are fine (unbounded along the rest), but a bound on an axis the
                # machine does not have means the config was written for another machine.
                extra = " ".join(_letter(i) for i in range(n_axes, named))
                raise ConfigError(
                    f"{zone.where} min_mm has {named} numbers"
                    f" ({' '.join(_letter(i) for i in range(named))}) but the machine has"
                    f" {n_axes} axes ({' '.join(self.axis_letters)}), so there is no axis"
                    f" {extra} to keep out of: remove those numbers from min_mm and max_mm, or"
                    " use the config written for this machine"
                )
        self.keep_outs = tuple(zones)

    def set_axis_letters(self, letters: Sequence[str]) -> None:
        """Name the axes (e.g. X Y Z U V W on a grblHAL build); the report cannot tell."""
        upper = tuple(letter.upper() for letter in letters)
        unknown = [letter for letter in upper if letter not in ALL_AXES]
        if unknown or len(set(upper)) != len(upper) or not upper:
            raise CoreError(
                f"axis letters {list(letters)} are not distinct letters from {''.join(ALL_AXES)}; "
                "list each axis once, in the order the controller reports them"
            )
        self._axis_letters = upper

    def set_settings(self, settings: Settings) -> None:
        """Replace all settings at once (e.g. from a saved `$$` listing)."""
        self.settings = settings

    # --- the one way in from the wire -------------------------------------------------------

    def apply(self, response: Response) -> None:
        """Fold one parsed response into the model."""
        if response.__class__ is Ok:
            self._talked = True  # the reply to almost every line: one test, not the whole chain
            return
        if isinstance(response, StatusReport):
            self._apply_status(response)
        elif isinstance(response, Banner):
            self._apply_banner(response)
        elif isinstance(response, SettingLine):
            self.settings = self.settings.with_line(response.number, response.raw)
        elif isinstance(response, NamedSetting):
            self.settings = self.settings.with_named(response.name, response.raw)
        elif isinstance(response, BuildOptions):
            self.option_codes = response.codes
            self._opt_blocks = response.planner_blocks
            self._opt_rx_bytes = response.rx_buffer_bytes
        elif isinstance(response, VersionInfo):
            # The banner's version is the cleaner one; take $I's only when no banner was seen.
            self.version = self.version or response.version
            self.build = response.build or None
            self.firmware = named_by_version(response.version) or self.firmware
        elif isinstance(response, Feedback):
            # grblHAL's `$I` names itself; its compatibility banner may have said plain "Grbl".
            self.firmware = named_by_info(response.text) or self.firmware
        elif isinstance(response, GcodeModes):
            self._apply_modes(response)
        elif isinstance(response, Parameter):
            self._apply_parameter(response)
        elif isinstance(response, AlarmReply):
            # An ALARM:N always leaves the controller in Alarm (firmware-facts §2, §3.4, §5.6).
            self.last_alarm = response.code
            self.state, self.substate = "Alarm", None
            self._homing = False  # a homing cycle that raised an alarm has ended
            if response.code in for_model(self).critical_alarms:
                self._critical_alarm = response.code
        elif isinstance(response, ErrorReply):
            self.last_error = response.code
        elif isinstance(response, Message):
            self.last_message = response.text
        # Only a reply to something the host asked proves a session is under way; the blank line,
        # noise and boot-time [MSG:] chatter (FluidNC) that precede a power-up banner do not.
        if isinstance(response, _REPLIES):
            self._talked = True

    def _to_mm(self, value: float) -> float:
        """A report-unit length or rate in mm (or mm/min): $13=1 reports inches (firmware-facts
        §5.5)."""
        # Adding 0.0 turns Grbl's rounded "-0.000" into a plain zero.
        return (inch_to_mm(value) if self.settings.report_inches else value) + 0.0

    def _vec_to_mm(self, values: Sequence[float]) -> Vec:
        """A report-unit vector in mm."""
        return tuple(self._to_mm(v) for v in values)

    def _apply_status(self, report: StatusReport) -> None:
        """Take state, positions and the optional fields; derive the missing frame from WCO."""
        self.state, self.substate = report.state, report.substate
        if self._homing and report.state in ("Idle", "Alarm"):
            self.state = "Home"  # made before the `$H` line was read (homing_sent)
        if report.wco is not None:
            self.wco_mm = self._vec_to_mm(report.wco)
        mpos = self._vec_to_mm(report.mpos) if report.mpos is not None else None
        wpos = self._vec_to_mm(report.wpos) if report.wpos is not None else None
        wco = self.wco_mm
        # WPos = MPos - WCO (firmware-facts §5.4); a frame is derived only when the axis counts
        # agree.
        if mpos is not None and wpos is None and wco is not None and len(wco) == len(mpos):
            wpos = tuple(m - o + 0.0 for m, o in zip(mpos, wco, strict=True))
        if wpos is not None and mpos is None and wco is not None and len(wco) == len(wpos):
            mpos = tuple(w + o + 0.0 for w, o in zip(wpos, wco, strict=True))
        axes = len(mpos if mpos is not None else wpos or ())
        if axes and self._report_axes and axes != self._report_axes:
            # The controller's axis count does not change mid-session: a report with another
            # count was damaged on the wire (a lost comma or digit). Keep the last positions.
            self.damaged_reports += 1
        elif mpos is not None or wpos is not None:
            self.mpos_mm, self.wpos_mm = mpos, wpos
            self._report_axes = axes
        if report.feed is not None:
            self.feed_mm_min = self._to_mm(report.feed)
        self.spindle_rpm = report.spindle_speed
        if report.buffer is not None:
            self.buffer = report.buffer
            if report.state == "Idle":
                free = report.buffer[0]
                seen = self._idle_planner_free_max
                self._idle_planner_free_max = free if seen is None else max(seen, free)
        self.line_number = report.line_number
        # Pn is printed only while some pin is triggered, so its absence means none (firmware-facts
        # §5.4).
        self.pins = report.pins or ""
        if report.overrides is not None:
            self.overrides = report.overrides
            # A: rides only with Ov and only while something is on; with Ov and no A, all is off.
            self.accessories = report.accessories or ""

    def _apply_banner(self, banner: Banner) -> None:
        """A welcome line: power-up on first sight, else a reset with its state wiped (§3.4)."""
        if self._talked:
            self.reset_count += 1
        self.firmware = banner.firmware
        self.version = banner.version
        # After a reset: state unknown, buffers empty, parser at defaults with G92 and TLO
        # cleared, overrides 100 %; MPos is kept (firmware-facts §3.4). WCO changed with G92/TLO,
        # and the first report after reset carries it again (firmware-facts §5.4), so forget ours.
        self.state, self.substate = None, None
        self._critical_alarm = None
        self._homing = False  # the reset ended the cycle and dropped the line
        self.wpos_mm, self.wco_mm = None, None
        self.buffer = None
        self._report_axes = None  # a rebuilt or reconfigured controller may have other axes
        # A reboot may come back with another planner size (grblHAL's `$398` takes effect only
        # then, firmware-facts §7): measure it again in the next Idle report.
        self._idle_planner_free_max = None
        self.feed_mm_min = None
        self.overrides = (100, 100, 100)
        self.modal = ModalState()
        for name in ("G92", "TLO"):
            if name in self.offsets_mm:
                self.offsets_mm[name] = tuple(0.0 for _ in self.offsets_mm[name])
        self._talked = False

    def _apply_modes(self, modes: GcodeModes) -> None:
        """Keep units, distance mode, WCS, feed and tool from `[GC:]`."""
        modal = ModalState(
            words=modes.words,
            feed_mm_min=self._to_mm(modes.feed) if modes.feed is not None else 0.0,
            tool=modes.tool if modes.tool is not None else 0,
        )
        for word in modes.words:
            if word in ("G20", "G21"):
                modal = replace(modal, units=word)
            elif word in ("G90", "G91"):
                modal = replace(modal, distance=word)
            elif word in _WCS_WORDS:
                modal = replace(modal, wcs=word)
        self.modal = modal

    def _apply_parameter(self, parameter: Parameter) -> None:
        """Keep one `$#` line in mm; PRB also records whether the probe triggered."""
        self.offsets_mm[parameter.name] = self._vec_to_mm(parameter.values)
        if parameter.name == "PRB":
            self.probe_ok = parameter.probe_ok

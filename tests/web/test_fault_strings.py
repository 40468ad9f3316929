"""Every sentence the server sends the page (faults, hints, refusals, reasons) reads in Chinese.

The sentences are not listed here: they are taken from the code that makes them with `ast` (every
`_fault_now` of the engine, every JogBuildError, the motion gate's refusals and stop sentences,
the arbiter's latches and refusals, the server's and the machine control's refusals, the
commands' `doing`, the host's and the link's losses, ...) and built the way that code builds
them, each placeholder filled from SAMPLES or from the assignments, helpers and tables the code
uses (the alarm and error tables, `_STATE_REASONS`, `_PIN_NAMES`, the command catalogue). Each
built sentence must match a pattern of SERVER_ZH in static/i18n.js (read from its lines) or be an
alarm or error code, and its Chinese, put together by the same rules as translateServer(), must
keep no English word but Grbl's words, units and the values passed through as sent. So a new
fault without a translation fails here. Where node is installed, the real translateServer() gives
the same Chinese as the rules here.
"""

from __future__ import annotations

import ast
import builtins
import importlib
import itertools
import json
import re
import shutil
import subprocess
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from smoothjog.core.codes import ALARM_CODES, ERROR_CODES
from smoothjog.core.errors import InputRefused, JogBuildError
from smoothjog.core.intents import StopIntent
from smoothjog.inputs.base import KIND_NOUNS
from smoothjog.web.server import STATIC_DIR
from tests.web.conftest import DESKTOP, OpenPage, StartPendant

SRC = Path(__file__).parents[2] / "src" / "smoothjog"
I18N = STATIC_DIR / "i18n.js"

# ------------------------------------------------------------------------- i18n.js, read


@dataclass(frozen=True)
class Tables:
    """What translateServer() uses, read from i18n.js."""

    server: list[tuple[re.Pattern[str], str, str]]  # (pattern, template, the JS source)
    what: dict[str, str]
    states: dict[str, str]
    alarms: dict[int, list[str]]
    errors: dict[int, list[str]]
    unknown: str
    labels: dict[str, str]
    code: re.Pattern[str]


def _block(js: str, start: str, end: str) -> list[str]:
    head = js.index(start)
    return js[head + len(start) : js.index(end, head)].splitlines()


def _compile(source: str) -> re.Pattern[str]:
    # JS regexes without the u flag: \d and \w are ASCII; `\/` is a plain slash in both.
    return re.compile(source, re.ASCII)


@cache
def tables() -> Tables:
    js = I18N.read_text(encoding="utf-8")
    server = []
    entry = re.compile(r'^\s*\[/(?P<re>.+)/, (?P<tpl>"(?:[^"\\]|\\.)*")\],$')
    for line in _block(js, "const SERVER_ZH = [", "\n];"):
        if line.strip().startswith("//") or not line.strip():
            continue
        m = entry.match(line)
        assert m, f"a SERVER_ZH line this test cannot read: {line!r}"
        server.append((_compile(m["re"]), json.loads(m["tpl"]), m["re"]))
    what = {}
    for line in _block(js, "const WHAT_ZH = {", "\n};"):
        if line.strip().startswith("//") or not line.strip():
            continue
        m = re.match(r'^\s*(?:"(?P<q>[^"]+)"|(?P<w>\w+)): (?P<v>".*"),$', line)
        assert m, f"a WHAT_ZH line this test cannot read: {line!r}"
        what[m["q"] or m["w"]] = json.loads(m["v"])
    zh = js[js.index("\n  zh: {") :]
    states = dict(re.findall(r'^\s*"st\.(\w+)": "(.*)",$', zh, re.M))
    assert "Idle" in states
    codes: dict[str, dict[int, list[str]]] = {}
    for name in ("ALARMS_ZH", "ERRORS_ZH"):
        rows = {}
        for line in _block(js, f"const {name} = {{", "\n};"):
            if not line.strip():
                continue
            m = re.match(r"^\s*(\d+): (.+),$", line)
            assert m, f"a {name} line this test cannot read: {line!r}"
            value = json.loads(m[2])
            rows[int(m[1])] = value if isinstance(value, list) else [value]
        codes[name] = rows
    unknown = re.search(r"^const UNKNOWN_CODE_ZH = (\".*\");$", js, re.M)
    labels = re.search(r'^const CODE_LABEL_ZH = \{ ALARM: (".*"), error: (".*") \};$', js, re.M)
    code = re.search(r"^const CODE = /(.+)/;$", js, re.M)
    assert unknown, "i18n.js has no UNKNOWN_CODE_ZH"
    assert labels, "i18n.js has no CODE_LABEL_ZH"
    assert code, "i18n.js has no CODE"
    return Tables(
        server=server,
        what=what,
        states=states,
        alarms=codes["ALARMS_ZH"],
        errors=codes["ERRORS_ZH"],
        unknown=json.loads(unknown[1]),
        labels={"ALARM": json.loads(labels[1]), "error": json.loads(labels[2])},
        code=_compile(code[1]),
    )


def translate(s: str) -> str:
    """translateServer() in Chinese, by the same rules (test_node_agrees checks they are)."""
    t = tables()
    if s == "":
        return s
    if s in t.what:
        return t.what[s]
    if s in t.states:
        return t.states[s]
    m = t.code.match(s)
    if m:
        rows = t.alarms if m[1] == "ALARM" else t.errors
        what, *todo = rows.get(int(m[2]), [t.unknown])
        head = f"{t.labels[m[1]]} {int(m[2])}：{what}"
        if m[3] is None:
            return head
        hint = translate(m[3])
        if hint != m[3]:
            return f"{head}——{hint}"
        return f"{head}，{todo[0]}" if todo else head
    for pattern, template, _ in t.server:
        found = pattern.search(s)
        if found:

            def part(g: re.Match[str], f: re.Match[str] = found) -> str:
                return translate(_group(f, int(g[1])))

            return re.sub(r"\{(\d)\}", part, template)
    return s


def _group(m: re.Match[str], i: int) -> str:
    return (m[i] or "") if i <= m.re.groups else ""


def first_pattern(s: str) -> str | None:
    """The source of the pattern that translates s, "CODE" for a code, None for none."""
    t = tables()
    if s in t.what or s in t.states:
        return "WHAT_ZH"
    if t.code.match(s):
        return "CODE"
    return next((src for pattern, _, src in t.server if pattern.search(s)), None)


# ------------------------------------------------------------------------- building the sentences


class Skip(Exception):  # noqa: N818 -- a control-flow signal, not an error
    """The text is someone else's (a str(exc) passed on), covered where it is made."""


class Missing(Exception):  # noqa: N818
    """A placeholder this test has no value for: add one to SAMPLES."""


SKIP = object()


@dataclass
class Module:
    """One source file: its tree, the functions enclosing each node, its real globals."""

    rel: str
    tree: ast.Module = field(init=False)
    globals: dict[str, Any] = field(init=False)
    enclosing: dict[int, ast.FunctionDef | ast.AsyncFunctionDef] = field(init=False)
    functions: dict[str, list[ast.FunctionDef | ast.AsyncFunctionDef]] = field(init=False)

    def __post_init__(self) -> None:
        self.tree = ast.parse((SRC / self.rel).read_text(encoding="utf-8"))
        name = "smoothjog." + self.rel.removesuffix(".py").replace("/", ".")
        self.globals = dict(vars(importlib.import_module(name)))
        self.enclosing = {}
        self.functions = {}

        def visit(node: ast.AST, func: ast.FunctionDef | ast.AsyncFunctionDef | None) -> None:
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                self.functions.setdefault(node.name, []).append(node)
                func = node
            if func is not None:
                self.enclosing[id(node)] = func
            for child in ast.iter_child_nodes(node):
                visit(child, func)

        visit(self.tree, None)

    @property
    def stem(self) -> str:
        return Path(self.rel).stem

    def where(self, node: ast.AST) -> str:
        return f"{self.rel}:{getattr(node, 'lineno', '?')}"


@cache
def module(rel: str) -> Module:
    return Module(rel)


def _locals(func: ast.FunctionDef | ast.AsyncFunctionDef) -> set[str]:
    a = func.args
    names = {x.arg for x in [*a.posonlyargs, *a.args, *a.kwonlyargs]}
    names |= {x.arg for x in (a.vararg, a.kwarg) if x is not None}
    for node in ast.walk(func):
        if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.ExceptHandler) and node.name:
            names.add(node.name)
    return names


def _free_names(expr: ast.expr) -> list[str]:
    bound = set()
    for node in ast.walk(expr):
        if isinstance(node, ast.comprehension):
            bound |= {n.id for n in ast.walk(node.target) if isinstance(n, ast.Name)}
        elif isinstance(node, ast.Lambda):
            bound |= {x.arg for x in node.args.args}
    loaded = {
        n.id for n in ast.walk(expr) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)
    }
    return sorted(loaded - bound)


def _self_method(mod: Module, expr: ast.expr) -> str | None:
    """The name of a method of this module that expr calls on self, or None."""
    if (
        isinstance(expr, ast.Call)
        and isinstance(expr.func, ast.Attribute)
        and isinstance(expr.func.value, ast.Name)
        and expr.func.value.id == "self"
        and expr.func.attr in mod.functions
    ):
        return expr.func.attr
    return None


def _assignments(func: ast.AST, name: str) -> list[tuple[ast.expr, int | None]]:
    """Each value assigned to name in func, with its index when unpacked from a tuple."""
    out: list[tuple[ast.expr, int | None]] = []
    for node in ast.walk(func):
        if isinstance(node, ast.Assign):
            for target in node.targets:
                if isinstance(target, ast.Name) and target.id == name:
                    out.append((node.value, None))
                elif isinstance(target, ast.Tuple):
                    for i, elt in enumerate(target.elts):
                        if isinstance(elt, ast.Name) and elt.id == name:
                            out.append((node.value, i))
        elif (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and node.target.id == name
            and node.value is not None
        ):
            out.append((node.value, None))
    return out


def _samples(mod: Module, func: ast.AST, name: str) -> list[Any] | None:
    fname = getattr(func, "name", "")
    for key in (f"{mod.stem}.{fname}.{name}", f"{mod.stem}.{name}"):
        if key in SAMPLES:
            value = SAMPLES[key]
            if value is SKIP:
                raise Skip(key)
            return list(value() if callable(value) else value)
    return None


Env = dict[str, Any]


def _values(mod: Module, func: Any, name: str, env: Env, depth: int) -> Iterator[tuple[Any, Env]]:
    sampled = _samples(mod, func, name)
    if sampled is not None:
        for value in sampled:
            yield value, env
        return
    alternatives = _assignments(func, name)
    if not alternatives or depth > 8:
        raise Missing(f"{mod.stem}.{func.name}.{name} ({mod.where(func)})")
    for value_expr, index in alternatives:
        method = _self_method(mod, value_expr)
        if method is not None:
            for ret in returned(mod, method, index):
                for v in build(mod, mod.functions[method][0], ret, {}, depth + 1):
                    yield v, env
        elif index is None:
            for v, env2 in _build_envs(mod, func, value_expr, env, depth + 1):
                yield v, env2
        elif isinstance(value_expr, ast.Tuple):
            for v, env2 in _build_envs(mod, func, value_expr.elts[index], env, depth + 1):
                yield v, env2
        else:
            raise Missing(f"{mod.stem}.{func.name}.{name}: unpacked from {ast.unparse(value_expr)}")


def _envs(mod: Module, func: Any, names: list[str], env: Env, depth: int) -> Iterator[Env]:
    if not names:
        yield env
        return
    name, rest = names[0], names[1:]
    if name in env:
        yield from _envs(mod, func, rest, env, depth)
        return
    for value, env2 in _values(mod, func, name, env, depth):
        yield from _envs(mod, func, rest, {**env2, name: value}, depth)


def _build_envs(
    mod: Module, func: Any, expr: ast.expr, env: Env, depth: int = 0
) -> Iterator[tuple[Any, Env]]:
    method = _self_method(mod, expr)
    if method is not None:
        # What a helper of the module returns, its parameters from SAMPLES.
        for ret in returned(mod, method):
            for value in build(mod, mod.functions[method][0], ret, {}, depth + 1):
                yield value, env
        return
    local = _locals(func) if func is not None else set()
    names = []
    for name in _free_names(expr):
        if name in local:
            names.append(name)
        elif name not in mod.globals and not hasattr(builtins, name):
            raise Missing(f"{mod.stem}.{name} ({mod.where(expr)})")
    code = compile(ast.fix_missing_locations(ast.Expression(expr)), mod.rel, "eval")
    for env2 in itertools.islice(_envs(mod, func, names, env, depth), 400):
        # Globals and locals in one mapping: a comprehension inside sees the samples too.
        yield eval(code, {**mod.globals, **env2}), env2


def build(
    mod: Module, func: Any, expr: ast.expr, env: Env | None = None, depth: int = 0
) -> list[Any]:
    """Every value expr takes in func with the samples (deduplicated, in order)."""
    out = []
    for value, _ in _build_envs(mod, func, expr, env or {}, depth):
        if value not in out:
            out.append(value)
    return out


def returned(mod: Module, method: str, index: int | None = None) -> list[ast.expr]:
    """The expressions method returns (the index-th of a returned tuple), None left out."""
    out = []
    for func in mod.functions[method]:
        for node in ast.walk(func):
            if isinstance(node, ast.Return) and node.value is not None:
                value = node.value
                if index is not None:
                    if not isinstance(value, ast.Tuple):
                        continue
                    value = value.elts[index]
                if not (isinstance(value, ast.Constant) and value.value is None):
                    out.append(value)
    return out


def method_returns(rel: str, method: str, index: int | None = None) -> list[str]:
    mod = module(rel)
    func = mod.functions[method][0]
    return [v for e in returned(mod, method, index) for v in build(mod, func, e) if v]


def call_args(rel: str, callee: str, position: int) -> list[str]:
    """What the module passes as the position-th argument of its calls to callee."""
    mod = module(rel)
    out = []
    for node in ast.walk(mod.tree):
        if (
            isinstance(node, ast.Call)
            and _callee(node) == callee
            and len(node.args) > position
            and id(node) in mod.enclosing
        ):
            out += build(mod, mod.enclosing[id(node)], node.args[position])
    return [v for v in out if isinstance(v, str)]


def _callee(call: ast.Call) -> str | None:
    f = call.func
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None


# ------------------------------------------------------------------------- samples


def _jog_build_texts() -> list[str]:
    return [text for site in jog_build_sites() for text in site.texts]


def _refusal(text: str, cause: BaseException | None) -> InputRefused:
    exc = InputRefused(text)
    exc.__cause__ = cause
    return exc


_GRBL_STATES = ["Idle", "Run", "Jog", "Home", "Hold", "Door", "Sleep", "Alarm", "Check"]
_FAKE_LIMITS = SimpleNamespace(limits=SimpleNamespace(axes=("X", "Y", "Z")))
_CODES = [SimpleNamespace(code=c) for c in (*range(1, 39), 40)]
_SERIAL = SimpleNamespace(path="/dev/ttyUSB0", baud=115200)
_TCP = SimpleNamespace(host="192.168.1.20", port=23)
_CNCJS = SimpleNamespace(url="http://127.0.0.1:8000", port="/dev/ttyUSB0")
_SIM = SimpleNamespace(
    firmware=SimpleNamespace(
        profile=SimpleNamespace(name="grbl-1.1h"), machine=SimpleNamespace(name="hobby-router")
    ),
    rig=SimpleNamespace(link=SimpleNamespace(baud=115200)),
)


def _running() -> list[str]:
    """What a machine command shows while it runs: each Command's `doing` ("homing")."""
    from smoothjog.authority.commands import CATALOGUE

    return [c.doing for c in CATALOGUE.values()]


def _describes() -> list[str]:
    from smoothjog.links.cncjs import CncjsLink
    from smoothjog.links.serial import SerialLink
    from smoothjog.links.sim import SimLink
    from smoothjog.links.tcp import TcpLink

    return [
        SerialLink.describe(_SERIAL),  # type: ignore[arg-type]
        TcpLink.describe(_TCP),  # type: ignore[arg-type]
        SimLink.describe(_SIM),  # type: ignore[arg-type]
        CncjsLink.describe(_CNCJS),  # type: ignore[arg-type]
    ]


def _jog_locks() -> list[str]:
    """Why jogging and lines wait: a CNCjs job, a sender's job through the proxy, settings the
    host could not read (host.py _settings_unread_reason)."""
    from smoothjog.links.cncjs import _WORKFLOW_LOCKS
    from smoothjog.proxy import JOB_LOCK

    unread = method_returns("host.py", "_settings_unread_reason")
    return [*_WORKFLOW_LOCKS.values(), JOB_LOCK, *unread]


def _unread_results() -> list[SimpleNamespace]:
    """A handshake's result with `$$` refused to the end (by code, in a state or none seen)."""
    out = []
    for code, state in ((8, "Run"), (8, "Home"), (40, None)):
        unread = SimpleNamespace(line="$$", code=code, state=state)
        out.append(SimpleNamespace(unread_line=lambda line, u=unread: u))
    return out


def _critical_alarms() -> list[int]:
    """The alarms after which a controller reads no line until it is reset, in any firmware."""
    from smoothjog.core.firmware import FIRMWARES

    return sorted({code for facts in FIRMWARES.values() for code in facts.critical_alarms})


def _pin_names() -> list[str]:
    from smoothjog.core.engine.reports import PIN_NAMES as _PIN_NAMES

    pins = [_PIN_NAMES[p] for p in "HD"]
    return [*pins, " and ".join(pins)]


#: The engine's modules whose faults reach the page (core/engine/).
ENGINE_FAULTS = (
    "core/engine/jogger.py",
    "core/engine/phase.py",
    "core/engine/stopper.py",
    "core/engine/steps.py",
    "core/engine/clearance.py",
)
SIGNS = "core/engine/signs.py"
BOUNDS = "core/engine/bounds.py"
#: The sign-table entries whose words an outside stop's sentence quotes (signs.py).
OUTSIDE_STOP_SIGNS = (
    "rest_inside_block",
    "rest_short_of_acked_path",
    "lag_behind_estimate",
    "line_unread",
    "off_path",
    "idle_short_of_path_end",
)


def _outside_hows() -> list[str]:
    """How the stop showed: the words the callers pass, or what a sign found."""
    said = [
        str(node.args[2].value)
        for node in ast.walk(module("core/engine/phase.py").tree)
        if isinstance(node, ast.Call)
        and _callee(node) == "_outside_stop"
        and isinstance(node.args[2], ast.Constant)
    ]
    return [
        *said,
        *[text for sign in OUTSIDE_STOP_SIGNS for text in method_returns(SIGNS, sign)],
        *method_returns(BOUNDS, "slowed_inside_a_block"),
        *method_returns(BOUNDS, "slowed_since"),
    ]


def _state_verdicts() -> list[SimpleNamespace]:
    """The verdicts of the state signs the phase machine shows as faults (signs.py)."""
    texts = [
        *method_returns(SIGNS, "hold_or_door_input"),
        *method_returns(SIGNS, "left_jog_states"),
    ]
    return [SimpleNamespace(how=text) for text in texts]


def _room_stoppers() -> list[str]:
    mod = module("core/engine/clearance.py")
    func = mod.functions["room_along"][0]
    return [v for e, i in _assignments(func, "by") for v in build(mod, func, e.elts[i]) if v]  # type: ignore[attr-defined]


def _engine_states() -> list[str]:
    """Tool has no sentence of its own; Joc is no firmware's (a report damaged on the wire)."""
    return [*module("core/engine/limits.py").globals["STATE_REASONS"], "Tool", "Joc"]


def _where_blocked(start: tuple[float, ...]) -> str:
    from smoothjog.core.engine.clearance import Clearance

    return Clearance.where_blocked(_FAKE_LIMITS, start)  # type: ignore[arg-type]


def _handles() -> list[SimpleNamespace]:
    kinds = [*KIND_NOUNS, "other"]
    return [SimpleNamespace(input=SimpleNamespace(kind=k, name="#2 10.0.0.5")) for k in kinds]


def _device_handles() -> list[SimpleNamespace]:
    """The physical devices as the arbiter holds them: the decoder's kind, the device's name."""
    from smoothjog.inputs.kinds import decoder_named

    return [
        SimpleNamespace(input=SimpleNamespace(kind=decoder_named(n.split()[0]).kind, name=n))
        for n in _DEVICE_NAMES
    ]


def _all_handles() -> list[SimpleNamespace]:
    return [*_handles(), *_device_handles()]


def _described() -> list[str]:
    """Each input as a stop names it: a page's or a device's STOP (arbiter._submit)."""
    describe = module("authority/arbiter.py").globals["_describe"]
    return [describe(h) for h in _all_handles()]


def _stop_bys() -> list[str]:
    """Who stopped the machine, as the gate's stop sentence names them: an input's STOP, the
    arbiter's own stops (the dead-man, a lost link, an input going away, ...), the gate's
    default and the pendant's signal handler."""
    return [
        *_described(),
        *call_args("authority/arbiter.py", "_halt", 0),
        *call_args("authority/gate.py", "stop", 0),
        *call_args("cli/pendant.py", "stop", 0),
    ]


# The physical input devices (devices.py, inputs/*.py).
_DEVICE_NAMES = [
    "whb04b KTURT.LTD WHB04B",
    "gamepad Xbox Wireless Controller",
    "keyboard AT Translated Set 2 keyboard",
    "knob Griffin PowerMate",
    "shuttle Contour Design ShuttleXpress",
    "spacemouse-evdev 3Dconnexion SpaceMouse Compact",
]
_DEVICE_LOSSES = [
    "the device's stream ended",
    "read error: Input/output error",
    "unplugged or asleep (No such device)",
    "unplugged or switched off (No such device)",
    "the device was closed",
    "the device closed (end of file)",
]
_DECODERS = ("gamepad", "keyboard", "knob", "shuttle", "spacemouse", "whb04b")


class _OSError:
    """An OSError as the device code reads it: its strerror, and str() the same words."""

    strerror = "Input/output error"

    def __str__(self) -> str:
        return self.strerror


def _notice_texts() -> list[str]:
    return [t for site in decoder_sites() if "describe" not in site.source for t in site.texts]


def _describes_of_decoders() -> list[SimpleNamespace]:
    out = []
    for rel in _DECODERS:
        for text in method_returns(f"inputs/{rel}.py", "describe"):
            out.append(SimpleNamespace(name=rel, describe=lambda t=text: t))
    return out


def _command_outcomes() -> list[str]:
    return [t for site in _sites("devices.py", _returns("__call__")) for t in site.texts]


def _device_commands() -> list[SimpleNamespace]:
    from smoothjog.inputs.device import DEVICE_COMMANDS

    return [SimpleNamespace(name=n) for n in DEVICE_COMMANDS]


def _whb04b_selves() -> list[SimpleNamespace]:
    from smoothjog.inputs.whb04b import FEED_CODES

    feeds = list(dict.fromkeys(FEED_CODES.values()))
    return [
        SimpleNamespace(watchdog_s=0.5, _axis=a, _feed=f, _mode=m)
        for a in ("X", "A", None)
        for f in feeds
        for m in ("step", "continuous")
    ]


#: Values for the placeholders, by "module.function.name" or "module.name": lists, or callables
#: that make them; SKIP for a text that is another's (covered where it is made).
SAMPLES: dict[str, Any] = {
    # The engine.
    "jogger.self": lambda: [
        SimpleNamespace(_where_blocked=_where_blocked, model=SimpleNamespace(jog_lock=lock))
        for lock in _jog_locks()
    ],
    "jogger.resp": _CODES,
    "jogger.jogs": [0, 1, 3],
    "jogger.exc": lambda: [JogBuildError(t) for t in _jog_build_texts()],
    "phase.self": lambda: [
        SimpleNamespace(model=SimpleNamespace(jog_lock=lock)) for lock in _jog_locks()
    ],
    "phase.err_mm": [0.4, 12.25],
    "phase._outside_stop.who": lambda: method_returns(SIGNS, "who_stopped"),
    "phase._react_to_state.verdict": _state_verdicts,
    "clearance.self": [SimpleNamespace(where_blocked=_where_blocked)],
    "clearance.start": [(1.25, -3.0, 0.0)],
    "clearance.step_room_mm.name": ["X+", "Z-"],
    "clearance.step_room_mm.by": _room_stoppers,
    "clearance.room_along.zone": [SimpleNamespace(name="clamp")],
    "clearance.path_problem.zone": [SimpleNamespace(name="clamp")],
    "steps.problem": lambda: method_returns("core/engine/clearance.py", "path_problem"),
    "stopper.resp": _CODES,
    "stopper.presume_lost.lost": [1, 3],
    "stopper.waited_s": [0.55, 12.0],
    "signs.rest_ahead_mm": [0.42],
    "signs.lag_mm": [1.5],
    "signs.unread_ms": [102.4, 1500.0],
    "signs.ev": lambda: [SimpleNamespace(pressed=p) for p in _pin_names()],
    "phase.state": _engine_states,
    "signs.state": _engine_states,
    "phase._outside_stop.how": _outside_hows,
    "signs.rest_inside_block.rest_mm": [12.5],
    "signs.rest_inside_block.seg": [SimpleNamespace(x1_mm=13.74)],
    "bounds.slowed_inside_a_block.feed_mm_min": [1500.0],
    "bounds.slowed_inside_a_block.into_mm": [6.0],
    "bounds.slowed_inside_a_block.low_mm_s": [41.7],
    "bounds.slowed_since.feed_mm_min": [826.0],
    "bounds.slowed_since.low": [60.2],
    # JogBuildError's texts.
    "stream.axis": ["A"],
    "stream.r": [1.5],
    "intents.intent": [
        SimpleNamespace(axis="A", dist_mm=250.0, speed=0.0, step_mm=0.0005, counts=1.5, mode="jump")
    ],
    "intents.axes": [("X", "Y", "Z")],
    "intents.axis": ["A"],
    "intents.value": [float("nan")],
    "intents.speed": [0.0001],
    "intents.feed_mm_min": [0.06],
    "jogline.value": [float("nan"), 1.25e9],
    "jogline.digits": [10],
    "jogline.mode": ["G92"],
    "jogline.units": ["G19"],
    "jogline.unknown_axes": [["Q"]],
    "jogline.axes": [("X", "Y", "Z")],
    "jogline.axis": ["A"],
    "jogline.feed_mm_min": [0.0, -5.0, 0.0004],
    "jogline.line": ["$J=G21G91X1.5Y2.5Z0.5F1000"],
    "jogline.max_line_chars": [24],
    # The machine commands.
    "control.self": lambda: [SimpleNamespace(running=r) for r in _running()],
    "control.word": ["G54", "G60"],
    "control.run.name": ["jump"],  # a command the catalogue lacks
    "control.axis": ["A"],
    "control.known": [("X", "Y", "Z")],
    "control.kind": ["feed", "rapid"],
    "control.step": ["+5"],
    "control.steps": [("reset", "+10", "-10")],
    "control.text": ["G0 X100 Y100 Z-5 F1500 (a very long comment for this controller)"],
    "control.console.limit": [79],
    "control.reply": _CODES,
    "control.exc": SKIP,  # str(exc), str(host.error): another's words
    "control.reason": SKIP,  # the gate's command_refusal(), covered in authority/gate.py
    # The motion gate (authority/gate.py) and the line table (core/states.py).
    "gate.self": lambda: [
        SimpleNamespace(running=r, host=SimpleNamespace(model=SimpleNamespace(jog_lock=lock)))
        for r in _running()
        for lock in _jog_locks()
    ],
    "gate.jog_refusal.view": [SimpleNamespace(reason=None)],  # the engine's: jogger.can_jog
    "gate.command_refusal.line": SKIP,  # line_refusal(), covered in core/states.py
    "gate.command_refusal.name": SKIP,  # _state_refusal(), covered by its own returns
    "gate._state_refusal.state": _GRBL_STATES,
    "gate._stop_text.by": _stop_bys,
    "gate.set_intent.intent": [StopIntent()],
    "states.state_refusal.state": _GRBL_STATES,
    "states.state_refusal.what": ["line", "command"],
    # The arbiter and the server.
    "arbiter.handle": _all_handles,
    "arbiter._detached_text.handle": lambda: [*_handles()[:-1], *_device_handles()],
    "arbiter.current": _all_handles,
    "arbiter.reason": lambda: [None, *method_returns("authority/gate.py", "jog_refusal")],
    "arbiter.check.name": ["#1 127.0.0.1"],  # the dead-man's: a page (only pages have a lease)
    "arbiter.check.silent_s": [0.151],
    "arbiter._latch_holder.by": _described,
    "arbiter._submit.latched": SKIP,  # a latch text, covered where it is set (_tripped[...] =)
    "arbiter.exc": SKIP,
    "arbiter.attach.input_": SKIP,  # attaching is refused before any page exists
    "arbiter.check_lease_s.input_": SKIP,
    "server.notice": [SimpleNamespace(silent_s=0.21)],
    "server.on_text.exc": lambda: [_refusal(t, JogBuildError(t)) for t in _jog_build_texts()[:6]],
    "server._goto_zero.exc": lambda: [_refusal(_jog_build_texts()[0], JogBuildError())],
    "server._set_ratios.exc": lambda: [JogBuildError(t) for t in _jog_build_texts()],
    "server.poll_view.exc": [KeyError("mpos")],
    "server._announce.text": SKIP,  # a device's sentence (devices.py): not the server's
    "server.refuse.text": SKIP,  # refuse()'s own parameter: its callers are the sites
    "server._stopped.record": SKIP,  # the gate's stop sentence, covered in authority/gate.py
    "session_backend.self": SKIP,  # the engine's, the gate's and the control's words
    "session_backend.session": SKIP,
    "session_backend.model": [SimpleNamespace(last_alarm=c) for c in (1, 2, 9, 12)],
    # The link and the host.
    "base.text": ["G0 X1~"],
    "base.char": ["~", "\t"],
    "base.index": [5],
    "serial.self": [SimpleNamespace(describe=lambda: _describes()[0])],
    "serial.exc": [SimpleNamespace(strerror="Input/output error")],
    "serial._lost.reason": lambda: call_args("links/serial.py", "_lost", 0),
    "tcp.self": [SimpleNamespace(describe=lambda: _describes()[1])],
    "tcp.exc": [SimpleNamespace(strerror="Connection reset by peer")],
    "tcp._lost.reason": lambda: call_args("links/tcp.py", "_lost", 0),
    "cncjs.self": [
        SimpleNamespace(
            url="http://127.0.0.1:8000",
            port="/dev/ttyUSB0",
            _writer_task=task,
            timeout_s=5.0,
            describe=lambda: _describes()[3],
        )
        for task in (None, object())
    ],
    "pendant._print_notice.text": SKIP,  # a device's sentence (devices.py), covered there
    "pendant.link": lambda: [SimpleNamespace(describe=lambda d=d: d) for d in _describes()],
    "cncjs._lost.reason": lambda: call_args("links/cncjs.py", "_lost", 0),
    "cncjs.kind": ["Marlin"],
    "cncjs.detail": [None, "Error: No such file or directory, cannot open /dev/ttyUSB0"],
    "cncjs.exc": [ConnectionResetError("Connection reset by peer")],
    "host.self": lambda: [
        SimpleNamespace(describe=lambda d=d: d, link=SimpleNamespace(describe=lambda d=d: d))
        for d in _describes()
    ],
    "host.text": ["$H"],
    "host.__init__.code": _critical_alarms,  # ResetNeededError's
    "host.__init__.sent": [True, False],
    "host._settings_unread_reason.result": _unread_results,
    "host.timeout_s": [5.0],
    "host.entry": [SimpleNamespace(text="G10L20P0X0")],
    "host.exc": [KeyError("mpos")],
    # The physical input devices.
    "devices.self": SKIP,  # only through its attributes below
    "devices._tell_once.text": SKIP,  # _tell_once's own parameter: its callers are the sites
    "devices.wish": ["whb04b", "gamepad"],
    "devices.device": lambda: [
        SimpleNamespace(path="/dev/hidraw3", problem=p)
        for p in method_returns("inputs/discovery.py", "_problem")
    ],
    "devices.exc": [_OSError()],
    "devices.decoder": _describes_of_decoders,
    "devices.source": [SimpleNamespace(info=SimpleNamespace(name="KTURT.LTD WHB04B"))],
    "devices.command": _device_commands,
    "devices.__call__.exc": [
        "homing is not enabled on this controller ($22=0): there are no switches to home to",
        "the work offset is not known yet; wait for the next status report",
    ],
    "devices.result": [
        SimpleNamespace(ok=False, error=None),
        SimpleNamespace(ok=False, error="the controller did not restart within 5 s"),
    ],
    "hidraw_source.exc": [SimpleNamespace(strerror="Input/output error", errno=19)],
    "evdev_source.exc": [SimpleNamespace(strerror="Input/output error", errno=19)],
    "discovery.dev_path": ["/dev/hidraw3"],
    "devinput.self": [
        SimpleNamespace(name=n, ended=e)
        for n, e in zip(_DEVICE_NAMES, [None, *_DEVICE_LOSSES[:5]], strict=True)
    ],
    "devinput._pump.self": SKIP,
    "devinput.run.self": lambda: [
        SimpleNamespace(name=_DEVICE_NAMES[0], ended=e) for e in [None, *_DEVICE_LOSSES]
    ],
    "devinput._apply.self": [SimpleNamespace(name=n) for n in _DEVICE_NAMES[:2]],
    "devinput._apply.action": lambda: [SimpleNamespace(text=t) for t in _notice_texts()],
    "devinput.notice.notice": SKIP,  # the arbiter's notice, covered there
    "devinput._submit.exc": [
        InputRefused("this pendant is watching only; press Take control to drive the machine"),
        InputRefused("jogging is disabled: the controller is asleep: reset it to wake it"),
    ],
    "devinput.command": _device_commands,
    "devinput._run_command.outcome": _command_outcomes,
    "devinput.exc": [_OSError()],
    "gamepad.self": [
        SimpleNamespace(speed=sp, deadman=d, info=SimpleNamespace(name="Xbox Wireless Controller"))
        for sp, d in ((0.5, 0x136), (0.125, 0x2C0), (1.0, None))
    ],
    "gamepad._command.self": [SimpleNamespace(deadman=d) for d in (0x136, 0x2C0)],
    "gamepad._command.action": ["home", "goto_zero", "resume"],
    "keyboard.self": [
        SimpleNamespace(speed=0.25, _step_mode=m, _step_mm=0.1, _tap_step_mm=t)
        for m in (False, True)
        for t in (None, 0.01)
    ],
    "knob.self": [
        SimpleNamespace(_axis="X", _step_mm=0.1, _mode=m) for m in ("position", "velocity")
    ],
    "knob.stopped": ["jog stopped; ", ""],
    "shuttle.self": [
        SimpleNamespace(
            model=SimpleNamespace(name="ShuttleXpress"),
            transport="hidraw",
            enable=e,
            buttons={
                1: SimpleNamespace(kind="axis", axis="X"),
                5: SimpleNamespace(kind="command", command=SimpleNamespace(name="zero")),
            },
            wheel=w,
            wheel_mode="position",
            step_mm=0.1,
            active_axis=a,
        )
        for e, w, a in (("hold", "handwheel", "X"), ("toggle", "steps", None))
    ],
    "spacemouse.self": [
        SimpleNamespace(
            model="SpaceMouse Compact",
            transport=t,
            mapping=m,
            buttons=b,
            deadzone=0.1,
            expo=2.0,
            speed=0.5,
            dominant=d,
            watchdog_s=0.5,
        )
        for t, m, b, d in (
            (
                "evdev",
                {"X": (0, 1), "Y": (1, -1)},
                {1: "stop", 2: SimpleNamespace(name="zero")},
                True,
            ),
            ("hidraw", {}, {}, False),
        )
    ],
    "spacemouse._stop.reason": lambda: call_args("inputs/spacemouse.py", "_stop", 0),
    "whb04b.self": _whb04b_selves,
    "whb04b._wheel.self": lambda: [x for x in _whb04b_selves() if x._axis],
    "whb04b._explain.text": SKIP,  # _explain's own parameter: its callers are the sites
}

#: Texts sent as they are, however English (an OS's error, a name the user gave, ...).
PASSTHROUGH = [
    "Error: No such file or directory, cannot open /dev/ttyUSB0",  # CNCjs's own error text
    "Input/output error",
    "Connection reset by peer",
    "/dev/ttyUSB0",
    "tcp://192.168.1.20:23",
    "http://127.0.0.1:8000",  # a CNCjs server's address
    "Marlin",  # a controller type as CNCjs names it
    "grbl-1.1h",
    "hobby-router",
    "Tool",  # a state Grbl 1.1h does not have, named as the controller names it
    "nan",
    "position, velocity",  # the handwheel modes and overrides, by their protocol names
    "feed, rapid",
    "reset, +10, -10",
    *_DEVICE_NAMES,  # a device as it names itself, and its model
    *(f"{kind} KTURT.LTD WHB04B" for kind in _DECODERS),
    "docs/devices.md",
    "ShuttleXpress",
    "SpaceMouse Compact",
    "WHB04B",
    "KTURT.LTD",
    "Xbox Wireless Controller",
    "No such device",
    "/dev/hidraw3",
    "1=X 5=zero",  # button mappings, by the names the configuration gives them
    "1=stop 2=zero",
    "X=x Y=-y",
    "--input whb04b",
    "--input gamepad",
]
#: Words the Chinese keeps: names, units, Grbl's states in its own spelling, acronyms.
LATIN_OK = {
    "smoothjog", "Grbl", "grblHAL", "FluidNC", "CNCjs", "Ctrl", "mm", "min", "Jog", "Run", "Hold",
    "ASCII", "EEPROM", "PWM", "JSON", "SpaceMouse", "Wi", "Fi", "udev", "hidraw",
    "evdev", "spacenavd", "Lead", "SIGTERM",
}  # fmt: skip
#: Grbl's own words: `error:15`, `$J=`, `$X`, G- and axis words, quoted values as sent.
GRBL_WORDS = re.compile(
    r"error:\d+|ALARM:\d+|\$[A-Za-z]+=?|\b[A-Z]\d[\d.]*\b|\b[XYZABCUVW]+\b|'[^']*'|\"[^\"]*\""
)


# ------------------------------------------------------------------------- the sites


@dataclass
class Site:
    """One place that makes a sentence the page shows, and the sentences it makes."""

    where: str
    source: str
    texts: list[str]


#: Which expressions of a node make a sentence (the arguments of a call, say).
Pick = Callable[[Module, ast.AST], list[ast.expr]]


def _sites(rel: str, pick: Pick, only: tuple[str, ...] = ()) -> list[Site]:
    """The sites pick finds in rel (only in the functions named, if any)."""
    mod = module(rel)
    out = []
    for node in ast.walk(mod.tree):
        func = mod.enclosing.get(id(node))
        if only and getattr(func, "name", None) not in only:
            continue
        for expr in pick(mod, node):
            if isinstance(expr, ast.Call) and _callee(expr) == "str":
                continue  # another's text, passed on
            try:
                texts = [t for t in build(mod, func, expr) if isinstance(t, str) and t]
            except Skip:
                continue
            out.append(Site(mod.where(expr), ast.unparse(expr), texts))
    return out


def _calls(name: str, *positions: int, keyword: str | None = None) -> Pick:
    def pick(mod: Module, node: ast.AST) -> list[ast.expr]:
        if not (isinstance(node, ast.Call) and _callee(node) == name):
            return []
        picked = [node.args[p] for p in positions if p < len(node.args)]
        return picked + [k.value for k in node.keywords if k.arg == keyword]

    return pick


def _returns(function: str, index: int | None = None) -> Pick:
    def pick(mod: Module, node: ast.AST) -> list[ast.expr]:
        if not (isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.name == function):
            return []
        return returned(mod, function, index)

    return pick


def _dict_values(*keys: str) -> Pick:
    def pick(mod: Module, node: ast.AST) -> list[ast.expr]:
        if not isinstance(node, ast.Dict):
            return []
        return [
            v
            for k, v in zip(node.keys, node.values, strict=True)
            if isinstance(k, ast.Constant) and k.value in keys
        ]

    return pick


def _item_assigned(attr: str) -> Pick:
    """The values put into `self.<attr>[...]`."""

    def pick(mod: Module, node: ast.AST) -> list[ast.expr]:
        if not isinstance(node, ast.Assign):
            return []
        for target in node.targets:
            if (
                isinstance(target, ast.Subscript)
                and isinstance(target.value, ast.Attribute)
                and target.value.attr == attr
            ):
                return [node.value]
        return []

    return pick


def _constants(name: str) -> Pick:
    """The module's own constants whose name fully matches the regex name."""

    def pick(mod: Module, node: ast.AST) -> list[ast.expr]:
        if not any(node is top for top in mod.tree.body):
            return []
        if isinstance(node, ast.AnnAssign) and node.value is not None:
            targets, value = [node.target], node.value
        elif isinstance(node, ast.Assign):
            targets, value = node.targets, node.value
        else:
            return []
        named = any(isinstance(t, ast.Name) and re.fullmatch(name, t.id) for t in targets)
        return [value] if named else []

    return pick


@cache
def fault_sites() -> list[Site]:
    """Every `self._fault_now(now_s, text, hint)` of the engine: its texts and its hints."""
    return [site for rel in ENGINE_FAULTS for site in _sites(rel, _calls("fault_now", 1, 2))]


@cache
def jog_build_sites() -> list[Site]:
    return [
        site
        for rel in ("core/intents.py", "core/jogline.py", "core/engine/stream.py")
        for site in _sites(rel, _calls("JogBuildError", 0))
    ]


ARBITER = "authority/arbiter.py"
GATE = "authority/gate.py"
#: What the gate says: why nothing, a jog or a command may start, and the stop sentence.
GATE_TEXTS = (
    "session_refusal",
    "jog_refusal",
    "busy_refusal",
    "command_refusal",
    "_state_refusal",
    "_stop_text",
)
#: Where a link says it was lost or closed, and where a console line fails, mid-session.
LINK_LOST = ("_lost", "close")
CONSOLE_FAILED = ("_ask", "_lost_to_reset")


@cache
def other_sites() -> list[Site]:
    """Why jogging is off, and what the server, gate, arbiter, control, host and link tell the
    page."""
    return [
        *_sites("core/engine/phase.py", _returns("can_jog", 1)),
        *_sites("web/session_backend.py", _dict_values("text", "hint")),
        *_sites("web/session_backend.py", _returns("_warning")),  # the view's warning
        *_sites("web/session_backend.py", _constants(r"[A-Z_]+_(?:TEXT|WARNING)")),
        *_sites("core/machine.py", _constants(r"UNHOMED_WARNING")),  # the view's warning's words
        # The motion gate: why a jog, a command or a line waits, and who stopped what.
        *_sites(GATE, _constants(r"[A-Z_]+_TEXT")),
        *[site for method in GATE_TEXTS for site in _sites(GATE, _returns(method))],
        *_sites("core/states.py", _returns("state_refusal")),
        *_sites("core/states.py", _constants(r"[A-Z_]+_TEXT")),
        # Each command's `doing`: control.running, and "jogging waits: homing is running".
        *_sites("authority/commands.py", _calls("Command", 1)),
        *_sites("control.py", _calls("ControlRefused", 0)),
        *_sites("control.py", _calls("CommandResult", 3, keyword="error")),
        *_sites(ARBITER, _calls("InputRefused", 0)),
        *_sites(ARBITER, _returns("_detached_text")),
        *_sites(ARBITER, _item_assigned("_tripped")),  # why a stopped input's jogs wait
        *_sites("web/server.py", _calls("refuse", 1)),
        *_sites("web/server.py", _calls("error_message", 0)),
        *_sites("links/base.py", _calls("RefusedError", 0), only=("encode_line",)),
        # A link lost mid-session (opening one fails before the pendant starts).
        *_sites("links/serial.py", _calls("LinkError", 0), only=LINK_LOST),
        *_sites("links/tcp.py", _calls("LinkError", 0), only=LINK_LOST),
        *_sites("links/cncjs.py", _calls("LinkError", 0), only=LINK_LOST),
        *_sites("cli/pendant.py", _calls("announce", 0)),  # the link back after a loss
        *_sites("host.py", _calls("LinkError", 0)),
        *_sites("host.py", _calls("ConnectError", 0), only=CONSOLE_FAILED),
        # A console line a critical alarm leaves unanswered (ResetNeededError), and settings
        # the host could not read (its jog lock: why jogs and lines wait).
        *_sites("host.py", _calls("__init__", 0), only=("__init__",)),
        *_sites("host.py", _returns("_settings_unread_reason")),
    ]


@cache
def decoder_sites() -> list[Site]:
    """What each device's decoder says (DeviceNotice) and how it describes itself."""
    out = []
    for rel in _DECODERS:
        out += _sites(f"inputs/{rel}.py", _calls("DeviceNotice", 0))
        out += _sites(f"inputs/{rel}.py", _returns("describe"))
    return [*out, *_sites("inputs/whb04b.py", _calls("_explain", 0))]


@cache
def device_sites() -> list[Site]:
    """What the device manager and each device input tell every page (with the device's name)."""
    return [
        *decoder_sites(),
        *_sites("devices.py", _calls("_tell", 0)),
        *_sites("devices.py", _calls("_tell_once", 1)),
        *_sites("devices.py", _returns("__call__")),
        *_sites("inputs/discovery.py", _returns("_problem")),
        *_sites("inputs/devinput.py", _calls("_tell", 0)),
        *_sites("inputs/devinput.py", _returns("_loss_text")),
        *_sites("inputs/hidraw_source.py", _calls("DeviceLost", 0)),
        *_sites("inputs/evdev_source.py", _calls("DeviceLost", 0)),
    ]


def all_texts() -> list[tuple[str, str]]:
    """(where, text) for every sentence the page can show."""
    out = []
    for site in [*fault_sites(), *jog_build_sites(), *other_sites(), *device_sites()]:
        out += [(site.where, text) for text in site.texts]
    return out


# ------------------------------------------------------------------------- the tests


def test_the_patterns_are_read_and_python_reads_them_as_js_does() -> None:
    t = tables()
    assert len(t.server) > 150
    js = I18N.read_text(encoding="utf-8")
    block = _block(js, "const SERVER_ZH = [", "\n];")
    assert len(t.server) == sum(1 for line in block if line.lstrip().startswith("[/"))
    for pattern, template, source in t.server:
        # Anchored, and only syntax both engines read alike (no lookbehind, named groups, flags).
        assert source.startswith("^"), source
        assert source.endswith("$"), source
        assert not re.search(r"\(\?<|\(\?P|\\[pPkuxc]", source), source
        used = {int(i) for i in re.findall(r"\{(\d)\}", template)}
        assert used <= set(range(1, pattern.groups + 1)), (source, template)
    assert set(ERROR_CODES) <= set(t.errors), "an error code without Chinese"
    assert set(ALARM_CODES) <= set(t.alarms), "an alarm code without Chinese"


def test_every_fault_of_the_engine_is_found_and_built() -> None:
    sources = [(SRC / rel).read_text(encoding="utf-8") for rel in ENGINE_FAULTS]
    calls = sum(source.count(".fault_now(") for source in sources)
    assert calls >= 14
    # A text and a hint per call (none skipped), each built from SAMPLES; "" is no hint.
    assert len(fault_sites()) == 2 * calls
    assert len(jog_build_sites()) >= 25
    for site in [*fault_sites(), *jog_build_sites(), *other_sites()]:
        assert site.texts or site.source == "''", f"{site.where}: nothing built: {site.source}"


def test_the_gate_arbiter_and_host_texts_are_found() -> None:
    """A helper renamed or moved would leave its sentences unchecked: each is found and built."""
    for method in GATE_TEXTS:
        sites = _sites(GATE, _returns(method))
        assert sites, f"{GATE}: no {method}()"
        assert all(s.texts for s in sites), f"{GATE}: no texts from {method}()"
    assert {t for s in _sites(GATE, _returns("_stop_text")) for t in s.texts} >= {
        f"stopped by {by}: the jog was cancelled" for by in _stop_bys()
    }
    latches = _sites(ARBITER, _item_assigned("_tripped"))
    assert len(latches) >= 3
    assert all(s.texts for s in latches)
    doing = [t for s in _sites("authority/commands.py", _calls("Command", 1)) for t in s.texts]
    assert sorted(doing) == sorted(_running())
    assert len(_sites("host.py", _calls("__init__", 0), only=("__init__",))) == 1
    assert method_returns("host.py", "_settings_unread_reason")
    assert method_returns("core/states.py", "state_refusal")


def test_every_sentence_the_page_shows_has_a_pattern() -> None:
    missing = sorted({(w, s) for w, s in all_texts() if first_pattern(s) is None})
    assert missing == [], "no SERVER_ZH pattern for:\n" + "\n".join(f"{w}: {s}" for w, s in missing)


def _english_left(zh: str) -> list[str]:
    rest = zh
    for text in PASSTHROUGH:
        rest = rest.replace(text, " ")
    rest = GRBL_WORDS.sub(" ", rest)
    rest = re.sub(r"`[^`]*`", " ", rest)  # a command line, kept as it is typed
    rest = re.sub(r"\b(?:BTN|KEY)_\w+", " ", rest)  # a button as the kernel names it
    return [w for w in re.findall(r"[A-Za-z]{3,}", rest) if w not in LATIN_OK]


def test_every_sentence_reads_in_chinese() -> None:
    left = {}
    for where, text in all_texts():
        zh = translate(text)
        words = _english_left(zh)
        if words or not re.search(r"[\u4e00-\u9fff]", zh):
            left[text] = (where, zh, words)
    assert left == {}, "English left in the Chinese page:\n" + "\n".join(
        f"{w}: {t!r}\n    -> {zh!r} {words}" for t, (w, zh, words) in left.items()
    )


def test_the_alarm_and_error_sentences_read_in_chinese() -> None:
    from smoothjog.core.codes import describe_alarm, describe_error

    for code in [*ALARM_CODES, 11]:
        text = describe_alarm(code)
        zh = translate(text)
        assert zh.startswith(f"报警 {code}："), (text, zh)
        assert _english_left(zh) == [], (text, zh)
    for code in [*ERROR_CODES, 40]:
        text = describe_error(code)
        zh = translate(text)
        assert zh.startswith(f"错误 {code}："), (text, zh)
        assert "——" in zh, f"the hint of {text!r} is not translated: {zh!r}"
        assert _english_left(zh) == [], (text, zh)


def test_every_pattern_is_used() -> None:
    used = {first_pattern(s) for _, s in all_texts()}
    # Inner parts are reached through the sentence around them.
    inner: set[str] = set()
    for _, s in all_texts():
        _collect_inner(s, inner)
    unused = [src for _, _, src in tables().server if src not in used | inner]
    assert unused == [], "SERVER_ZH patterns no sentence of the server uses:\n" + "\n".join(unused)


def _collect_inner(s: str, seen: set[str]) -> None:
    t = tables()
    m = t.code.match(s)
    if m:
        if m[3]:
            seen.add(first_pattern(m[3]) or "")
            _collect_inner(m[3], seen)
        return
    for pattern, _, src in t.server:
        found = pattern.search(s)
        if found:
            seen.add(src)
            for part in found.groups():
                if part:
                    _collect_inner(part, seen)
            return


@pytest.mark.skipif(shutil.which("node") is None, reason="node is not installed")
def test_node_agrees(tmp_path: Path) -> None:
    """The real translateServer() in node gives the Chinese the rules here give."""
    texts = sorted({s for _, s in all_texts()})
    script = tmp_path / "translate.mjs"
    script.write_text(
        "globalThis.document = { documentElement: {} };\n"
        f"const m = await import({json.dumps(I18N.as_uri())});\n"
        'm.setLanguage("zh");\n'
        'let input = "";\n'
        "for await (const chunk of process.stdin) input += chunk;\n"
        "console.log(JSON.stringify(JSON.parse(input).map((s) => m.translateServer(s))));\n",
        encoding="utf-8",
    )
    node = shutil.which("node")
    assert node is not None
    done = subprocess.run(
        [node, str(script)],
        input=json.dumps(texts),
        capture_output=True,
        text=True,
        timeout=30,
        check=True,
    )
    by_node = dict(zip(texts, json.loads(done.stdout), strict=True))
    differ = {s: (zh, translate(s)) for s, zh in by_node.items() if zh != translate(s)}
    assert differ == {}


async def test_the_chinese_page_shows_a_fault_and_its_hint_in_chinese(
    pendant: StartPendant, open_page: OpenPage
) -> None:
    """In Chromium: the status line puts the text and the hint through translateServer()."""
    p = await pendant()
    page = await open_page(p.url, viewport=DESKTOP, touch=False, locale="zh-CN")
    await page.wait_for_selector("#role:has-text('控制中')")
    site = next(s for s in fault_sites() if any(t.startswith("step refused") for t in s.texts))
    text = site.texts[0]
    hint = next(h for s in fault_sites() for h in s.texts if h == "jog the other way")
    p.backend.set_view(fault={"text": text, "hint": hint})
    shown = f"{translate(text)} {translate(hint)}"
    await page.wait_for_function(
        "(want) => document.querySelector('#status-text').textContent === want", arg=shown
    )
    control = {**p.backend.view_state["control"], "running": "homing"}
    p.backend.set_view(control=control)
    await page.wait_for_function(
        "() => document.querySelector('#m-running').textContent === '正在执行：回零'"
    )

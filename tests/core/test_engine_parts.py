"""The engine package keeps its shape: parts never import the phase machine, no import circle,
no file over 600 lines, and the public names stay where the host, bench and tests take them."""

from __future__ import annotations

import ast
from pathlib import Path

from smoothjog.core import engine

ENGINE = Path(engine.__file__).parent
PHASE_MACHINE = {"jogger", "phase"}
MAX_LINES = 600


def _engine_imports(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module:
            if node.module == "smoothjog.core.engine":
                out |= {alias.name for alias in node.names}
            elif node.module.startswith("smoothjog.core.engine."):
                out.add(node.module.rsplit(".", 1)[1])
    return out


def test_no_part_imports_the_phase_machine() -> None:
    for path in ENGINE.glob("*.py"):
        if path.stem in PHASE_MACHINE or path.stem == "__init__":
            continue
        assert not _engine_imports(path) & PHASE_MACHINE, f"{path.name} imports the phase machine"


def test_the_engine_modules_import_no_circle() -> None:
    graph = {p.stem: _engine_imports(p) - {p.stem} for p in ENGINE.glob("*.py")}
    graph.pop("__init__")
    done: set[str] = set()

    def visit(name: str, trail: tuple[str, ...]) -> None:
        assert name not in trail, " -> ".join((*trail, name))
        if name in done:
            return
        for dep in graph.get(name, set()):
            visit(dep, (*trail, name))
        done.add(name)

    for name in graph:
        visit(name, ())


def test_no_engine_file_is_over_600_lines() -> None:
    for path in ENGINE.glob("*.py"):
        lines = len(path.read_text(encoding="utf-8").splitlines())
        assert lines <= MAX_LINES, f"{path.name}: {lines} lines"


def test_the_public_names() -> None:
    assert sorted(engine.__all__) == [
        "EngineEvent",
        "EngineLimits",
        "EngineStats",
        "EngineView",
        "JogTuning",
        "Jogger",
        "Output",
        "Phase",
        "SendLine",
        "SendRealtime",
        "StopRecord",
    ]

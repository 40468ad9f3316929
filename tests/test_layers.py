"""The layers import one way: core <- sim, links, inputs <- session, handshake <- web, cli."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parent.parent / "src" / "smoothjog"

#: For each layer, the smoothjog packages/modules it may import (besides itself).
ALLOWED: dict[str, set[str]] = {
    "core": set(),
    "sim": {"core"},
    "links": {"core", "sim"},  # links/sim.py wraps the simulator in the Link contract
    "inputs": {"core"},
    "handshake": {"core", "links"},
    "session": {"core", "links", "handshake"},
    "vsession": {"core", "sim", "inputs"},
    "config": {"core", "links"},  # it checks tcp:// URLs with the TCP link's own parser
    "web": {"core", "links", "sim", "session", "handshake", "config", "inputs"},
    "cli": {
        "core",
        "sim",
        "links",
        "inputs",
        "session",
        "vsession",
        "handshake",
        "config",
        "web",
    },
}


def _layer(path: Path) -> str:
    rel = path.relative_to(SRC)
    return rel.parts[0].removesuffix(".py")


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module]
        elif isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        else:
            continue
        for name in names:
            parts = name.split(".")
            if parts[0] == "smoothjog" and len(parts) > 1:
                found.add(parts[1])
    return found


FILES = sorted(p for p in SRC.rglob("*.py") if p.name not in ("__init__.py", "__main__.py"))


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(SRC)))
def test_imports_point_one_way(path: Path) -> None:
    layer = _layer(path)
    if layer not in ALLOWED:
        pytest.fail(f"{path.relative_to(SRC)} is in no known layer: add it to ALLOWED")
    bad = _imports(path) - ALLOWED[layer] - {layer}
    assert not bad, f"{path.relative_to(SRC)} ({layer}) imports {sorted(bad)}"


def test_core_uses_only_the_standard_library() -> None:
    allowed_third_party: set[str] = set()
    for path in (SRC / "core").rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                tops = {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                tops = {node.module.split(".")[0]}
            else:
                continue
            for top in tops - {"smoothjog", "__future__"} - allowed_third_party:
                assert top in _stdlib(), f"{path.name} imports {top}, which is not stdlib"


def _stdlib() -> frozenset[str]:
    import sys

    return frozenset(sys.stdlib_module_names)


def test_core_reads_no_clock_and_does_no_io() -> None:
    banned_modules = {"time", "asyncio", "socket", "os", "serial", "threading", "select"}
    for path in (SRC / "core").rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                tops = {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                tops = {node.module.split(".")[0]}
            else:
                tops = set()
            assert not tops & banned_modules, f"core/{path.name} imports {tops & banned_modules}"
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
                assert node.func.id not in {"open", "print", "input"}, (
                    f"core/{path.name} calls {node.func.id}()"
                )

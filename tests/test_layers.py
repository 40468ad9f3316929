"""The layers import one way: core <- sim, links, inputs <- handshake, host <- authority <- cli."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parent.parent / "src" / "smoothjog"

#: For each layer, the smoothjog packages/modules it may import (besides itself).
ALLOWED: dict[str, set[str]] = {
    "core": set(),
    "vclock": {"core"},
    # The one raw-pty opener (a leaf, beside core): the simulator's pty and the proxy's.
    "pty_port": {"core"},
    "sim": {"core", "pty_port"},
    "links": {"core", "sim"},  # links/sim.py wraps the simulator in the Link contract
    "inputs": {"core"},
    "handshake": {"core"},
    "host": {"core", "links", "handshake"},
    # Who may move the machine and what a stop does: the gate (over the host), the arbiter
    # (which input speaks), the command catalogue.
    "authority": {"core", "inputs", "links", "host"},
    "control": {"core", "links", "host", "authority"},  # the catalogue's commands, run
    "virtual": {"core", "sim", "links", "inputs", "host", "vclock"},
    "config": {"core", "links"},  # it checks tcp:// URLs with the TCP link's own parser
    # The session's input devices: found (inputs), run under the arbiter, commands by control.
    "devices": {"core", "links", "inputs", "host", "authority", "control", "config", "handshake"},
    "web": {
        "core",
        "links",
        "sim",
        "host",
        "authority",
        "handshake",
        "config",
        "inputs",
        "control",
    },
    # The sender's side of `smoothjog proxy`: its pty and TCP port, lines forwarded by the host.
    "proxy": {"core", "links", "host", "pty_port", "authority"},
    "cli": {
        "core",
        "sim",
        "links",
        "inputs",
        "host",
        "authority",
        "vclock",
        "virtual",
        "handshake",
        "config",
        "control",
        "devices",
        "web",
        "proxy",
        "pty_port",
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


def _top_modules(node: ast.AST) -> set[str]:
    """Top-level module names an import node brings in (empty for any other node)."""
    if isinstance(node, ast.Import):
        return {alias.name.split(".")[0] for alias in node.names}
    if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
        return {node.module.split(".")[0]}
    return set()


CORE_TREES = [(p, ast.parse(p.read_text(encoding="utf-8"))) for p in (SRC / "core").rglob("*.py")]


def test_core_uses_only_the_standard_library() -> None:
    stdlib = frozenset(sys.stdlib_module_names)
    for path, tree in CORE_TREES:
        for node in ast.walk(tree):
            for top in _top_modules(node) - {"smoothjog", "__future__"}:
                assert top in stdlib, f"{path.name} imports {top}, which is not stdlib"


def test_core_reads_no_clock_and_does_no_io() -> None:
    banned_modules = {"time", "asyncio", "socket", "os", "serial", "threading", "select"}
    for path, tree in CORE_TREES:
        for node in ast.walk(tree):
            tops = _top_modules(node)
            assert not tops & banned_modules, f"core/{path.name} imports {tops & banned_modules}"
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
                assert node.func.id not in {"open", "print", "input"}, (
                    f"core/{path.name} calls {node.func.id}()"
                )

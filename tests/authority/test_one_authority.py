"""Only the authority decides whether motion may start: a fact read from the code with `ast`.

The signs of that decision are the engine's verdict (`can_jog`), the jog lock another program
holds (`jog_lock`), and the states that count as moving (`MOVING_STATES`). Outside `core/`
(which states the facts) and `authority/` (which decides), a module may only pass the gate's own
verdict on (`gate.can_jog()`), or keep the lock as data (the host stores it); it may not read one
of them to decide for itself.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / "src" / "smoothjog"
SIGNS = frozenset({"can_jog", "jog_lock", "MOVING_STATES"})
DECIDERS = ("core", "authority")


def _outside_the_authority() -> list[Path]:
    return sorted(
        p
        for p in SRC.rglob("*.py")
        if p.relative_to(SRC).parts[0].removesuffix(".py") not in DECIDERS
    )


def _asks_the_gate(node: ast.Attribute) -> bool:
    """`gate.can_jog` or `self.gate.can_jog`: passing the gate's verdict on."""
    owner = node.value
    name = owner.attr if isinstance(owner, ast.Attribute) else getattr(owner, "id", None)
    return name == "gate"


def decisions(path: Path) -> list[str]:
    """Where path reads a sign of the decision for itself (line: what)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Attribute) and node.attr in SIGNS:
            if isinstance(node.ctx, ast.Load) and not _asks_the_gate(node):
                found.append(f"{node.lineno}: .{node.attr}")
        elif isinstance(node, ast.Name) and node.id in SIGNS and isinstance(node.ctx, ast.Load):
            found.append(f"{node.lineno}: {node.id}")
    return found


@pytest.mark.parametrize("path", _outside_the_authority(), ids=lambda p: str(p.relative_to(SRC)))
def test_no_module_but_the_authority_decides_whether_motion_may_start(path: Path) -> None:
    assert decisions(path) == [], f"{path.relative_to(SRC)} decides for itself"


def test_the_check_finds_a_decision(tmp_path: Path) -> None:
    sample = tmp_path / "sample.py"
    sample.write_text(
        "def may(host, gate):\n"
        "    if host.model.jog_lock:\n"
        "        return False\n"
        "    ok, _ = gate.can_jog()\n"
        "    return ok and host.view().can_jog\n",
        encoding="utf-8",
    )
    assert decisions(sample) == ["2: .jog_lock", "5: .can_jog"]

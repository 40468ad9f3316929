"""STOP always stops: every stop source against every kind of motion (the issue's acceptance test).

Sources: the controlling page's STOP button, a watching page's STOP button and its Escape key, a
gamepad's STOP button (GamepadDecoder under DeviceInput, attached to the session's arbiter as a
watcher), and SIGINT to the `smoothjog proxy` command. Motions: a held jog (a key held on the
controlling page, at 100 %), a 100 mm step, go to work zero, a console `G1X-150F3000`, a
sender's job through the proxy (a simple_stream.py-style sender on the proxy's pty), and homing
(`$H` from the page; the machine powers up in Alarm, and each homing cell after the first starts
in the Alarm the one before left).

For each cell, on the simulator's ground truth (`smoothjog sim --trace`, never smoothjog's own
view): the machine was moving when the stop was given (the page's click or key-down, the pad's
press, the signal); from then until the controlling input was released it travelled at most
v²/2a + v x (one status period + harness.HOPS_S), v the motion's own speed and a Grbl's
acceleration along its direction (the table also shows the brief's bound without HOPS_S); it
stood still for the last 2 s of that while the input was still held (a held jog stopped by
another input keeps beating through the hold, and the arbiter's latch must refuse it); and both
pages were told who stopped it and what was done (cancel, feed hold, reset).

The simulator writes its trace only when it stops, so the module runs every selected cell first
(matrix.py: two machines side by side, the in-process session and the signal lane) and each
test then judges its own cell; `-k` selects cells as usual and only those run. The table is
printed (-s) and written to test-artifacts/stop-matrix.txt.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest
import pytest_asyncio

from tests.stopmatrix.harness import write_machine
from tests.stopmatrix.matrix import CELLS, Cell, Verdict, order, run_lanes, table
from tests.web.conftest import CHROMIUM, CHROMIUM_ARGS

pytestmark = [
    pytest.mark.timeout(600),
    pytest.mark.skipif(not Path(CHROMIUM).exists(), reason=f"{CHROMIUM} is not installed"),
]
REPORT = Path(__file__).parents[2] / "test-artifacts" / "stop-matrix.txt"


def _selected(session: pytest.Session, module: object) -> list[Cell]:
    """The cells of this module's tests that this run will run."""
    cells = []
    for item in session.items:
        if isinstance(item, pytest.Function) and item.module is module:
            cell = item.callspec.params.get("cell") if hasattr(item, "callspec") else None
            if isinstance(cell, Cell):
                cells.append(cell)
    return order(cells)


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def verdicts(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> AsyncIterator[dict[str, Verdict]]:
    """Run every selected cell once; their verdicts by cell id."""
    from playwright.async_api import async_playwright

    folder = tmp_path_factory.mktemp("stopmatrix")
    machine = write_machine(folder)
    async with async_playwright() as pw:
        browser = await pw.chromium.launch(
            executable_path=CHROMIUM, headless=True, args=list(CHROMIUM_ARGS)
        )
        try:
            result = await run_lanes(
                _selected(request.session, request.module), folder, machine, browser
            )
        finally:
            await browser.close()
    text = table(result)
    REPORT.parent.mkdir(exist_ok=True)
    REPORT.write_text(text + "\n", encoding="utf-8")
    print("\n" + text)
    yield result


@pytest.mark.parametrize("cell", CELLS, ids=[c.id for c in CELLS])
def test_stop_always_stops(cell: Cell, verdicts: dict[str, Verdict]) -> None:
    verdict = verdicts[cell.id]
    assert verdict.ok, (
        f"{cell.id}: moved {verdict.dist_mm} mm after the stop (bound {verdict.bound_mm:.3f}"
        f" mm at {verdict.speed_mm_s:.1f} mm/s): " + "; ".join(verdict.problems)
    )

"""S1, S2, S4 and S5 on every modelled link, for smoothjog and for one long jog + 0x85.

Part of `python -m bench jog --links ideal,ch340,...` (default: every link in
smoothjog.sim.rig.LINK_MODELS); the table goes to links.md beside jog.md.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import statistics
import subprocess
from dataclasses import dataclass
from pathlib import Path

from bench import scenarios as sc
from bench.hosts import REFERENCE_FACTORIES, Method, Shipped
from smoothjog.config import Config
from smoothjog.core.engine import Jogger, JogTuning
from smoothjog.sim.rig import LINK_MODELS, LinkModel

LONG_JOG = "one long jog + 0x85"
#: The machine of the per-link table (the one the engine issue measured the links on).
LINK_MACHINE = "hobby-router"
#: The scenarios of the per-link table.
LINK_SCENARIOS = ("S1", "S2", "S4", "S5")


def cli_tuning() -> JogTuning:
    """The tuning `smoothjog jog` and the pendant run with on the default configuration.

    Built as cli/jog.py builds it, from the built-in defaults of config.py ([jog] speed_ratios,
    link_margin_s = 5 ms); the bench's own smoothjog host uses JogTuning() (link margin 0).
    """
    jog = Config().jog
    return JogTuning(speed_ratios=dict(jog.speed_ratios), link_margin_s=jog.link_margin_s)


@dataclass(frozen=True)
class Host:
    """One row's host: a name, the engine factory and the tuning it runs with, in words."""

    name: str
    factory: Method
    tuning: str


def hosts() -> list[Host]:
    """smoothjog with the bench's tuning and with the CLI's, and the long-jog reference."""
    bench_t = JogTuning()
    cli_t = cli_tuning()
    return [
        Host(
            "smoothjog",
            Shipped(bench_t),
            f"bench: JogTuning() (link margin {1000 * bench_t.link_margin_s:g} ms)",
        ),
        Host(
            "smoothjog",
            Shipped(cli_t),
            f"CLI defaults (link margin {1000 * cli_t.link_margin_s:g} ms)",
        ),
        Host(LONG_JOG, REFERENCE_FACTORIES[LONG_JOG], "(its own: no engine tuning)"),
    ]


def phase_link(link: LinkModel, k: int) -> LinkModel:
    """The link of release phase k: its own seed, so the phases sample the link's randomness."""
    return dataclasses.replace(link, seed=1000 * link.seed + k)


def cycle_on_link_s(factory: Method, link: LinkModel) -> float:
    """The host's send cycle on this link, to spread the releases over all of its phases.

    smoothjog's blocks grow with a slow wire (about 78 ms at 9600 baud, see docs/jogging.md)
    and a long round trip; phases spread over the ideal wire's 10.5 ms would sample a small
    part of such a cycle. Measured as the mean time between the jog lines sent
    in a second of full-speed hold; a reference method keeps its own fixed cycle.
    """
    vs, _t0 = sc._session(factory, LINK_MACHINE, "grbl", link)
    try:
        vs.set_intent(sc._stick(1.0))
        vs.run_until(vs.now_s + 1.0)
        driver = vs.driver
        if not isinstance(driver, Jogger):
            return float(getattr(driver, "cycle_s", 0.010))
        sent = driver.stats.jogs_sent
        vs.run_until(vs.now_s + 1.0)
        return 1.0 / max(driver.stats.jogs_sent - sent, 1)
    finally:
        vs.close()


Results = dict[str, dict[int, dict[str, dict[str, float]]]]
Plots = dict[str, dict[int, dict[str, sc.Run]]]


def run_links(
    names: list[str], phases: int, firmware: str = "grbl"
) -> tuple[Results, Plots, list[Host], dict[str, list[float]]]:
    """results[link][host index][scenario] = median metrics over the release phases; also the
    send cycle each host's releases were spread over, per link (cycles[link][host index])."""
    rows = hosts()
    results: Results = {}
    plots: Plots = {}
    cycles: dict[str, list[float]] = {}
    for name in names:
        base = LINK_MODELS[name]
        results[name] = {}
        plots[name] = {}
        cycles[name] = []
        for i, host in enumerate(rows):
            runs: dict[str, list[sc.Run]] = {}
            cycle = cycle_on_link_s(host.factory, base)
            cycles[name].append(cycle)
            for k in range(phases):
                off = cycle * (k + 0.5) / phases
                link = phase_link(base, k)
                f = host.factory
                runs.setdefault("S1", []).append(
                    sc.release(f, LINK_MACHINE, firmware, off, 1.0, link=link)
                )
                runs.setdefault("S2", []).append(sc.hold(f, LINK_MACHINE, firmware, off, link=link))
                runs.setdefault("S4", []).append(
                    sc.client_dies(f, LINK_MACHINE, firmware, off, link=link)
                )
                runs.setdefault("S5", []).append(
                    sc.release(f, LINK_MACHINE, firmware, off, 0.1, link=link)
                )
            results[name][i] = {
                key: {m: statistics.median(r.metrics[m] for r in rs) for m in rs[0].metrics}
                for key, rs in runs.items()
            }
            for key in ("S1", "S5"):
                # The spread over the phases: a median alone hides a release that lands in a gap.
                dists = [r.metrics["dist_mm"] for r in runs[key]]
                results[name][i][key] |= {"dist_lo_mm": min(dists), "dist_hi_mm": max(dists)}
            plots[name][i] = {key: rs[0] for key, rs in runs.items()}
        print(f"  ran the links table on {name}", flush=True)
    return results, plots, rows, cycles


def _mm(value: float, digits: int = 2) -> str:
    return "never" if math.isinf(value) else f"{value:.{digits}f}"


def _spread(r: dict[str, float], digits: int = 2) -> str:
    """The lowest and highest distance over the phases, when the run kept them."""
    if "dist_lo_mm" not in r:
        return "-"
    return f"{_mm(r['dist_lo_mm'], digits)}-{_mm(r['dist_hi_mm'], digits)}"


def cells(r: dict[str, dict[str, float]], ph: sc.Physics) -> list[str]:
    """One row's figures: S1 mm / s, S2 % / dips (mean speed), S4 mm (x v²/2a), S5 mm / ms."""
    s1, s2, s4, s5 = (r[key] for key in LINK_SCENARIOS)
    restarts = f", {int(s1['restarts'])} restarts" if s1["restarts"] else ""
    restarts5 = f", {int(s5['restarts'])} restarts" if s5["restarts"] else ""
    return [
        f"{_mm(s1['dist_mm'])} mm ({_spread(s1)}) / {s1['time_s']:.3f} s{restarts}",
        f"{100 * s2['within_2pct']:.1f} % / {int(s2['dips'])} dips "
        f"(mean {100 * s2['mean_of_v']:.1f} % of v)",
        f"{_mm(s4['dist_mm'])} mm ({_mm(s4['dist_mm'] / ph.stop_mm)}x)",
        f"{_mm(s5['dist_mm'], 3)} mm ({_spread(s5, 3)}) / {1000 * s5['time_s']:.0f} ms{restarts5}",
    ]


def table(results: Results, rows: list[Host], ph: sc.Physics) -> list[str]:
    """Markdown: one row per link and host, then the S1 ratio to the long jog per link."""
    out = [
        "| link | host | tuning | S1 release: distance (phases) / time"
        " | S2 6 s hold: within 2 % / dips"
        " (mean speed)"
        " | S4 client dies: distance (x v²/2a) | S5 10 % release: distance (phases) / time |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, by_host in results.items():
        for i, host in enumerate(rows):
            out.append(
                f"| {name} | {host.name} | {host.tuning} | "
                + " | ".join(cells(by_host[i], ph))
                + " |"
            )
    long_i = next(i for i, h in enumerate(rows) if h.name == LONG_JOG)
    sj = [i for i, h in enumerate(rows) if h.name != LONG_JOG]
    out += [
        "",
        "S1 distance of smoothjog over the long jog's on the same link (target <= 1.05):",
        "",
        "| link | " + " | ".join(f"smoothjog, {rows[i].tuning}" for i in sj) + " |",
        "|---|" + "---|" * len(sj),
    ]
    for name, by_host in results.items():
        long_mm = by_host[long_i]["S1"]["dist_mm"]
        ratios = []
        for i in sj:
            ratio = by_host[i]["S1"]["dist_mm"] / long_mm
            ratios.append(f"{ratio:.3f} ({'met' if ratio <= 1.05 else 'NOT met'})")
        out.append(f"| {name} | " + " | ".join(ratios) + " |")
    return out


def models(names: list[str]) -> list[str]:
    """Markdown: every link's model and parameters."""
    out = [
        "| link | what it models | baud, bits/byte | latency + jitter each way | adapter packets"
        " | stalls | seed |",
        "|---|---|---|---|---|---|---|",
    ]
    for name in names:
        m = LINK_MODELS[name]
        jitter = (
            f"{1000 * m.latency_s:g} ms"
            if m.jitter_s == 0
            else f"{1000 * m.latency_s:g} + {m.jitter_shape} [0, {1000 * m.jitter_s:g}) ms"
        )
        batch = (
            f"{1000 * m.batch_timer_s:g} ms timer or {m.batch_bytes} bytes"
            if m.batch_timer_s
            else "none"
        )
        stalls = (
            f"{1000 * m.stall_s:g} ms every {m.stall_gap_s[0]:g}-{m.stall_gap_s[1]:g} s"
            if m.stall_s
            else "none"
        )
        out.append(
            f"| {name} | {m.description} | {m.baud}, {m.bits_per_byte} | {jitter} | {batch} | "
            f"{stalls} | {m.seed} |"
        )
    return out


def plot(plots: Plots, rows: list[Host], out: Path) -> list[Path]:
    """One PNG per scenario: X velocity against time, one panel per link, every host overlaid."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    names = list(plots)
    for key in LINK_SCENARIOS:
        fig, axes = plt.subplots(len(names), 1, figsize=(9, 1.8 * len(names)), sharex=True)
        axes_list = list(axes) if len(names) > 1 else [axes]
        for ax, name in zip(axes_list, names, strict=True):
            for i, host in enumerate(rows):
                run = plots[name][i][key]
                label = f"{host.name}, {host.tuning}" if host.name != LONG_JOG else host.name
                ax.plot([t for t, _ in run.series], [v for _, v in run.series], lw=1.0, label=label)
            ax.axvline(0.0, color="grey", lw=0.6, ls=":")
            ax.set_ylabel("vx mm/s", fontsize=7)
            ax.set_title(name, fontsize=8, loc="left")
            ax.grid(alpha=0.3)
        axes_list[0].legend(fontsize=6, loc="upper right")
        axes_list[-1].set_xlabel("time (s) from the event: release, death (S2: the press)")
        fig.suptitle(f"{key} on {LINK_MACHINE}, per link (first release phase)", fontsize=10)
        fig.tight_layout()
        path = out / f"links-{key}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        written.append(path)
    return written


def source_hash() -> str:
    """A short SHA-256 over every source file of smoothjog as imported (names and contents)."""
    import smoothjog

    root = Path(smoothjog.__file__).parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:12]


def code_version() -> str:
    """What was measured: the source hash, the commit, and the files changed on top of it.

    Outside a git checkout (a snapshot), $BENCH_CODE_NOTE says what the snapshot is.
    """
    tree = f"smoothjog sources sha256 {source_hash()}"
    note = os.environ.get("BENCH_CODE_NOTE")
    if note:
        tree += f" ({note})"
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
        status = subprocess.run(
            ["git", "status", "--porcelain"], capture_output=True, text=True, check=True
        ).stdout.splitlines()
    except (OSError, subprocess.CalledProcessError):
        return tree if note else f"{tree} (not in a git checkout)"
    changed = sorted(line[3:] for line in status if not line[3:].startswith("bench/results/"))
    if not changed:
        return f"{tree}, commit {head}, clean"
    return f"{tree}, commit {head} with uncommitted changes to {', '.join(changed)}"


def report(names: list[str], phases: int, out: Path, command: str) -> list[str]:
    """Run the per-link table, write links.md and its plots into out; returns the lines."""
    results, plots, rows, cycles = run_links(names, phases)
    cli = next(i for i, h in enumerate(rows) if h.tuning.startswith("CLI defaults"))
    ph = sc.physics(LINK_MACHINE)
    lines = [
        "# Jog benchmark on modelled links",
        "",
        f"Command: `{command}`",
        "",
        f"Code: {code_version()}.",
        "",
        f"{LINK_MACHINE}, Grbl 1.1h profile on every link (the FluidNC telnet row too: only the "
        "wire differs), simulated, soft limits off. "
        f"v = {ph.speed_mm_s:.1f} mm/s, a = {ph.accel_mm_s2:.0f} mm/s², "
        f"v²/2a = {ph.stop_mm:.2f} mm. Medians over {phases} release phases; each phase runs on "
        "its own seed of the link (seed x 1000 + phase), so the medians also sample the link's "
        "jitter, stalls and adapter-timer phase.",
        "",
        "## The links (smoothjog.sim.rig.LINK_MODELS)",
        "",
        *models(names),
        "",
        "## Results",
        "",
        *table(results, rows, ph),
        "",
        "The releases of each row are spread evenly over that host's send cycle on that link"
        " (the mean time between its jog lines during a full-speed hold, measured first);"
        " smoothjog's, CLI defaults: "
        + ", ".join(f"{name} {1000 * by_link[cli]:.1f} ms" for name, by_link in cycles.items())
        + ".",
        "",
        "In brackets after the S1 and S5 distances: the lowest and highest over the phases. "
        "Both smoothjog rows are the engine as it is; the tuning column says which JogTuning the "
        "host built it with. In both, the host hands the engine the modelled wire's byte time "
        "(Link.byte_time_s), as the CLI's serial link does with its baud rate.",
        "",
    ]
    for path in plot(plots, rows, out):
        lines.append(f"![{path.stem}]({path.name})")
    lines.append("")
    return lines


def parse_names(arg: str) -> list[str]:
    """The link names of a --links argument ("all": every model; "none" or "": none)."""
    if arg == "all":
        return list(LINK_MODELS)
    names = [n for n in arg.split(",") if n and n != "none"]
    unknown = [n for n in names if n not in LINK_MODELS]
    if unknown:
        raise SystemExit(
            f"unknown link {', '.join(unknown)}: use {', '.join(LINK_MODELS)}, all or none"
        )
    return names

"""`python -m bench NAME [options]`: run one benchmark (see README.md, "Other commands")."""

from __future__ import annotations

import sys


def main() -> int:
    """Dispatch to a benchmark; with no name, run jog, micro and sim."""
    args = sys.argv[1:]
    name = args[0] if args and not args[0].startswith("-") else "all"
    rest = args[1:] if name != "all" else args
    if name == "jog":
        from bench import jog

        return jog.main(rest)
    if name == "fuzz":
        from bench import fuzz

        return fuzz.main(rest)
    if name == "micro":
        from bench import micro

        return micro.main(rest)
    if name == "sim":
        from bench import bench_sim_speed

        return bench_sim_speed.main()
    if name == "cpu":
        from bench import cpu

        return cpu.main(rest)
    if name == "cncjs":
        from bench import cncjs

        return cncjs.main(rest)
    if name == "proxy":
        from bench import proxy

        return proxy.main(rest)
    if name == "stopat":
        from bench import stopat

        return stopat.main(rest)
    if name == "deadman":
        from bench import deadman

        return deadman.main(rest)
    if name == "lead":
        from bench import lead

        return lead.main(rest)
    if name == "memory":
        from bench import memory

        return memory.main(rest)
    if name == "reset":
        from bench import reset

        return reset.main(rest)
    if name == "all":
        from bench import bench_sim_speed, jog, micro

        code = jog.main(rest)
        code |= micro.main([])
        code |= bench_sim_speed.main()
        return code
    print(
        f"unknown benchmark {name!r}: use jog, fuzz, micro, sim, cpu, cncjs, proxy, deadman,"
        " stopat, lead or reset",
        file=sys.stderr,
    )
    return 2


raise SystemExit(main())

"""`python -m bench NAME [options]`: run one benchmark (see README.md, "Other commands")."""

from __future__ import annotations

import importlib
import sys

#: Each benchmark's name and its module under bench/ (each has main(argv) -> exit code).
BENCHMARKS = {
    "jog": "jog",
    "fuzz": "fuzz",
    "micro": "micro",
    "cpu": "cpu",
    "cncjs": "cncjs",
    "proxy": "proxy",
    "stopat": "stopat",
    "deadman": "deadman",
    "lead": "lead",
    "memory": "memory",
    "reset": "reset",
}


def main() -> int:
    """Dispatch to a benchmark; with no name, run jog, micro and sim."""
    args = sys.argv[1:]
    name = args[0] if args and not args[0].startswith("-") else "all"
    rest = args[1:] if name != "all" else args
    if name == "sim":
        from bench import bench_sim_speed

        return bench_sim_speed.main()
    if name == "all":
        from bench import bench_sim_speed, jog, micro

        code = jog.main(rest)
        code |= micro.main([])
        code |= bench_sim_speed.main()
        return code
    module = BENCHMARKS.get(name)
    if module is None:
        print(f"unknown benchmark {name!r}: use {', '.join(BENCHMARKS)} or sim", file=sys.stderr)
        return 2
    status: int = importlib.import_module(f"bench.{module}").main(rest)
    return status


raise SystemExit(main())

"""``lipgen bench``: run the benchmark suites and write JSON."""

from __future__ import annotations

import argparse
import json
import sys


def add_parser(sub) -> None:
    p = sub.add_parser(
        "bench",
        help="run the benchmarks and write JSON (machine, versions, figures)",
        description="Run lipgen's benchmark suites. Every figure that has a baseline (the thesis's "
        "dense inverse, a bare numpy matmul, pyrender's own render time) is measured in the same "
        "run and reported as a ratio, since these machines are noisy.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--out", default="renders/bench.json", help="JSON file to write")
    p.add_argument("--suite", action="append", dest="suites", metavar="NAME",
                   help="run only this suite (repeatable); see --list")
    p.add_argument("--quick", action="store_true", help="smaller sizes, for a fast check")
    p.add_argument("--list", action="store_true", help="list the suites and exit")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from lipgen.bench import available_suites, run_benchmarks

    if args.list:
        for name, module in sorted(available_suites().items()):
            sys.stdout.write(f"{name}\t{module}\n")
        return 0
    result = run_benchmarks(args.out, suites=args.suites, quick=args.quick)
    summary = {name: s["status"] for name, s in result["suites"].items()}
    sys.stdout.write(json.dumps(summary, indent=2) + f"\nwrote {args.out}\n")
    return 0 if all(v == "ok" for v in summary.values()) else 1

"""The ``ijoy`` command line."""

from __future__ import annotations

import argparse
import json
import sys


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ijoy", description="The intelligent joystick for legged robots, in JAX.")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="walk HRP-2 through clutter with the intelligent and a naive joystick; "
                                       "write a PNG of the footholds")
    demo.add_argument("--out", default="ijoy_demo.png", help="PNG to write (default: %(default)s)")
    demo.add_argument("--steps", type=int, default=24, help="number of steps (default: %(default)s)")
    demo.add_argument("--margin", type=float, default=0.02, help="safety margin in metres (default: %(default)s)")
    bench = sub.add_parser("bench", help="run a benchmark and print JSON lines (see BENCHMARKS.md)")
    bench.add_argument("name", choices=["footcost", "select", "check"],
                       help="footcost: evaluations/s; select: decisions/s, rollout steps/s and the NumPy baseline; "
                            "check: fixed decisions saved to / compared with --ref (device agreement)")
    bench.add_argument("--ref", default=None, help="npz of reference decisions for 'check'")
    bench.add_argument("--quick", action="store_true", help="small sizes, for a smoke test")
    bench.add_argument("--json", default=None, help="also write the results to this file")
    args = parser.parse_args(argv)
    if args.command == "demo":
        from ijoy_jax import demo as demo_mod

        result = demo_mod.run(args.out, args.steps, args.margin)
        print(json.dumps(result, indent=2))
        return 0
    if args.command == "bench":
        from ijoy_jax import bench as bench_mod

        rows = bench_mod.run(args.name, quick=args.quick, path=args.ref)
        if args.json:
            with open(args.json, "w") as f:
                json.dump(rows, f, indent=2)
        return 0
    return 2


if __name__ == "__main__":
    sys.exit(main())

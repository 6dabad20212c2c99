"""``ijoy demo``: the paper's Fig. 3 from the command line (the walk itself: :mod:`ijoy_jax.apps.demo`).

Kept here so that :mod:`ijoy_jax.apps.cli` only registers the subcommand (:func:`add_parser`) and dispatches
to :func:`main`.
"""

from __future__ import annotations

import json

from ijoy_jax.apps.options import output_file, positive_int


def add_parser(sub) -> None:
    """Register ``demo`` on an argparse subparsers object."""
    demo = sub.add_parser(
        "demo",
        help="walk HRP-2 through clutter with the intelligent and a naive joystick; write a PNG of the footholds",
        description="The paper's Fig. 3: HRP-2 walks forward at 0.25 m/s through a 4 x 2.4 m "
        "cluttered map, once with the intelligent joystick and once with a naive one "
        "(the lattice step nearest the command). Prints both walks' summaries as "
        "JSON and draws their footholds in one PNG.",
    )
    demo.add_argument("--out", default="ijoy_demo.png", type=output_file, help="PNG to write (default: %(default)s)")
    demo.add_argument("--steps", type=positive_int, default=24, help="number of steps (default: %(default)s)")
    demo.add_argument("--margin", type=float, default=0.02, help="safety margin in metres (default: %(default)s)")


def main(args) -> int:
    """Run ``ijoy demo`` from parsed arguments: both walks' summaries as JSON (bad values raise ValueError)."""
    from ijoy_jax.apps import demo as demo_mod

    result = demo_mod.run(args.out, args.steps, args.margin)
    print(json.dumps(result, indent=2))
    return 0

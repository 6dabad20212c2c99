"""``ijoy cue study`` and ``ijoy cue field``: does the haptic cue help, and what it looks like.

Kept here so that :mod:`ijoy_jax.apps.cli` only registers the subcommand (:func:`add_parser`) and
dispatches to :func:`main`.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from ijoy_jax.apps.options import output_file, output_folder, positive_int


def add_parser(sub) -> None:
    """Register ``cue`` (with ``study`` and ``field``) on an argparse subparsers object."""
    cue = sub.add_parser("cue", help="the haptic cue: the operator study (cue on/off, tuned) and its field plots",
                         description="The force-feedback cue of ijoy_jax.cue: a simulated operator drives the "
                                     "perfect robot through random scenarios with the cue off, on and tuned by "
                                     "gradient (ijoy_jax.cue.study), or the paper's scenarios drawn in command "
                                     "space (ijoy_jax.cue.plot).")
    csub = cue.add_subparsers(dest="cue_command", required=True)
    st = csub.add_parser("study", help="tune the cue on training scenarios, compare off / on / tuned on held-out "
                                       "ones; write result.json, study.md and PNGs to --out",
                         description="A simulated operator drives the perfect robot through random scenarios of "
                                     "each family with the cue off, on, and tuned by gradient on training "
                                     "scenarios (ijoy_jax.cue.study); the three are compared on held-out "
                                     "scenarios with 95%% intervals. Writes result.json, study.md, study.png and "
                                     "field.png to --out.")
    st.add_argument("--out", default="results/cue_study", type=output_folder,
                    help="output folder (created; files in it are overwritten; default: %(default)s)")
    st.add_argument("--train", type=int, default=8, help="training scenarios per family (default: %(default)s)")
    st.add_argument("--held-out", type=int, default=40,
                    help="held-out scenarios per family (default: %(default)s)")
    st.add_argument("--steps", type=positive_int, default=30, help="decisions per drive (default: %(default)s)")
    st.add_argument("--tune-steps", type=int, default=40, help="Adam steps (default: %(default)s; 0: no tuning)")
    st.add_argument("--learning-rate", type=float, default=0.05, help="Adam's (default: %(default)s)")
    st.add_argument("--seed", type=int, default=0, help="training scenarios; held-out use seed + 1 (default: 0)")
    st.add_argument("--quick", action="store_true", help="2 training and 3 held-out scenarios per family, 12 "
                                                        "decisions, 3 Adam steps (a smoke test)")
    fld = csub.add_parser("field", help="draw the paper's scenarios (wall ahead, sidestep along a wall, clutter) "
                                        "with the cue field in command space",
                          description="The paper's scenarios (a wall ahead, a sidestep along a wall, clutter) drawn "
                                      "beside the cue's force field in command space (ijoy_jax.cue.plot), with the "
                                      "default cue parameters; writes one PNG.")
    fld.add_argument("--out", default="ijoy_cue_field.png", type=output_file,
                     help="PNG to write (default: %(default)s)")


def main(args) -> int:
    """Run ``ijoy cue study`` or ``ijoy cue field`` from parsed arguments (bad values raise ValueError)."""
    import matplotlib

    matplotlib.use("Agg")
    from ijoy_jax import robots
    from ijoy_jax.cue import plot

    robot = robots.hrp2(margin=0.02)
    if args.cue_command == "field":  # --out checked as parsed
        from ijoy_jax.progress import compiling

        with compiling("the cue's field over the paper's three scenes", prefix="ijoy cue field: "):
            plot.scenario_figure(plot.paper_cases(), robot, out=args.out)  # the compile; drawing is quick
        print(json.dumps({"png": args.out}))
        return 0
    return study(args, robot)


def study(args, robot) -> int:
    """``ijoy cue study``: tune, then compare off / on / tuned on held-out scenarios; write the results."""
    import numpy as np

    from ijoy_jax import cue, stats
    from ijoy_jax.cue import plot
    from ijoy_jax.cue import study as S

    if args.quick:
        args.train, args.held_out, args.steps, args.tune_steps = 2, 3, 12, 3
    for name in ("train", "held_out", "steps"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be at least 1, got {getattr(args, name)}")
    if args.tune_steps < 0 or not args.learning_rate > 0:
        raise ValueError("--tune-steps must be >= 0 and --learning-rate > 0")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cfg = S.StudyConfig(num_steps=args.steps)
    t0 = time.perf_counter()
    conditions = {"off": None, "cue": cue.make_params()}
    record = {"config": {k: v for k, v in vars(args).items() if k not in ("command", "cue_command")},
              "operator": {k: float(v) for k, v in vars(S.default_operator()).items()},
              "default_params": _plain(cue.make_params())}
    if args.tune_steps:
        train = S.make_scenarios(args.seed, args.train)
        tuned = S.tune_cue(train, robot, cfg=cfg, steps=args.tune_steps, learning_rate=args.learning_rate)
        conditions["tuned"] = tuned.params
        record["tuning"] = {"losses": np.asarray(tuned.losses).tolist(), "best_step": tuned.best,
                            "terms": {k: np.asarray(v).tolist() for k, v in tuned.terms.items()},
                            "tuned_params": _plain(tuned.params), "scenarios": int(train.family.shape[0])}
        print(json.dumps({"tuned": record["tuning"]["tuned_params"], "best_step": tuned.best,
                          "loss_first_best": [float(tuned.losses[0]), float(tuned.losses[tuned.best])]}), flush=True)
    held = S.make_scenarios(args.seed + 1, args.held_out)
    res = S.compare(held, robot, conditions, cfg=cfg)
    by_family = {}
    names = list(conditions)
    per = res["per_scenario"]
    for fam in S.FAMILIES:
        pick = np.array([f == fam for f in res["family"]])
        by_family[fam] = {
            "summary": {c: {m: stats.mean_ci(v[m][pick]) for m in S.METRICS} for c, v in per.items()},
            "difference": {c: {m: stats.mean_ci((per[c][m] - per[names[0]][m])[pick]) for m in S.METRICS}
                           for c in names[1:]},
            "n": int(pick.sum())}
    record.update(summary=res["summary"], difference=res["difference"], by_family=by_family, n=res["n"],
                  seconds=time.perf_counter() - t0)
    table = S.markdown(res, f"held-out scenarios, seed {args.seed + 1}")
    for fam in S.FAMILIES:
        table += "\n\n" + S.markdown(by_family[fam], f"family {fam}")
    (out / "study.md").write_text(table + "\n")
    (out / "result.json").write_text(json.dumps(record, indent=2, default=float) + "\n")
    plot.study_figure(res, out=str(out / "study.png"))
    plot.scenario_figure(plot.paper_cases(), robot, params=conditions.get("tuned"), out=str(out / "field.png"))
    print(table)
    print(json.dumps({"out": str(out), "seconds": round(record["seconds"], 1)}))
    return 0


def _plain(p) -> dict:
    import numpy as np

    return {k: np.asarray(v).tolist() for k, v in vars(p).items()}

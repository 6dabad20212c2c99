"""Benchmarks behind ``ijoy bench NAME`` (results go to BENCHMARKS.md by hand).

Each row reports compile time and steady-state run time separately (median
of repeated calls after ``block_until_ready``), the throughput, and XLA's own
FLOP and byte counts per decision for the roofline. Everything runs on the
default JAX device, so the same command measures the CPU here and a GPU on
the lent machine.

  footcost  candidate foothold evaluations per second (HRP-2, 2 cm grid, 2D and 2.5D)
  lookahead decision time of the selectors beyond the paper: one-step exhaustive, the exact two-step
            lookahead, all 246 k pairs of HRP-2 (a beam of the whole action set), the three-step beam, and
            continuous refinement alone and after the lookahead, on 2D and 2.5D maps; then the beam's loss
            against the exact search on decisions met by one-step walks on the constrained families.
  select    full decisions per second (exhaustive and ordered, 2.5D with swing path; ordered also with
            windows sized for the 2 cm margin; on a GPU both again with the fused Pallas FootCost kernel, and
            exhaustive with it on a map of posts taller than the clearance, where its corridor broad phase fails),
            each row with the FootCosts a decision evaluated on average (``actions_per_decision``: the action
            set's size for the exhaustive search, fewer for the paper's ordered one), closed-loop rollout
            steps per second (robots on one shared terrain, and each on its own 2 m x 2 m terrain as in
            sweeps), and the NumPy implementation
            of the paper's algorithm in the same run, for the ratio. ``--kernel`` and ``--parts`` run some
            of it (``--kernel pallas --parts decisions``: the fused kernel's decision rates alone, a few
            minutes on a GPU).
"""

from __future__ import annotations

import json
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np

import ijoy_jax as ij
from ijoy_jax import footcost, select
from ijoy_jax.apps.options import names_of, output_file
from ijoy_jax.control import rollout

GRID = (200, 200)  # 4 m x 4 m
RES = 0.02


def workload_terrain(has_height: bool, seed: int = 0) -> ij.Terrain:
    """The benchmarks' 4 m x 4 m map at 2 cm (:data:`GRID`, :data:`RES`): 0.2 % obstacle cells and, 2.5D, a 3 cm
    swell along x plus 2 mm noise; the same map for the same ``seed``."""
    rng = np.random.default_rng(seed)
    free = rng.random(GRID) > 0.002
    h = None
    if has_height:
        x = np.arange(GRID[0])[:, None] * RES
        h = (0.03 * np.sin(2.0 * x) + 0.002 * rng.standard_normal(GRID)).astype(np.float32)
    return ij.terrain.from_arrays(h, free, RES)


def _indexed(terrain: ij.Terrain, robot) -> footcost.TerrainIndex:
    """``terrain``'s :class:`~ijoy_jax.footcost.TerrainIndex` for ``robot``, built by one jitted call (the robot's
    window sizes are static, so it is closed over)."""
    return jax.jit(lambda t: footcost.index_terrain(t, robot))(terrain)


def _posts(seed: int = 5) -> ij.Terrain:
    """The 2.5D benchmark map with 30 posts 12-25 cm tall and 2-12 cm wide: taller than the HRP-2 preset's 10 cm
    clearance, so the fused kernel's swing-corridor broad phase rarely applies and its exact walk runs."""
    base = workload_terrain(True)
    rng = np.random.default_rng(seed)
    h = np.asarray(base.height).copy()
    for _ in range(30):
        i, j = rng.integers(0, 195, 2)
        a, b = rng.integers(1, 7, 2)
        h[i:i + a, j:j + b] += rng.uniform(0.12, 0.25)
    return ij.terrain.from_arrays(h.astype(np.float32), np.asarray(base.free), RES)


def workload_queries(n: int, seed: int = 1):
    """``n`` decisions on :func:`workload_terrain`: (stance (n, 3), command (n, 3), swing_from (n, 3)), the
    stance foot inside the map, the left swing foot behind and beside it; the same for the same ``seed``."""
    rng = np.random.default_rng(seed)
    stance = np.column_stack([rng.uniform(1.0, 3.0, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    command = np.column_stack([rng.uniform(-0.25, 0.25, n), rng.uniform(-0.15, 0.15, n), rng.uniform(-0.4, 0.4, n)])
    c, s = np.cos(stance[:, 2]), np.sin(stance[:, 2])
    rel = np.column_stack([rng.uniform(-0.2, 0.2, n), -rng.uniform(0.19, 0.33, n)])  # left swing foot behind
    swing = np.column_stack([stance[:, 0] + c * rel[:, 0] - s * rel[:, 1], stance[:, 1] + s * rel[:, 0] + c * rel[:, 1],
                             stance[:, 2]])
    f = lambda a: jnp.asarray(a, jnp.float32)  # noqa: E731
    return f(stance), f(command), f(swing)


def _starts(robot, b: int, x: float, y0: float, rows: int):
    """(b, 2, 3) start poses, feet side by side facing +x at ``x``, staggered in y from ``y0`` in ``rows`` rows."""
    y = y0 + 0.01 * (np.arange(b) % rows)
    return jax.vmap(lambda yi: ij.robots.start_stance(robot, x, yi))(jnp.asarray(y, jnp.float32))


def _time(fn, *args, repeats: int = 10, min_seconds: float = 0.5, max_seconds: float = 8.0, outputs=None):
    """(compile s, median run s, flops, bytes) of ``fn(*args)``, compiled ahead of time; ``outputs``: a list that
    gets the first call's result appended (what the timed program returned, without compiling it again)."""
    t0 = time.perf_counter()
    compiled = fn.lower(*args).compile()
    compile_s = time.perf_counter() - t0
    first = jax.block_until_ready(compiled(*args))
    if outputs is not None:
        outputs.append(first)
    times = []
    start = time.perf_counter()
    while len(times) < 2 or (
        time.perf_counter() - start < max_seconds
        and (len(times) < repeats or (time.perf_counter() - start < min_seconds and len(times) < 1000))
    ):
        t0 = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        times.append(time.perf_counter() - t0)
    cost = compiled.cost_analysis()
    cost = cost[0] if isinstance(cost, (list, tuple)) else cost
    cost = cost or {}
    flops, nbytes = float(cost.get("flops", np.nan)), float(cost.get("bytes accessed", np.nan))
    return compile_s, float(np.median(times)), flops, nbytes


def _cpu() -> bool:
    return jax.devices()[0].platform == "cpu"


def _env() -> dict:
    dev = jax.devices()[0]
    return {"device": getattr(dev, "device_kind", str(dev)), "platform": dev.platform, "jax": jax.__version__,
            "cpu": platform.processor() or platform.machine(), "date": time.strftime("%Y-%m-%d")}


def _emit(rows: list, row: dict) -> None:
    rows.append(row)
    print(json.dumps(row), flush=True)


def _batched(one, chunk: int):
    """Map ``one`` over a batch in vmapped chunks of ``chunk`` (bounded memory for huge batches)."""

    def run(*args):
        n = args[0].shape[0]
        if n <= chunk:
            return jax.vmap(one)(*args)
        return jax.lax.map(lambda a: one(*a), args, batch_size=chunk)

    return jax.jit(run)


def bench_footcost(rows, quick: bool, chunk: int):
    robot = ij.robots.hrp2(margin=0.02)
    n_act = robot.num_actions
    sizes = [1, 16] if quick else ([1, 16, 256, 2048] if _cpu() else [1, 16, 256, 2048, 16384, 65536])
    for has_height in (False, True):
        terrain = workload_terrain(has_height)
        index = _indexed(terrain, robot)

        def one(stance, swing, terrain=terrain, index=index):
            steps = ij.action_steps(robot, stance, -1)
            return footcost.foot_cost_terms(terrain, robot, stance, -1, steps, swing_from=swing,
                                            action_index=jnp.arange(n_act), index=index).total

        f = _batched(one, chunk)
        for b in sizes:
            stance, _, swing = workload_queries(b)
            comp, run, flops, nbytes = _time(f, stance, swing)
            _emit(rows, dict(_env(), bench="footcost", terrain="2.5D" if has_height else "2D", batch=b,
                             candidates=b * n_act, compile_s=round(comp, 3), run_s=run,
                             evals_per_s=b * n_act / run, flops_per_eval=flops / (b * n_act),
                             bytes_per_eval=nbytes / (b * n_act)))


KERNELS = ("xla", "pallas")
"""FootCost's implementations ``ijoy bench select --kernel`` chooses between: XLA's and the fused Pallas kernel."""

SELECT_PARTS = ("decisions", "rollouts", "numpy")
"""The parts of ``ijoy bench select``, in the order they run: batched decisions per second, closed-loop rollout
steps per second of the perfect walker, and the paper's algorithm in NumPy."""


def select_kernels(kernels=None) -> tuple[str, ...]:
    """The FootCost implementations ``ijoy bench select`` times: ``kernels`` (some of "xla", "pallas") checked,
    or by default XLA's and, on a GPU, the fused kernel's. ValueError for the fused kernel on a CPU, where it only
    runs interpreted (a test of its arithmetic, not a speed)."""
    if kernels is None:
        return ("xla",) if _cpu() else ("xla", "pallas")
    kernels = tuple(kernels)
    unknown = [k for k in kernels if k not in KERNELS]
    if unknown or not kernels:
        raise ValueError(f"kernel must be xla or pallas, got {list(kernels)}")
    if "pallas" in kernels and _cpu():
        raise ValueError("--kernel pallas: the fused kernel's speed needs a GPU (on a CPU it runs interpreted); "
                         "this machine's JAX device is a CPU")
    return kernels


def bench_select(rows, quick: bool, chunk: int, kernels=None, parts=SELECT_PARTS):
    """``ijoy bench select``: the ``parts`` of :data:`SELECT_PARTS` asked for, with the FootCost implementations
    ``kernels`` (:func:`select_kernels`); the NumPy part has no kernel."""
    kernels = select_kernels(kernels)
    unknown = [p for p in parts if p not in SELECT_PARTS]
    if unknown or not parts:
        raise ValueError(f"unknown parts {unknown or list(parts)}; known: {', '.join(SELECT_PARTS)}")
    robot = ij.robots.hrp2(margin=0.02)
    targets = ij.make_targets(robot)
    terrain = workload_terrain(True)
    index = _indexed(terrain, robot)
    if "decisions" in parts:
        _select_decisions(rows, quick, chunk, kernels, robot, targets, terrain, index)
    if "rollouts" in parts:
        _select_rollouts(rows, quick, kernels, robot, targets, terrain)
    if "numpy" in parts:
        _select_numpy(rows, quick, robot, targets, terrain)


def _select_decisions(rows, quick, chunk, kernels, robot, targets, terrain, index):
    """Batched decisions per second of every selector case on the benchmark map, with each of ``kernels``."""
    sizes = [1, 16] if quick else ([1, 16, 256, 1024] if _cpu() else [1, 16, 256, 4096, 32768])
    # The default windows cover margins up to 10 cm (a margin sweep never recompiles); the last case sizes them
    # for the 2 cm in use (``max_margin=0.02``): the same decisions, less work per candidate.
    cases, tight = [], None
    if "xla" in kernels:
        tight = ij.robots.hrp2(margin=0.02, max_margin=0.02)
        tight_index = _indexed(terrain, tight)
        # The paper's 2D occupancy grid too (the same map's obstacles, no heights): its own code path (exact
        # coverage, no plane fit), whose 3x slowdown went unseen for days while only the 2.5D rows were re-run.
        flat = workload_terrain(False)
        flat_index = _indexed(flat, robot)
        cases += [("2.5D", terrain, "exhaustive", "xla", robot, index, sizes),
                  ("2.5D", terrain, "ordered", "xla", robot, index, sizes),
                  ("2.5D", terrain, "ordered", "xla", tight, tight_index, sizes[:2]),
                  ("2D", flat, "exhaustive", "xla", robot, flat_index, sizes),
                  ("2D", flat, "ordered", "xla", robot, flat_index, sizes)]
    if "pallas" in kernels:  # the fused Pallas kernel (select_kernels refuses it on a CPU)
        big = sizes + ([] if quick else [131072])
        cases += [("2.5D", terrain, "exhaustive", "pallas", robot, index, big),
                  ("2.5D", terrain, "ordered", "pallas", robot, index, big)]
        # Where the swing corridor's broad phase fails: the exact corridor walk runs for most blocks.
        posts = _posts()
        posts_index = _indexed(posts, robot)
        cases += [("2.5D posts", posts, "exhaustive", "pallas", robot, posts_index, sizes[-2:])]
    for terrain_name, tmap, method, kernel, rb, ix, batches in cases:
        options = ij.SelectOptions(method=method, kernel=kernel)

        def one(stance, command, swing, tmap=tmap, options=options, rb=rb, ix=ix):
            c = select.select_step(tmap, rb, stance, -1, command, options, swing_from=swing, targets=targets,
                                   index=ix)
            return c.index, c.cost, c.evaluated

        # The kernel keeps its intermediates on chip, so a whole batch fits at once.
        f = _batched(one, chunk if kernel == "xla" else 1 << 20)
        max_margin = 0.02 if rb is tight else 0.1
        for b in batches:
            stance, command, swing = workload_queries(b)
            out = []
            if b == 1:  # one decision as a user makes it: no vmap over a batch of one (slower; benchmarks_history)
                comp, run, flops, nbytes = _time(jax.jit(one), stance[0], command[0], swing[0], outputs=out)
            else:
                comp, run, flops, nbytes = _time(f, stance, command, swing, outputs=out)
            _emit(rows, dict(_env(), bench="select", method=method, kernel=kernel, max_margin=max_margin,
                             terrain=terrain_name, batch=b,
                             # FootCosts a decision evaluated, on average (exhaustive: the action set's size)
                             actions_per_decision=float(np.mean(np.asarray(out[0][2]))),
                             compile_s=round(comp, 3), run_s=run, decisions_per_s=b / run,
                             us_per_decision=1e6 * run / b, flops_per_decision=flops / b,
                             bytes_per_decision=nbytes / b))


def _select_rollouts(rows, quick, kernels, robot, targets, terrain):
    """Closed-loop rollout steps per second of the perfect walker, with each of ``kernels``."""
    # Closed loop: B robots walking 16 steps on the same 2.5D terrain.
    steps = 16
    cmd = jnp.array([0.2, 0.0, 0.1], jnp.float32)
    loops = [(m, k) for m, k in (("ordered", "xla"), ("ordered", "pallas"), ("exhaustive", "pallas")) if k in kernels]
    for method, kernel in loops:
        for b in ([1, 8] if quick else ([1, 64] if _cpu() else [1, 64, 1024, 8192, 32768])):
            if kernel == "xla" and b > 8192:
                continue  # XLA materialises per-candidate windows: its rows stop at the sizes of earlier runs
            starts = _starts(robot, b, 1.0, 1.0, 50)
            f = jax.jit(jax.vmap(lambda s, options=ij.SelectOptions(method=method, kernel=kernel): rollout(
                terrain, robot, s, cmd, steps, options, targets=targets).footsteps))
            comp, run, _, _ = _time(f, starts, repeats=3, min_seconds=0.2)
            _emit(rows, dict(_env(), bench="rollout", method=method, kernel=kernel, terrain="2.5D", batch=b,
                             steps=steps, compile_s=round(comp, 3), run_s=run, steps_per_s=b * steps / run))
    # A robot per terrain, as in sweeps: B robots, each on its own 2 m x 2 m 2.5D map (the per-terrain tables are
    # built once per rollout, in index_terrain; inside the step they would be rebuilt every step).
    grid = (100, 100)
    x = jnp.arange(grid[0], dtype=jnp.float32)[:, None] * RES
    flat = ij.terrain.from_arrays(np.zeros(grid, np.float32), np.ones(grid, bool), RES)
    for b in ([2] if quick else ([16] if _cpu() else [64, 1024, 4096])):
        heights = jax.vmap(lambda i: 0.03 * jnp.sin(2.0 * x + 0.1 * i)
                           + 0.002 * jax.random.normal(jax.random.key(i), grid))(jnp.arange(b))
        terrains = jax.vmap(lambda h: flat.replace(height=h))(heights)
        starts = _starts(robot, b, 0.5, 0.8, 40)
        for method, kernel in loops:
            f = jax.jit(jax.vmap(lambda t, s, options=ij.SelectOptions(method=method, kernel=kernel): rollout(
                t, robot, s, cmd, steps, options, targets=targets).footsteps))
            comp, run, _, _ = _time(f, terrains, starts, repeats=3, min_seconds=0.2)
            _emit(rows, dict(_env(), bench="rollout", method=method, kernel=kernel, terrain="2.5D, one per robot",
                             batch=b, steps=steps, compile_s=round(comp, 3), run_s=run, steps_per_s=b * steps / run))


def _select_numpy(rows, quick, robot, targets, terrain):
    """The paper's algorithm in plain NumPy, same terrain and queries, one decision at a time."""
    from ijoy_jax.testing import NumpyFootCost, ordered_select

    ref = NumpyFootCost(terrain, robot)
    n = 5 if quick else 20
    stance, command, swing = (np.asarray(a, np.float64) for a in workload_queries(n))
    t0 = time.perf_counter()
    for q in range(n):
        ordered_select(ref, targets, stance[q], -1, command[q], swing[q])
    run = (time.perf_counter() - t0) / n
    _emit(rows, dict(_env(), bench="select", method="numpy-ordered", terrain="2.5D", batch=1, run_s=run,
                     decisions_per_s=1.0 / run, us_per_decision=1e6 * run))


_EVALS_AT_ONCE = {"one-step": 496, "lookahead H=2 exact": 8 * 496, "lookahead H=2 all pairs": 496 * 496,
                  "lookahead H=3 beam 16": 16 * 496, "refine": 4 * 27, "lookahead H=2 exact + refine": 8 * 496}
# FootCost evaluations one decision of each selector holds in memory at once (an iteration of the exact search, a
# level of the beam, a move of the refinement): what the benchmark's vmapped chunks are sized by.

LOOKAHEAD_SELECTORS = (
    ("one-step", dict(method="exhaustive")),
    ("lookahead H=2 exact", dict(method="lookahead", horizon=2)),
    ("lookahead H=2 all pairs", dict(method="lookahead", horizon=2, beam=-1)),  # beam -1: the whole action set
    ("lookahead H=3 beam 16", dict(method="lookahead", horizon=3, beam=16)),
    ("refine", dict(method="exhaustive", refine=True)),
    ("lookahead H=2 exact + refine", dict(method="lookahead", horizon=2, refine=True)),
)
"""The selectors ``ijoy bench lookahead`` times: name and the fields of its :class:`ijoy_jax.SelectOptions`."""


def _constrained_decisions(robot, per_family: int, steps: int, seed: int = 0):
    """Decisions a one-step walker meets on the sweeps' constrained families (stone path at 0.15-0.25 m/s,
    corridor with pockets, dense clutter with turning): per family (name, terrains (B, ...), and per decision
    (B * steps) the terrain row, stance, stance side, swing foot and command)."""
    from ijoy_jax.terrain import generators as gen

    shape = (200, 100)
    fams = {
        "stone_path": ("stone_path", gen.StonePathParams(start_x=0.1, size=0.36, pitch=0.4, first=0.2,
                                                         pitch_jitter=0.02), None, ((0.15, 0.25), (0, 0), (0, 0))),
        "corridor": ("corridor", gen.CorridorParams(start_x=0.1, length=2.5, width_end=0.42, count=3), None,
                     ((0.25, 0.25), (-0.1, 0.1), (0, 0))),
        "clutter": ("obstacles", gen.ObstacleParams(count=30), 32, ((0.1, 0.25), (-0.05, 0.05), (-0.3, 0.3))),
    }
    targets = ij.make_targets(robot)
    out = []
    for i, (label, (family, params, slots, ranges)) in enumerate(fams.items()):
        keys = jax.random.split(jax.random.key(seed + i), per_family)
        extra = {} if slots is None else {"max_count": slots}
        terrains = gen.batch(family, keys, params, shape=shape, **extra)
        c = gen.start_point(params, shape=shape)
        start = ij.robots.start_stance(robot, c[0], c[1])
        rng = np.random.default_rng(seed + i)
        cmds = np.stack([rng.uniform(lo, hi, per_family) for lo, hi in ranges], -1).astype(np.float32)
        walk = jax.jit(jax.vmap(lambda t, cmd, start=start: ij.rollout(t, robot, start, cmd, steps, targets=targets)))
        traj = walk(terrains, jnp.asarray(cmds))
        # The feet before each decision: the start, then each step's landing replaces its side's foot.
        feet = np.broadcast_to(np.asarray(start), (per_family, 2, 3)).copy()
        rows = []
        for k in range(steps):
            sides = np.asarray(traj.sides[:, k])
            for b in range(per_family):
                swing_row = 0 if sides[b] > 0 else 1
                rows.append((b, feet[b, 1 - swing_row].copy(), -float(sides[b]), feet[b, swing_row].copy(), cmds[b]))
            feet[np.arange(per_family), np.where(sides > 0, 0, 1)] = np.asarray(traj.footsteps[:, k])
        out.append((label, terrains, rows))
    return out


def bench_lookahead(rows, quick: bool, chunk: int):
    """Decision time of each of :data:`LOOKAHEAD_SELECTORS` (2D and 2.5D, batched), then the beam's loss."""
    robot = ij.robots.hrp2(margin=0.02)
    n = robot.num_actions
    targets = ij.make_targets(robot)
    cpu = _cpu()
    for has_height in (False, True):
        terrain = workload_terrain(has_height)
        index = _indexed(terrain, robot)
        for name, kw in LOOKAHEAD_SELECTORS:
            kw = dict(kw, beam=n) if kw.get("beam") == -1 else kw
            every_pair = kw.get("beam") == n
            if quick:
                sizes = [1, 4]
            elif every_pair:
                sizes = [1, 4] if cpu else [1, 64]
            else:
                sizes = [1, 16] if cpu else [1, 256, 4096]

            def one(stance, command, swing, options=ij.SelectOptions(**kw), terrain=terrain, index=index):
                c = select.select_step(terrain, robot, stance, -1, command, options, swing_from=swing,
                                       targets=targets, index=index)
                return c.index, c.evaluated

            # Vmapped chunks of about the one-step's FootCost evaluations at once (``chunk`` decisions of N):
            # a lookahead decision evaluates ~10-500x as many.
            f = _batched(one, max(1, chunk * n // _EVALS_AT_ONCE[name]))
            for b in sizes:
                stance, command, swing = workload_queries(b)
                args = (stance[0], command[0], swing[0]) if b == 1 else (stance, command, swing)
                fn = jax.jit(one) if b == 1 else f
                comp, run, _, _ = _time(fn, *args, repeats=5, min_seconds=0.3, max_seconds=20.0)
                evaluated = float(np.mean(np.asarray(fn(*args)[1])))
                _emit(rows, dict(_env(), bench="lookahead", selector=name, terrain="2.5D" if has_height else "2D",
                                 batch=b, compile_s=round(comp, 3), run_s=run, decisions_per_s=b / run,
                                 us_per_decision=1e6 * run / b, footcost_evals_per_decision=evaluated))
    # The beam's loss against the exact search, on decisions from one-step walks of the constrained families.
    per_family, steps = (2, 4) if quick else ((8, 12) if cpu else (64, 16))
    cases = [(2, k) for k in (1, 4, 16, 64)] + [(3, k) for k in (4, 16, 64)]
    for label, terrains, decisions in _constrained_decisions(robot, per_family, steps):
        idx = np.asarray([d[0] for d in decisions])
        maps = jax.tree_util.tree_map(lambda a, idx=idx: a[idx], terrains)  # each decision's terrain
        stance, side, swing, command = (jnp.asarray(np.stack([d[j] for d in decisions]), jnp.float32)
                                        for j in (1, 2, 3, 4))

        def plan(st, t, sd, sw, cmd, horizon, beam):  # stance first: _batched reads the batch size from it
            options = ij.SelectOptions(method="lookahead", horizon=horizon, beam=beam)
            return select.lookahead_plan(t, robot, st, sd, cmd, options, swing_from=sw, targets=targets)

        exact = {}
        for horizon in (2, 3):
            # Decisions in vmapped chunks (the exact search of H = 3 holds chunk x chunk x N FootCosts per decision).
            f = _batched(lambda *a, h=horizon: plan(*a, h, None), 128 if horizon == 2 else 16)
            t0 = time.perf_counter()
            exact[horizon] = jax.block_until_ready(f(stance, maps, side, swing, command))
            _emit(rows, dict(_env(), bench="lookahead-exact", family=label, horizon=horizon,
                             decisions=len(decisions), run_s_with_compile=time.perf_counter() - t0,
                             footcost_evals_mean=float(np.mean(np.asarray(exact[horizon].evaluated))),
                             footcost_evals_max=float(np.max(np.asarray(exact[horizon].evaluated)))))
        for horizon, k in cases:
            f = _batched(lambda *a, h=horizon, k=k: plan(*a, h, k), max(1, (128 if horizon == 2 else 64) * 16 // k))
            got = f(stance, maps, side, swing, command)
            ref = exact[horizon]
            a, b = np.asarray(got.score, np.float64), np.asarray(ref.score, np.float64)
            both = np.isfinite(a) & np.isfinite(b)
            loss = a[both] - b[both]
            _emit(rows, dict(_env(), bench="lookahead-beam", family=label, horizon=horizon, beam=k,
                             decisions=len(decisions), same_first_step=float(np.mean(
                                 np.asarray(got.first) == np.asarray(ref.first))),
                             score_loss_mean=float(loss.mean()) if loss.size else 0.0,
                             score_loss_p95=float(np.quantile(loss, 0.95)) if loss.size else 0.0,
                             worse_rate=float(np.mean(loss > 1e-4)) if loss.size else 0.0,
                             beam_found_none=int(np.sum(~np.isfinite(a) & np.isfinite(b)))))
    turning_overshoot(rows, quick)


def turning_overshoot(rows, quick: bool):
    """The turn-axis overshoot before (the paper's rate mode) and after (heading hold), with a simulated operator
    (:func:`ijoy_jax.turning.overshoot_study`): turning on the spot and while walking, without and with the
    paper's one decision of latency, on the lattice and refined. Degrees; 95% t intervals of the mean."""
    from ijoy_jax import turning
    from ijoy_jax.stats import mean_ci

    robot = ij.robots.hrp2(margin=0.02)
    num = 16 if quick else 256
    for forward in (0.0, 0.15):
        for latency in (0, 1):
            for mode in ("rate", "heading"):
                for refine in (False, True):
                    r = turning.overshoot_study(robot, num=num, latency=latency, mode=mode, forward=forward,
                                                refine=refine)
                    ci = lambda x: mean_ci(x)[1]  # noqa: E731
                    _emit(rows, dict(_env(), bench="turning-overshoot", forward_m_s=forward, latency=latency,
                                     mode=mode, refine=refine, scenarios=num,
                                     overshoot_deg_mean=float(np.mean(r.overshoot)),
                                     overshoot_deg_ci95=ci(r.overshoot),
                                     overshoot_deg_max_abs=float(np.max(np.abs(r.overshoot))),
                                     error_to_goal_deg_mean=float(np.mean(r.error)),
                                     error_to_goal_deg_ci95=ci(r.error)))


def check(rows, quick: bool, chunk: int, path: str | None = None):
    """Decisions on a fixed set of queries (2D and 2.5D, both methods), for comparing devices.

    Saves ``index``/``cost`` arrays to ``path`` (npz) if it does not exist,
    else compares against it and reports the number of differing decisions.
    """
    import os

    robot = ij.robots.hrp2(margin=0.02)
    targets = ij.make_targets(robot)
    out = {}
    kernels = ("xla",) if _cpu() else ("xla", "pallas")  # the reference is always the XLA path's decisions
    for has_height in (False, True):
        terrain = workload_terrain(has_height, seed=3)
        index = footcost.index_terrain(terrain, robot)
        stance, command, swing = workload_queries(256 if quick else 2048, seed=4)
        for method in ("exhaustive", "ordered"):
            for kernel in kernels:
                def one(st, cmd, sw, options=ij.SelectOptions(method=method, kernel=kernel), terrain=terrain,
                        index=index):
                    c = select.select_step(terrain, robot, st, -1, cmd, options, swing_from=sw, targets=targets,
                                           index=index)
                    return c.index, c.cost

                i, c = _batched(one, chunk)(stance, command, swing)
                key = f"{'25d' if has_height else '2d'}_{method}" + ("" if kernel == "xla" else "_pallas")
                out[key + "_index"], out[key + "_cost"] = np.asarray(i), np.asarray(c)
        # Beyond the paper, XLA FootCost: the two-step lookahead and the refinement, on fewer queries.
        few = 64 if quick else 256
        for name, kw in (("lookahead2", dict(method="lookahead", horizon=2)), ("refine", dict(refine=True))):
            def one(st, cmd, sw, options=ij.SelectOptions(**kw), terrain=terrain, index=index):
                c = select.select_step(terrain, robot, st, -1, cmd, options, swing_from=sw, targets=targets,
                                       index=index)
                return c.index, c.cost

            i, c = _batched(one, max(1, chunk // 16))(stance[:few], command[:few], swing[:few])
            key = f"{'25d' if has_height else '2d'}_{name}"
            out[key + "_index"], out[key + "_cost"] = np.asarray(i), np.asarray(c)
    if path and os.path.exists(path):
        ref = np.load(path)
        for k in sorted(out):
            if k.endswith("_index"):
                rk = k.replace("_pallas", "")
                if rk not in ref:
                    _emit(rows, dict(_env(), bench="check", case=k[:-6], missing_from_ref=path))
                    continue
                c, rc = out[k.replace("index", "cost")], ref[rk.replace("index", "cost")]
                fin = np.isfinite(rc)
                _emit(rows, dict(_env(), bench="check", case=k[:-6], decisions=len(out[k]),
                                 index_differs=int(np.sum(out[k] != ref[rk])),
                                 validity_differs=int(np.sum(np.isfinite(c) != fin)),
                                 max_cost_diff=float(np.max(np.abs(c[fin] - rc[fin]), initial=0.0))))
    elif path:
        np.savez(path, **out)
        _emit(rows, dict(_env(), bench="check", saved=path))


def run(name: str, quick: bool = False, chunk: int = 1024, path: str | None = None, kernels=None,
        parts=SELECT_PARTS) -> list:
    """Run benchmark ``name`` ("footcost", "select", "lookahead" or "check"); print and return JSON rows.
    ``kernels`` and ``parts``: ``select``'s only (:func:`bench_select`)."""
    rows: list = []
    if name == "check":
        check(rows, quick, chunk, path)
    elif name == "select":
        bench_select(rows, quick, chunk, kernels, parts)
    else:
        {"footcost": bench_footcost, "lookahead": bench_lookahead}[name](rows, quick, chunk)
    return rows


def add_check_options(parser) -> None:
    """``ijoy bench check``'s own option, beside every benchmark's ``--quick`` and ``--json``."""
    parser.add_argument("--ref", default=None, type=output_file,
                        help="npz of reference decisions: compared with where it exists, else written")


def _parts(text: str) -> list[str]:
    """``--parts`` as a list of :data:`SELECT_PARTS` (ArgumentTypeError otherwise)."""
    return names_of(text, SELECT_PARTS, "parts")


def add_select_options(parser) -> None:
    """``ijoy bench select``'s own options, beside every benchmark's ``--quick`` and ``--json``."""
    parser.add_argument("--kernel", choices=list(KERNELS), default=None,
                        help="time FootCost's XLA path or the fused kernel only (default: XLA's, and on a GPU both)")
    parser.add_argument("--parts", type=_parts, default=None,
                        help=f"comma-separated parts to run, of {', '.join(SELECT_PARTS)} (default: all)")


def report(args) -> list:
    """``ijoy bench footcost`` (``select``, ``lookahead``, ``check``) from parsed options: :func:`run`'s rows."""
    kernel, parts = getattr(args, "kernel", None), getattr(args, "parts", None)
    return run(args.name, quick=args.quick, path=getattr(args, "ref", None),
               kernels=None if kernel is None else [kernel], parts=SELECT_PARTS if parts is None else parts)

"""Benchmark the haptic cue: ``ijoy bench cue [--quick] [--json PATH]``.

Measures on the CPU (or whatever device JAX uses by default), HRP-2 (496 actions) on a 4 m x 2.4 m
clutter map at 2 cm (the demo's scene):

* ``tick``: one haptic tick, ``jax.jit(cue.tick_force)`` on the step's prepared tick
  (:func:`ijoy_jax.cue.prepare_tick`) and ``jax.jit(cue.force)`` on its feasible set: compile time, then the
  median (10th / 90th percentile) wall time per call over many calls, each synchronised with
  ``block_until_ready``, and the process CPU time per call. Timed in a fresh Python process per setting:
  synchronous CPU dispatch (``jax_cpu_enable_async_dispatch = False``, set before any JAX work) with the
  process pinned to one CPU, as a 1 kHz haptic loop's process should run; synchronous, not pinned; and
  JAX's defaults (asynchronous dispatch hands every program of more than one kernel to another thread,
  about 10 us more per call). The target is a median under 20 us. Also the public call outside any jit
  (``cue.force``, with its input checks: use the jitted call in a loop).
* ``step``: once per step, :func:`ijoy_jax.cue.feasible_commands` (one FootCost evaluation of the
  action set) and :func:`ijoy_jax.cue.reach` (32 directions): compile and median per call.
* ``tick_batched``: ``jax.vmap`` of the force over B commands on one feasible set: evaluations/s.
"""

from __future__ import annotations

import json
import os
import platform as _host
import statistics
import subprocess
import sys

from ijoy_jax.apps.options import positive_int, positive_ints

SYNC_FLAG = "jax_cpu_enable_async_dispatch"


def _workload():
    """(feasible set, a blocked command, params) of the demo scene, 0.3 m before the first obstacle."""
    import jax.numpy as jnp

    import ijoy_jax as ij
    from ijoy_jax import cue
    from ijoy_jax.apps.demo import demo_scene

    terrain = demo_scene()
    robot = ij.robots.hrp2(margin=0.02)
    feasible = cue.feasible_commands(terrain, robot, [3.5, 1.2, 0.0], -1)  # the wall 0.2 m ahead
    return terrain, robot, feasible, jnp.array([0.25, 0.05, 0.1], jnp.float32), cue.make_params()


def tick(calls: int, sync: bool, pin: bool = False) -> dict:
    """Time one haptic tick in this process (call it first thing in a fresh process: see the module docstring).

    ``pin``: first pin this process to one CPU (Linux ``sched_setaffinity``), as a haptic loop's process would
    be: XLA's CPU thread pool then has no second core to hand work to.
    """
    pinned = None
    if pin and hasattr(os, "sched_setaffinity"):
        pinned = max(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {pinned})
    import jax

    jax.config.update(SYNC_FLAG, not sync)
    from ijoy_jax import cue
    from ijoy_jax.apps.bench_haptics import single_call

    _, _, feasible, command, params = _workload()
    out = {"dispatch": "synchronous" if sync else "asynchronous (JAX's default)", "pinned_cpu": pinned}
    out["jit_tick_force"] = single_call(jax.jit(cue.tick_force), (cue.prepare_tick(feasible, params), command), calls)
    out["jit_force"] = single_call(jax.jit(cue.force), (feasible, command, params), calls)
    out["public_force"] = single_call(cue.force, (feasible, command, params), max(50, calls // 10))
    blocked = cue.force_terms(feasible, command, params)
    out["blocked"] = bool(blocked.blocked)
    return out


def _tick_in_subprocess(calls: int, sync: bool, pin: bool) -> dict:
    cmd = [sys.executable, "-m", "ijoy_jax.apps.cli", "--no-compile-cache", "bench", "cue", "--tick-only", "--calls",
           str(calls)]
    if sync:
        cmd.append("--sync")
    if pin:
        cmd.append("--pin")
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=dict(os.environ))
    if proc.returncode != 0:
        raise RuntimeError(f"the tick benchmark's process failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run(quick: bool = False, calls: int | None = None, sizes: tuple[int, ...] | None = None) -> dict:
    """Run every benchmark; returns a JSON-serialisable dict.

    Args:
      quick: fewer calls and smaller batches.
      calls: timed ticks per dispatch mode (default 2000 quick, 20000 full).
      sizes: batch sizes of the vmapped force (default 1, 64, 1024 and, unless quick, 16384).
    """
    import jax
    import numpy as np

    from ijoy_jax import cue
    from ijoy_jax.apps.bench_haptics import single_call, time_calls

    n = calls or (2000 if quick else 20000)
    out = {"device": str(jax.devices()[0]), "platform": jax.default_backend(), "jax": jax.__version__,
           "python": sys.version.split()[0], "host": _host.machine(), "cpu_count": os.cpu_count(),
           "loadavg_1min_start": _loadavg(), "dtype": "float32", "quick": quick, "actions": 496}
    out["tick"] = [_tick_in_subprocess(n, sync, pin) for sync, pin in ((True, True), (True, False), (False, False))]
    steps = max(20, n // 100)
    import ijoy_jax as ij
    from ijoy_jax.apps.demo import demo_scene

    terrain, robot = demo_scene(), ij.robots.hrp2(margin=0.02)
    out["feasible_commands"] = single_call(
        lambda s: cue.feasible_commands(terrain, robot, s, -1), (np.array([3.5, 1.2, 0.0]),), steps)
    _, _, feasible, command, params = _workload()
    out["reach"] = single_call(lambda f: cue.reach(f, 32), (feasible,), steps)
    batched = jax.jit(jax.vmap(cue.force, in_axes=(None, 0, None)))
    rng = np.random.default_rng(0)
    rows = []
    for b in sizes or ((1, 64, 1024) if quick else (1, 64, 1024, 16384)):
        cmds = jax.numpy.asarray(rng.uniform([-0.3, -0.2, -0.5], [0.3, 0.2, 0.5], (b, 3)), jax.numpy.float32)
        compile_s = single_call(batched, (feasible, cmds, params), 3)["compile_s"]
        reps = max(3, min(200, int((2e5 if not quick else 2e4) // b)))
        t = statistics.median(time_calls(batched, (feasible, cmds, params), reps))
        rows.append({"batch": b, "compile_s": compile_s, "median_s": t, "evals_per_s": b / t})
    out["tick_batched"] = rows
    out["loadavg_1min_end"] = _loadavg()
    return out


def _loadavg():
    try:
        return os.getloadavg()[0]
    except OSError:  # not available on this platform
        return None


def format_report(r: dict) -> str:
    """Human-readable summary of :func:`run`'s result."""
    lines = [f"device: {r['device']} ({r['platform']}), jax {r['jax']}, {r['dtype']}, {r['cpu_count']} CPUs, "
             f"load average {r['loadavg_1min_start']} -> {r['loadavg_1min_end']}; HRP-2, {r['actions']} actions"]

    def row(name, s):
        return (f"{name}: compile {s['compile_s'] * 1e3:.0f} ms; median {s['median_us']:.1f} us (p10 "
                f"{s['p10_us']:.1f}, p90 {s['p90_us']:.1f}; process CPU {s['cpu_us_per_call']:.1f} us) over "
                f"{s['calls']} calls")

    for t in r["tick"]:
        where = f"pinned to CPU {t['pinned_cpu']}" if t.get("pinned_cpu") is not None else "not pinned"
        lines.append(f"tick, {t['dispatch']} dispatch, {where}:")
        lines.append("  " + row("jit(cue.tick_force)", t["jit_tick_force"]))
        lines.append("  " + row("jit(cue.force)", t["jit_force"]))
        lines.append("  " + row("cue.force (checked, eager)", t["public_force"]))
    lines.append(row("per step: feasible_commands", r["feasible_commands"]))
    lines.append(row("per step: reach (32 directions)", r["reach"]))
    lines.append("force batched (vmap over commands):")
    for b in r["tick_batched"]:
        lines.append(f"  B={b['batch']:>6d}: compile {b['compile_s'] * 1e3:6.0f} ms, median "
                     f"{b['median_s'] * 1e3:8.3f} ms, {b['evals_per_s']:.3g} evals/s")
    return "\n".join(lines)


def add_options(parser) -> None:
    """``ijoy bench cue``'s own options, beside every benchmark's ``--quick`` and ``--json``."""
    parser.add_argument("--calls", type=positive_int, help="timed ticks per dispatch mode")
    parser.add_argument("--sizes", type=positive_ints, help="comma-separated batch sizes, e.g. 1,64,1024")
    parser.add_argument("--tick-only", action="store_true", help="only the tick, in this process (JSON line)")
    parser.add_argument("--sync", action="store_true", help="with --tick-only: synchronous CPU dispatch")
    parser.add_argument("--pin", action="store_true", help="with --tick-only: pin the process to one CPU")


def report(args) -> dict:
    """``ijoy bench cue`` from parsed options: the result, printed by :func:`format_report` (with --tick-only:
    :func:`tick`'s, printed as one JSON line)."""
    if args.tick_only:
        result = tick(args.calls or 2000, args.sync, args.pin)
        print(json.dumps(result))
        return result
    result = run(quick=args.quick, calls=args.calls, sizes=args.sizes)
    print(format_report(result))
    return result


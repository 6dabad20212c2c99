"""Benchmark the haptic force path: ``ijoy bench haptics [--quick] [--json PATH]``.

Measures, on whatever device JAX uses by default (CPU or one GPU), with plain
JAX (no mujoco, no scipy):

* ``leg_force``: one jitted evaluation of the ALDURO leg's repulsive force
  from cylinder positions (forward kinematics, Jacobian by autodiff, limiting
  planes, force), leg geometry passed as traced arguments: compile time, then
  the median (and 10th/90th percentile) wall time per call over many calls,
  each synchronised with ``block_until_ready``, and the process CPU time per
  call (on a shared machine wall time includes waiting for a core). The 1 kHz
  haptic loop's budget is 1 ms; the target is a median under 50 microseconds.
* ``leg_force_fixed_geometry``: the same with the geometry closed over
  (compile-time constants, as for one fixed robot).
* ``filter_step``: the same for one spring-damper update of a 2-axis joystick.
* ``leg_force_batched``: ``jax.vmap`` of the leg force over B configurations,
  compile time and evaluations per second for several batch sizes.
"""

from __future__ import annotations

import os
import platform as _host
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.apps.options import positive_int, positive_ints
from ijoy_jax.haptics.filter import SpringDamper, discretize, filter_step, init_state
from ijoy_jax.haptics.leg import PAPER_Q, alduro_leg, leg_repulsive_force


def time_calls(fn, args, n) -> list[float]:
    """Wall seconds of ``n`` calls ``fn(*args)``, each synchronised with ``block_until_ready``."""
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t0)
    return times


def _compile(fn, args):
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    return time.perf_counter() - t0


def single_call(fn, args, n) -> dict:
    """Compile time, then wall-time statistics per call and process CPU time per call (a JSON-able dict)."""
    compile_s = _compile(fn, args)
    time_calls(fn, args, min(200, n))  # warm-up
    cpu0 = time.process_time()
    t = np.array(time_calls(fn, args, n))
    cpu = (time.process_time() - cpu0) / n
    return {
        "compile_s": compile_s,
        "calls": n,
        "median_us": float(np.median(t) * 1e6),
        "p10_us": float(np.percentile(t, 10) * 1e6),
        "p90_us": float(np.percentile(t, 90) * 1e6),
        "cpu_us_per_call": cpu * 1e6,
    }


def _loadavg():
    try:
        return os.getloadavg()[0]
    except OSError:  # not available on this platform
        return None


def run(quick: bool = False, calls: int | None = None, sizes: tuple[int, ...] | None = None) -> dict:
    """Run all benchmarks; returns a JSON-serialisable dict.

    Args:
      quick: fewer calls and smaller batches.
      calls: timed calls per single-call benchmark (default 2000 quick, 20000 full).
      sizes: batch sizes (default 1, 64, 1024, 16384 and, unless quick, 131072).
    """
    leg = alduro_leg(-1.0)
    q = jnp.asarray(PAPER_Q, jnp.float32)
    c1, lam = jnp.float32(1.0), jnp.float32(0.05)
    n_single = calls or (2000 if quick else 20000)
    out = {
        "device": str(jax.devices()[0]),
        "platform": jax.default_backend(),
        "jax": jax.__version__,
        "python": sys.version.split()[0],
        "host": _host.machine(),
        "cpu_count": os.cpu_count(),
        "loadavg_1min_start": _loadavg(),
        "dtype": "float32",
        "quick": quick,
    }
    # Geometry as traced arguments (no recompile when it changes) ...
    out["leg_force"] = single_call(jax.jit(leg_repulsive_force), (leg, q, c1, lam), n_single)
    # ... and as compile-time constants (a fixed robot: XLA folds the geometry).
    out["leg_force_fixed_geometry"] = single_call(jax.jit(lambda x: leg_repulsive_force(leg, x, c1, lam)), (q,),
                                                  n_single)

    coeffs = discretize(SpringDamper.create(2 * np.pi * 2.0, 0.7), 1e-3)
    step = jax.jit(filter_step)
    out["filter_step"] = single_call(step, (coeffs, init_state(jnp.zeros(2)), jnp.array([0.1, -0.2])), n_single)

    batched = jax.jit(jax.vmap(leg_repulsive_force, in_axes=(None, 0, None, None)))
    rng = np.random.default_rng(0)
    stroke = np.asarray(leg.stroke)
    sizes = sizes or ((1, 64, 1024, 16384) if quick else (1, 64, 1024, 16384, 131072))
    rows = []
    for b in sizes:
        qb = jnp.asarray(rng.uniform(0.02, 0.98, (b, 4)) * stroke, jnp.float32)
        compile_s = _compile(batched, (leg, qb, c1, lam))
        reps = max(3, min(200 if not quick else 50, int((2e5 if not quick else 2e4) // b)))
        t = statistics.median(time_calls(batched, (leg, qb, c1, lam), reps))
        rows.append({"batch": b, "compile_s": compile_s, "median_s": t, "evals_per_s": b / t})
    out["leg_force_batched"] = rows
    out["loadavg_1min_end"] = _loadavg()
    return out


def format_report(r: dict) -> str:
    """Human-readable summary of :func:`run`'s result."""
    lines = [
        f"device: {r['device']} ({r['platform']}), jax {r['jax']}, {r['dtype']}, "
        f"{r['cpu_count']} CPUs, load average {r['loadavg_1min_start']} -> {r['loadavg_1min_end']}"
    ]
    for key in ("leg_force", "leg_force_fixed_geometry", "filter_step"):
        s = r[key]
        lines.append(
            f"{key}: compile {s['compile_s'] * 1e3:.0f} ms; median {s['median_us']:.1f} us "
            f"(p10 {s['p10_us']:.1f}, p90 {s['p90_us']:.1f}; process CPU {s['cpu_us_per_call']:.1f} us)"
            f" over {s['calls']} calls"
        )
    lines.append("leg_force batched (vmap):")
    for row in r["leg_force_batched"]:
        lines.append(
            f"  B={row['batch']:>7d}: compile {row['compile_s'] * 1e3:6.0f} ms, "
            f"median {row['median_s'] * 1e3:9.3f} ms, {row['evals_per_s']:.3g} evals/s"
        )
    return "\n".join(lines)


def add_options(parser) -> None:
    """``ijoy bench haptics``'s own options, beside every benchmark's ``--quick`` and ``--json``."""
    parser.add_argument("--calls", type=positive_int, help="timed calls per single-call benchmark")
    parser.add_argument("--sizes", type=positive_ints, help="comma-separated batch sizes, e.g. 1,64,1024")


def report(args) -> dict:
    """``ijoy bench haptics`` from parsed options: the result, printed by :func:`format_report`."""
    result = run(quick=args.quick, calls=args.calls, sizes=args.sizes)
    print(format_report(result))
    return result


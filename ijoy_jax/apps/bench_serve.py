"""Benchmark the footstep server: ``ijoy bench serve [--quick] [--json PATH]``.

One run, one workload: HRP-2 (496 actions, margin 2 cm) on the benchmark's 2.5D map of 200 x 200 cells at
2 cm (``bench.workload_terrain``: a 3 cm swell, 2 mm noise, 0.2 % obstacle cells), full decisions with the
swing-path check, stances and commands from ``bench.workload_queries``, sides alternating. Measured, in this
order:

* ``in_process``: :func:`ijoy_jax.select_step` called in this process with the map's prepared tables
  (:func:`ijoy_jax.select.prepare`, as the server keeps them), each call synchronised with
  ``block_until_ready``: p50 / p99 per call (the public call checks its arguments each time);
  ``in_process_jit``: the same inside the caller's own ``jax.jit`` (the checks skip traced values, as in
  the server); ``in_process_plain``: 10 calls without the prepared tables (the terrain's index and the
  robot's target set are built in each call).
* ``server``: ``ijoy serve`` started as a subprocess on 127.0.0.1 (its start-up and warm-up compile timed),
  the map sent once (``set_terrain`` round trip), then the same decisions through a
  :class:`~ijoy_jax.server.Client`: round trip (client send to reply decoded) p50 / p99, the server's own
  compute time per request (``compute_us``: the decision and the chosen step's cost terms), and their
  difference (transport, JSON, scheduling). Every reply is checked against the in-process decision
  (``mismatches`` must be 0). The in-process and server calls alternate request by request, so that on a
  shared machine they see the same load.

The machine's load average is recorded at the start and the end: on a shared machine the figures move.
"""

from __future__ import annotations

import os
import platform
import re
import sys
import time

import numpy as np


def _pct(xs, q) -> float:
    return float(np.percentile(np.asarray(xs) * 1e3, q))


def _summary(xs) -> dict:
    return {"p50_ms": _pct(xs, 50), "p99_ms": _pct(xs, 99), "mean_ms": float(np.mean(xs) * 1e3), "n": len(xs)}


def _loadavg():
    try:
        return os.getloadavg()[0]
    except OSError:
        return None


def run(quick: bool = False, requests: int | None = None) -> dict:
    """Run the benchmark; returns a JSON-serialisable dict (see the module docstring)."""
    import jax

    import ijoy_jax as ij
    from ijoy_jax import select
    from ijoy_jax.apps.bench import workload_queries, workload_terrain
    from ijoy_jax.server import serve_subprocess

    n = requests or (50 if quick else 300)
    out = {"device": str(jax.devices()[0]), "platform": jax.default_backend(), "jax": jax.__version__,
           "python": sys.version.split()[0], "host": platform.machine(), "cpu_count": os.cpu_count(),
           "loadavg_1min_start": _loadavg(), "date": time.strftime("%Y-%m-%d"), "requests": n,
           "workload": "HRP-2, 496 actions, margin 0.02 m; 2.5D map 200 x 200 at 0.02 m; exhaustive, swing path"}
    terrain, robot = workload_terrain(True), ij.robots.hrp2(margin=0.02)
    stance, command, swing = (np.asarray(a) for a in workload_queries(n))
    sides = [-1 if i % 2 == 0 else 1 for i in range(n)]
    prepared = select.prepare(terrain, robot)

    def decide(i, **tables):
        return ij.select_step(terrain, robot, stance[i], sides[i], command[i], swing_from=swing[i], **tables)

    jitted = jax.jit(lambda t, r, p, s, side, c, w: ij.select_step(t, r, s, side, c, swing_from=w, index=p.index,
                                                                  targets=p.targets))

    def decide_jit(i):
        return jitted(terrain, robot, prepared, stance[i], sides[i], command[i], swing[i])

    t0 = time.perf_counter()
    jax.block_until_ready(decide(0, index=prepared.index, targets=prepared.targets))
    out["in_process_compile_s"] = time.perf_counter() - t0
    jax.block_until_ready(decide_jit(0))
    jax.block_until_ready(decide(0))
    plain = []
    for i in range(min(n, 10)):
        t0 = time.perf_counter()
        jax.block_until_ready(decide(i))
        plain.append(time.perf_counter() - t0)
    out["in_process_plain"] = _summary(plain)

    t0 = time.perf_counter()
    with serve_subprocess("--warm-up", "200x200@0.02", "--margin", "0.02") as server:
        out["server_start_s"] = time.perf_counter() - t0
        for _ in range(40):  # the warm-up line is on stderr, read by another thread than the listening line
            warm = [line for line in server.output if "warm-up" in line]
            if warm:
                break
            time.sleep(0.05)
        m = re.search(r"(\d+) programs in ([\d.]+) s", warm[0]) if warm else None
        out["server_warm_up"] = {"programs": int(m.group(1)), "seconds": float(m.group(2))} if m else None
        with server.client() as client:
            t0 = time.perf_counter()
            client.set_terrain(terrain)
            out["set_terrain_ms"] = (time.perf_counter() - t0) * 1e3
            client.step(stance[0], sides[0], command[0], swing[0])  # the connection's first request
            public, own_jit, rtt, compute, mismatches = [], [], [], [], 0
            for i in range(n):  # interleaved, so that the three see the same load on a shared machine
                t0 = time.perf_counter()
                c = jax.block_until_ready(decide(i, index=prepared.index, targets=prepared.targets))
                public.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                jax.block_until_ready(decide_jit(i))
                own_jit.append(time.perf_counter() - t0)
                r = client.step(stance[i], sides[i], command[i], swing[i])
                rtt.append(r.round_trip_s)
                compute.append(r.compute_s)
                mismatches += r.index != int(c.index) or not np.array_equal(r.foothold, np.asarray(c.foothold))
    out["in_process"] = _summary(public)
    out["in_process_jit"] = _summary(own_jit)
    out["round_trip"] = _summary(rtt)
    out["server_compute"] = _summary(compute)
    out["overhead"] = _summary(np.asarray(rtt) - np.asarray(compute))
    out["mismatches"] = int(mismatches)
    out["loadavg_1min_end"] = _loadavg()
    return out


def format_report(r: dict) -> str:
    """Human-readable summary of :func:`run`'s result."""
    def ms(s):
        return f"p50 {s['p50_ms']:.2f} ms, p99 {s['p99_ms']:.2f} ms (mean {s['mean_ms']:.2f}, n {s['n']})"

    warm = r["server_warm_up"]
    lines = [
        f"device: {r['device']} ({r['platform']}), jax {r['jax']}, {r['cpu_count']} CPUs, load average "
        f"{r['loadavg_1min_start']} -> {r['loadavg_1min_end']}; {r['workload']}",
        f"in-process select_step, prepared tables: {ms(r['in_process'])}; compile {r['in_process_compile_s']:.1f} s",
        f"in-process, inside the caller's jit (no per-call checks): {ms(r['in_process_jit'])}",
        f"in-process select_step, plain (index and targets built per call): {ms(r['in_process_plain'])}",
        f"server: started and listening in {r['server_start_s']:.1f} s"
        + (f" (warm-up: {warm['programs']} programs in {warm['seconds']:.1f} s)" if warm else "")
        + f"; set_terrain round trip {r['set_terrain_ms']:.1f} ms",
        f"server round trip over localhost: {ms(r['round_trip'])}",
        f"server compute per request: {ms(r['server_compute'])}",
        f"round trip - compute (transport, JSON, scheduling): {ms(r['overhead'])}",
        f"replies that differ from the in-process decision: {r['mismatches']}",
    ]
    return "\n".join(lines)


def report(args) -> dict:
    """``ijoy bench serve`` from parsed options: :func:`run`'s result, printed by :func:`format_report`."""
    result = run(quick=args.quick)
    print(format_report(result))
    return result

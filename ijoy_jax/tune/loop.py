"""The host-side tuning loop: jitted optax steps (:mod:`ijoy_jax.optim`), many runs at once, minibatches,
progress, saving.

:func:`tune` calls a :class:`~ijoy_jax.optim.Tuner`'s jitted ``step`` ``steps`` times (impure: it prints
progress, steps/s, loss and ETA, and times the compile), collects the loss curves and optionally saves
everything with :func:`save`; :func:`load` reads it back. For a fit that lives inside one jitted function,
:func:`ijoy_jax.optim.run_steps` is its in-graph twin. Many runs at once (``num_runs``), minibatches shared by
every run and bijectors of constrained parameters: see :mod:`ijoy_jax.optim`.

Files written by :func:`save` (``out_dir``)::

  params.npz     final parameters, one array per leaf, named by its dotted path
                 (leading run axis when ``num_runs`` was given).
  params.json    the same as nested lists (readable).
  losses.csv     long format: ``step,run,loss[,<term>...]`` one row per step and run.
  manifest.json  versions (python, jax, jaxlib, optax, numpy, ijoy_jax), the
                 user's config, steps, runs, compile and run time.

Example:
  >>> import jax, jax.numpy as jnp, optax
  >>> from ijoy_jax.tune import loop
  >>> def loss(p, batch):                         # fit the mean of a noisy batch
  ...     return jnp.mean((p["mu"] - batch) ** 2)
  >>> res = loop.tune(loss, {"mu": jnp.zeros(3)}, optax.adam(0.1), 50, key=0, num_runs=3,
  ...                 batch_fn=lambda k: 2.0 + 0.1 * jax.random.normal(k, (16,)), progress=False)
  >>> res.losses.shape, bool(abs(res.params["mu"][0] - 2.0) < 0.2)
  ((3, 50), True)
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import platform
import sys
import time
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any, NamedTuple

import jax
import numpy as np
import optax

from ijoy_jax.optim import make_tuner
from ijoy_jax.prng import as_key

# --------------------------------------------------------------------------- host loop


class TuneResult(NamedTuple):
    """Result of :func:`tune` (NumPy, on the host).

    params: the final unconstrained parameters (pytree; leading run axis R with ``num_runs``).
    losses: (steps,) or (R, steps) loss before each update.
    terms: dict name -> array shaped like ``losses`` (named terms; empty without ``has_aux``).
    grad_norms: shaped like ``losses``.
    compile_s: seconds of the first step (trace + compile + run).
    run_s: seconds of the other steps (after ``block_until_ready``).
    out_dir: where the results were saved (None if not saved).
    """

    params: Any
    losses: np.ndarray
    terms: dict
    grad_norms: np.ndarray
    compile_s: float
    run_s: float
    out_dir: Path | None

    @property
    def seconds_per_step(self) -> float:
        """Mean wall time of one update after compilation (s); NaN with a single step."""
        n = self.losses.shape[-1] - 1
        return self.run_s / n if n > 0 else math.nan


def _fmt_time(s: float) -> str:
    if not math.isfinite(s):
        return "?"
    m, s = divmod(int(round(s)), 60)
    return f"{m}m{s:02d}s" if m else f"{s}s"


def tune(
    loss_fn: Callable,
    params0: Any,
    optimizer: optax.GradientTransformation,
    steps: int,
    *,
    key,
    batch_fn: Callable[[jax.Array], Any] | None = None,
    hparams: Any = None,
    num_runs: int | None = None,
    has_aux: bool = False,
    progress: bool = True,
    log_every: int = 10,
    out_dir: str | Path | None = None,
    config: Any = None,
) -> TuneResult:
    """Minimise ``loss_fn`` with ``optimizer`` for ``steps`` jitted updates; optionally save the results.

    An impure host loop (it prints and times) around :func:`make_tuner`'s
    pure, jitted ``step``; use :func:`make_tuner` directly to embed the
    update in your own loop or ``lax.scan``.

    Args:
      loss_fn, optimizer, batch_fn, hparams, num_runs, has_aux: see :func:`make_tuner`.
      params0: initial unconstrained parameters (pytree; leading run axis with ``num_runs``).
      steps: number of updates (>= 1).
      key: int seed or PRNG key; step t's minibatch uses ``fold_in(key, t)``.
      progress: print ``step, loss (min/mean over runs), steps/s, ETA`` to
        stderr every ``log_every`` steps (False: quiet).
      log_every: steps between progress lines (>= 1).
      out_dir: if given, :func:`save` the result there (created if needed).
      config: JSON-serialisable dict or dataclass saved in the manifest.

    Returns:
      :class:`TuneResult`.

    Example:
      >>> import jax.numpy as jnp, optax
      >>> from ijoy_jax.tune import loop
      >>> r = loop.tune(lambda p, b: (p - 3.0) ** 2, jnp.float32(0.0), optax.adam(0.3), 100, key=0,
      ...               progress=False)
      >>> round(float(r.params), 1)
      3.0
    """
    if not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f"steps must be a positive int, got {steps!r}")
    if not isinstance(log_every, (int, np.integer)) or log_every < 1:
        raise ValueError(f"log_every must be a positive int, got {log_every!r}")
    if num_runs is not None and (not isinstance(num_runs, (int, np.integer)) or num_runs < 1):
        raise ValueError(f"num_runs must be None or a positive int, got {num_runs!r}")
    key = as_key(key)
    tuner = make_tuner(loss_fn, optimizer, batch_fn=batch_fn, hparams=hparams, num_runs=num_runs, has_aux=has_aux)
    state = tuner.init(params0)
    metrics = []
    t0 = time.perf_counter()
    t_first = None
    for i in range(steps):
        state, m = tuner.step(state, key)
        metrics.append(m)
        if i == 0:
            jax.block_until_ready(m)
            t_first = time.perf_counter()
        if progress and ((i + 1) % log_every == 0 or i + 1 == steps):
            loss = np.asarray(m.loss)  # syncs: the rate below is honest
            now = time.perf_counter()
            rate = i / (now - t_first) if i > 0 and now > t_first else math.nan
            eta = (steps - i - 1) / rate if rate > 0 else math.nan
            lo = f"loss {loss.min():.5g}" + (f" (mean {loss.mean():.5g} over {loss.size} runs)" if loss.ndim else "")
            print(f"step {i + 1}/{steps}  {lo}  {rate:.3g} steps/s  ETA {_fmt_time(eta)}", file=sys.stderr)
    jax.block_until_ready(state)
    t_end = time.perf_counter()
    stacked = jax.tree.map(lambda *x: np.stack([np.asarray(v) for v in x], axis=-1), *metrics)
    result = TuneResult(
        params=jax.tree.map(np.asarray, state.params),
        losses=stacked.loss,
        terms=dict(stacked.terms),
        grad_norms=stacked.grad_norm,
        compile_s=float(t_first - t0),
        run_s=float(t_end - t_first),
        out_dir=None,
    )
    if out_dir is not None:
        result = result._replace(out_dir=save(out_dir, result, config=config))
    return result


# --------------------------------------------------------------------------- saving


def _flat(tree) -> dict[str, np.ndarray]:
    out = {}
    for path, leaf in jax.tree_util.tree_flatten_with_path(tree)[0]:
        name = ".".join(str(getattr(p, "key", getattr(p, "name", getattr(p, "idx", p)))) for p in path)
        out[name or "params"] = np.asarray(leaf)
    return out


def _jsonable(config):
    if config is None:
        return None
    if dataclasses.is_dataclass(config) and not isinstance(config, type):
        config = dataclasses.asdict(config)
    return json.loads(json.dumps(config, default=lambda o: np.asarray(o).tolist()))


def versions() -> dict[str, str]:
    """Versions of the packages a tuning result depends on."""
    import jaxlib

    return {
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "optax": optax.__version__,
        "numpy": np.__version__,
        "ijoy_jax": metadata.version("ijoy_jax"),
        "backend": jax.default_backend(),
    }


def save(out_dir: str | Path, result: TuneResult, *, config: Any = None, extra: dict | None = None) -> Path:
    """Write ``params.npz``, ``params.json``, ``losses.csv`` and ``manifest.json`` (see the module docstring).

    Args:
      out_dir: folder (created if needed); existing files of the same names are overwritten.
      result: a :class:`TuneResult`.
      config: JSON-serialisable dict or dataclass recorded in the manifest.
      extra: more JSON-serialisable entries for the manifest (e.g. evaluation numbers).

    Returns:
      The folder as a Path.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    flat = _flat(result.params)
    np.savez(out / "params.npz", **flat)
    (out / "params.json").write_text(json.dumps({k: v.tolist() for k, v in flat.items()}, indent=2) + "\n")
    losses = np.atleast_2d(result.losses)  # (R, steps)
    terms = {k: np.atleast_2d(v) for k, v in result.terms.items()}
    names = sorted(terms)
    with open(out / "losses.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "run", "loss", *names])
        for r in range(losses.shape[0]):
            for t in range(losses.shape[1]):
                w.writerow([t, r, repr(float(losses[r, t])), *(repr(float(terms[n][r, t])) for n in names)])
    manifest = {
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "versions": versions(),
        "steps": int(losses.shape[1]),
        "num_runs": None if np.ndim(result.losses) == 1 else int(losses.shape[0]),
        "compile_s": result.compile_s,
        "run_s": result.run_s,
        "final_loss": losses[:, -1].tolist(),
        "config": _jsonable(config),
    }
    if extra:
        manifest.update(_jsonable(extra))
    (out / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")
    return out


class Saved(NamedTuple):
    """What :func:`load` returns.

    params: dict dotted name -> np.ndarray (leading run axis if several runs).
    losses: (steps,) or (R, steps) as saved.
    terms: dict name -> array shaped like ``losses``.
    manifest: the manifest dict (versions, config, timings).
    """

    params: dict
    losses: np.ndarray
    terms: dict
    manifest: dict


def load(out_dir: str | Path) -> Saved:
    """Read a folder written by :func:`save` (or :func:`tune` with ``out_dir``).

    Raises:
      FileNotFoundError: a file is missing.
    """
    out = Path(out_dir)
    manifest = json.loads((out / "manifest.json").read_text())
    with np.load(out / "params.npz") as z:
        params = {k: z[k] for k in z.files}
    with open(out / "losses.csv", newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], np.asarray(rows[1:], np.float64).reshape(-1, len(rows[0]))
    runs = int(body[:, 1].max()) + 1 if len(body) else 0
    steps = int(body[:, 0].max()) + 1 if len(body) else 0

    def col(j):
        a = np.zeros((runs, steps))
        a[body[:, 1].astype(int), body[:, 0].astype(int)] = body[:, j]
        return a if manifest.get("num_runs") is not None else a[0]

    terms = {name: col(j) for j, name in enumerate(header) if j >= 3}
    return Saved(params, col(2), terms, manifest)

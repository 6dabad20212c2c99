"""Forward tuning: choose selector parameters that minimise command error plus obstacle risk.

The objective a user cares about, over a distribution of decisions (random
terrain, stance heading and side, joystick command; :func:`sample_decisions`):

  J = E[ command_error ] + risk_weight * E[ near ]

* ``command_error`` (m): how far the chosen step lands from the ideal step
  p_next = p0 + step_time * command, ``|dxy| + rotation_scale * |dtheta|``
  in the stance foot's frame.
* ``near`` (a probability): the foothold, placed with Gaussian placement noise
  (std ``noise_xy`` m on x and y, ``noise_theta`` rad on the heading), lies
  within ``distance`` of an obstacle: its footprint (no margin) grown by
  ``distance`` overlaps an obstacle cell or leaves the map.

Relaxed objective (what is differentiated). Under the Boltzmann relaxation of
:func:`ijoy_jax.tune.relax.relaxed_select` the choice is action i with
probability p_i(params), so

  J_relaxed = mean over decisions of sum_i p_i (err_i + risk_weight * risk_i).

Why neither a soft grown footprint nor reparameterised Monte-Carlo: the
candidate footholds are a fixed, parameter-free set (the action set composed
with the stance pose), the parameters only move probability mass among them,
and the placement noise acts after the choice, independently of the
parameters. So ``risk_i = P_noise[foothold i + noise is near an obstacle]`` is
a constant per action and decision: it is estimated once per decision by
Monte-Carlo with the EXACT overlap test (``num_noise_samples`` common draws
shared by all actions and parameters), and the gradient flows exactly through
p_i. Reparameterisation would differentiate the noisy pose, which does not
depend on the parameters (zero gradient); a soft footprint would only add
bias. ``err_i`` is the error of action i itself: we use the *expected error*
sum_i p_i err_i, not the error of the expected step, which a split
distribution (half left of an obstacle, half right) would drive to zero while
the robot steps onto neither mean.

Tunable parameters (traced Robot leaves, optimised unconstrained):
``w``, ``rotation_weight`` and the metric weights and limits
(``"metrics.slope_weight"``, ...) in log space (:func:`ijoy_jax.optim.positive`);
``margin`` through a scaled sigmoid into (0, max_margin)
(:func:`ijoy_jax.optim.interval`), max_margin being the margin the
robot's static windows were built for (``robots.make_robot(max_margin=...)``), so the
window sizes never change and nothing recompiles. On 2D maps FootCost is 0
or +inf, so the exact choice does not depend on ``w`` (zero action costs)
nor the metric terms: the default tunables are then ``rotation_weight`` and
``margin`` (2.5D adds ``w`` and the metric weights and limits).

Evaluation (:func:`evaluate`): the EXACT selector (:func:`ijoy_jax.select.select_step`,
scored against p_next) on held-out decisions, the command error of its
choice and Monte-Carlo counts of noisy placements near/on obstacles.

Example:
  >>> import ijoy_jax as ij
  >>> from ijoy_jax.tune import forward
  >>> cfg = forward.ForwardConfig(shape=(40, 40), density=0.1, batch_size=2, steps=3, num_noise_samples=2)
  >>> robot = forward.paper_robot(cfg)
  >>> fit = forward.tune_forward(robot, cfg, key=0, progress=False)
  >>> fit.result.losses.shape
  (3,)
"""

from __future__ import annotations

import dataclasses
import functools
import math
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ijoy_jax import geometry, optim, robots
from ijoy_jax.footcost import foot_cost_terms, index_terrain
from ijoy_jax.limits import check_map_shape
from ijoy_jax.prng import as_key
from ijoy_jax.robots import Robot, get_leaf, set_leaf, side_actions, side_p0, side_sign
from ijoy_jax.select import prepare, select_step
from ijoy_jax.select_options import SelectOptions
from ijoy_jax.targets import make_targets
from ijoy_jax.terrain import Terrain, generators
from ijoy_jax.terrain.family import ParamError
from ijoy_jax.tune import loop, relax

METRIC_NAMES = tuple(n for n in robots.SELECTOR_LEAVES if n.startswith("metrics."))
TUNABLE = robots.SELECTOR_LEAVES
"""Names of the Robot leaves :func:`tune_forward` may tune: the selector's (:data:`ijoy_jax.robots.SELECTOR_LEAVES`)."""


@dataclasses.dataclass(frozen=True)
class ForwardConfig:
    """Everything a forward tuning run depends on (saved in the run's manifest).

    Decisions (:func:`sample_decisions`)::

      shape, resolution: grid of each random map (cells, m); the stance foot is
        at the map centre.
      has_height: 2.5D maps (object tops raise the ground) or 2D.
      family: terrain family of :data:`ijoy_jax.terrain.generators.FAMILIES` (default
        "obstacles": 8 boxes and cylinders of 4-15 cm per map).
      terrain_params: ``{field: value}`` (or pairs) of the family's parameter class
        over its defaults, checked by the family (the start zone is set below);
        a family with object slots gets just enough for its count (at least 1).
      clear_radius: cells within this radius of the stance foot are kept free (m).
      heading: stance heading uniform in [-heading, heading] (rad).
      command_low, command_high: joystick command uniform in this box (m/s, m/s, rad/s).

    Objective::

      distance: a foothold is *near* an obstacle when its footprint grown by this
        overlaps one (m).
      noise_xy, noise_theta: placement noise std (m, rad).
      num_noise_samples: Monte-Carlo draws of the noise per decision.
      rotation_scale: metres of command error per radian of heading error.
      risk_weight: metres of command error one near-obstacle foothold is worth.

    Relaxation (:mod:`ijoy_jax.tune.relax`)::

      sharpness, tau, barrier_weight.

    Tuner::

      names: Robot leaves to tune (None: ``rotation_weight``, ``margin``; 2.5D
        also ``w`` and every metric weight and limit).
      batch_size: decisions per step; steps: Adam steps; learning_rate: on the
        unconstrained variables; seed: of the training decisions.

    Robot (:func:`paper_robot`): density of HRP-2's action set, max_margin (m),
      and the starting margin (m).
    """

    shape: tuple = (60, 60)
    resolution: float = 0.02
    has_height: bool = False
    family: str = "obstacles"
    terrain_params: tuple = ()
    clear_radius: float = 0.15
    heading: float = 0.5
    command_low: tuple = (-0.25, -0.1, -0.4)
    command_high: tuple = (0.25, 0.1, 0.4)
    distance: float = 0.04
    noise_xy: float = 0.02
    noise_theta: float = 0.05
    num_noise_samples: int = 8
    rotation_scale: float = 0.1
    risk_weight: float = 0.5
    sharpness: float = 3.0
    tau: float = 0.02
    barrier_weight: float = 1.0
    names: tuple | None = None
    batch_size: int = 8
    steps: int = 100
    learning_rate: float = 0.05
    seed: int = 0
    density: float = 0.5
    max_margin: float = 0.08
    margin: float = 0.02

    def __post_init__(self):
        for name in ("shape", "command_low", "command_high", "names"):  # hashable (jit static)
            v = getattr(self, name)
            if v is not None:
                object.__setattr__(self, name, (v,) if isinstance(v, str) else tuple(v))
        object.__setattr__(self, "terrain_params", tuple(sorted(dict(self.terrain_params).items())))
        _check_config(self)

    def tuned_names(self) -> tuple:
        """The Robot leaves this config tunes (``names`` or the default for 2D/2.5D)."""
        if self.names is not None:
            return tuple(self.names)
        if self.has_height:
            return ("w", "rotation_weight", "margin", *METRIC_NAMES)
        return ("rotation_weight", "margin")


def _check_config(cfg: ForwardConfig) -> None:
    def need(ok, msg):
        if not ok:
            raise ValueError(f"ForwardConfig: {msg}")

    try:
        shape = check_map_shape(cfg.shape)
    except ValueError as e:
        need(False, str(e))
    need(min(shape) >= 8, f"shape must be 2 ints >= 8, got {cfg.shape}")
    need(cfg.resolution > 0, f"resolution must be > 0, got {cfg.resolution}")
    need(cfg.family in generators.FAMILIES, f"family must be one of {sorted(generators.FAMILIES)}, got {cfg.family!r}")
    fam = generators.FAMILIES[cfg.family]
    given = dict(cfg.terrain_params)
    need(not any(k.startswith("start_") for k in given), "terrain_params: the start zone is set by clear_radius")
    try:
        fam.validate(given)  # each value (and unknown names), then the ordered ranges over the defaults
        fam.validate(_terrain_params(cfg))
    except ParamError as e:
        need(False, f"terrain_params: {e}")
    need(len(cfg.command_low) == 3 and len(cfg.command_high) == 3, "command_low/high must have 3 entries")
    need(all(lo <= hi for lo, hi in zip(cfg.command_low, cfg.command_high, strict=True)),
         "command_low must be <= command_high")
    for name in ("distance", "noise_xy", "noise_theta", "rotation_scale", "risk_weight", "clear_radius", "heading"):
        need(getattr(cfg, name) >= 0 and math.isfinite(getattr(cfg, name)), f"{name} must be finite and >= 0")
    for name in ("sharpness", "tau", "barrier_weight", "learning_rate", "density", "max_margin"):
        need(getattr(cfg, name) > 0 and math.isfinite(getattr(cfg, name)), f"{name} must be finite and > 0")
    for name in ("num_noise_samples", "batch_size", "steps"):
        need(int(getattr(cfg, name)) >= 1, f"{name} must be >= 1")
    try:
        robots.check_density(cfg.density)  # the action set's range, before any robot is built
    except ValueError as e:
        need(False, str(e))
    need(0 < cfg.margin < cfg.max_margin, f"margin must be in (0, max_margin={cfg.max_margin}), got {cfg.margin}")
    if cfg.names is not None:
        bad = [n for n in cfg.names if n not in TUNABLE]
        need(not bad and len(cfg.names) > 0, f"names must be a non-empty subset of {TUNABLE}, got {bad or cfg.names}")


def paper_robot(cfg: ForwardConfig, **overrides) -> Robot:
    """HRP-2 with the paper's hand-set selector parameters (w = 1, rotation_weight = 100,
    ``cfg.margin``), action-set ``cfg.density`` and windows sized for ``cfg.max_margin``."""
    return robots.hrp2(margin=cfg.margin, density=cfg.density, max_margin=cfg.max_margin, **overrides)


def max_margin_of(robot: Robot) -> float:
    """Largest margin (m) the robot's static windows cover, from ``max_radius`` and the foot size.

    Solves ``hypot(L + 2m, W + 2m) = 2 max_radius`` for m (concrete robot only).
    """
    length, width, r = float(robot.foot_length), float(robot.foot_width), float(robot.max_radius)
    b = 4.0 * (length + width)
    c = length * length + width * width - 4.0 * r * r
    return (-b + math.sqrt(b * b - 32.0 * c)) / 16.0


# --------------------------------------------------------------------------- parameters


def bijectors(robot: Robot, names) -> dict[str, optim.Bijector]:
    """name -> :class:`~ijoy_jax.optim.Bijector`: ``interval(0, max_margin)`` for margin, else ``positive``."""
    out = {}
    for n in names:
        if n not in TUNABLE:
            raise ValueError(f"cannot tune {n!r}; tunable: {TUNABLE}")
        # 0.999: stay clear of the window's edge, where float rounding could flag a margin as too big.
        out[n] = optim.interval(0.0, 0.999 * max_margin_of(robot)) if n == "margin" else optim.positive()
    return out


def to_unconstrained(robot: Robot, names, values: dict | None = None) -> dict:
    """dict name -> () float32 unconstrained variable, from ``values`` (natural units) or the robot's leaves.

    Values may be (R,) arrays (R runs). Margins are clipped into the open interval first.
    """
    values = {} if values is None else dict(values)
    out = {}
    for n, b in bijectors(robot, names).items():
        v = np.asarray(values[n] if n in values else get_leaf(robot, n), np.float64)
        if n == "margin":
            hi = 0.999 * max_margin_of(robot)
            v = np.clip(v, 1e-3 * hi, (1 - 1e-3) * hi)
        elif np.any(v <= 0):
            raise ValueError(f"{n} must be > 0 to be tuned in log space, got {v}")
        out[n] = jnp.asarray(b.inverse(jnp.asarray(v, jnp.float32)), jnp.float32)
    return out


def with_params(robot: Robot, uparams: dict) -> Robot:
    """The robot with each named leaf set from its unconstrained variable (traceable)."""
    bij = bijectors(robot, uparams)
    for n, u in uparams.items():
        robot = set_leaf(robot, n, bij[n].forward(u).astype(get_leaf(robot, n).dtype))
    return robot


def natural_values(robot: Robot, uparams: dict) -> dict:
    """dict name -> float (or list over runs) in natural units (m, cost units, rad)."""
    bij = bijectors(robot, uparams)
    return {n: np.asarray(bij[n].forward(jnp.asarray(u))).tolist() for n, u in uparams.items()}


# --------------------------------------------------------------------------- decisions


class Decisions(NamedTuple):
    """B decisions to score (leading batch axis on every leaf).

    Fields::

      terrains: Terrain with (B, nx, ny) leaves.
      stances: (B, 3) stance foot poses (m, rad).
      sides: (B,) stance side, +1 left / -1 right.
      commands: (B, 3) joystick commands (m/s, m/s, rad/s).
      noise: (B, K, 3) standard-normal placement-noise draws (scaled by the
        config's std when used).
    """

    terrains: Terrain
    stances: jax.Array
    sides: jax.Array
    commands: jax.Array
    noise: jax.Array


def _terrain_params(cfg: ForwardConfig):
    """The family's parameters: its defaults, ``cfg.terrain_params``, the start zone at the map centre."""
    fam = generators.FAMILIES[cfg.family]
    return fam.params(**dict(cfg.terrain_params), start_x=0.5, start_y=0.5, start_radius=cfg.clear_radius)


def sample_decisions(key, num: int, cfg: ForwardConfig) -> Decisions:
    """Draw ``num`` decisions: a map of ``cfg.family`` per decision with the stance foot at its centre.

    Jit-able (``num`` and the config are static). Terrains come from
    :func:`ijoy_jax.terrain.generators.batch` (start zone at the map centre with
    radius ``clear_radius``).

    Example:
      >>> from ijoy_jax.tune import forward
      >>> d = forward.sample_decisions(0, 3, forward.ForwardConfig(shape=(40, 40), num_noise_samples=4))
      >>> d.terrains.free.shape, d.noise.shape
      ((3, 40, 40), (3, 4, 3))
    """
    key = as_key(key)
    kt, kh, ks, kc, kn = jax.random.split(key, 5)
    params = _terrain_params(cfg)
    slots = generators.FAMILIES[cfg.family].slots(params)
    static = {} if slots is None else {"max_count": slots}
    shape = tuple(int(s) for s in cfg.shape)
    terrains = generators.batch(cfg.family, jax.random.split(kt, num), params, shape=shape,
                                resolution=cfg.resolution, has_height=cfg.has_height, **static)
    centre = generators.start_point(params, shape=shape, resolution=cfg.resolution)
    heading = jax.random.uniform(kh, (num,), minval=-cfg.heading, maxval=cfg.heading)
    stances = jnp.concatenate([jnp.broadcast_to(centre, (num, 2)), heading[:, None]], axis=1)
    sides = jnp.where(jax.random.bernoulli(ks, 0.5, (num,)), 1.0, -1.0).astype(jnp.float32)
    commands = jax.random.uniform(kc, (num, 3), minval=jnp.asarray(cfg.command_low, jnp.float32),
                                  maxval=jnp.asarray(cfg.command_high, jnp.float32))
    noise = jax.random.normal(kn, (num, int(cfg.num_noise_samples), 3), jnp.float32)
    return Decisions(terrains, stances.astype(jnp.float32), sides, commands, noise)


# --------------------------------------------------------------------------- exact geometry


def probe_robot(robot: Robot, distance: float) -> Robot:
    """A copy of ``robot`` whose margin is ``distance`` (m) and whose windows are large enough for it.

    Its FootCost ``obstacle`` term is +inf exactly when the footprint grown by
    ``distance`` overlaps an obstacle cell or leaves the map.
    """
    need = 0.5 * math.hypot(float(robot.foot_length) + 2 * distance, float(robot.foot_width) + 2 * distance)
    return robot.replace(margin=jnp.float32(distance), max_radius=max(float(robot.max_radius), need))


def _near(terrain, index, probe, stance, side, poses):
    """(M,) bool: the footprint grown by the probe's margin at each pose (M, 3) touches an obstacle / leaves the map."""
    m = poses.shape[0]
    return foot_cost_terms(terrain, probe, stance, side, poses, action_index=jnp.zeros((m,), jnp.int32),
                           index=index).obstacle > 0


def _noisy(poses, noise, cfg: ForwardConfig):
    """(..., K, 3) poses + scaled noise: poses (..., 3), noise (K, 3)."""
    std = jnp.asarray([cfg.noise_xy, cfg.noise_xy, cfg.noise_theta], jnp.float32)
    return poses[..., None, :] + std * noise


def action_risk(terrain: Terrain, robot: Robot, probe: Robot, stance, side, noise, cfg: ForwardConfig) -> jax.Array:
    """(N,) fraction of the K noisy placements of each action's foothold that are near an obstacle.

    Parameter-free (no gradient needed): the exact grown-footprint test of
    :func:`probe_robot` at ``foothold_i + std * noise_k``.
    """
    swing = -side_sign(side)
    steps = geometry.compose(stance, side_actions(robot, swing))  # (N, 3)
    poses = _noisy(steps, noise, cfg)  # (N, K, 3)
    n, k = poses.shape[:2]
    near = _near(terrain, index_terrain(terrain, probe), probe, stance, side, poses.reshape(n * k, 3))
    return jnp.mean(near.reshape(n, k).astype(jnp.float32), axis=1)


# --------------------------------------------------------------------------- objective


class Batch(NamedTuple):
    """A training minibatch: the decisions and the (B, N) exact risk of every action."""

    decisions: Decisions
    risk: jax.Array


def make_batch_fn(robot: Robot, cfg: ForwardConfig):
    """``batch_fn(key) -> Batch`` of ``cfg.batch_size`` decisions with per-action risk (jit-able)."""
    probe = probe_robot(robot, cfg.distance)

    def batch_fn(key):
        d = sample_decisions(key, int(cfg.batch_size), cfg)
        risk = jax.vmap(lambda t, s, side, nz: action_risk(t, robot, probe, s, side, nz, cfg))(
            d.terrains, d.stances, d.sides, d.noise
        )
        return Batch(d, risk)

    return batch_fn


def _errors(robot: Robot, side, command, acts_rel):
    """(N,) translation (m) and heading (rad) error of every action against p_next (stance frame)."""
    swing = -side_sign(side)
    p_next = side_p0(robot, swing) + robot.step_time * command
    d = acts_rel - p_next
    return geometry.safe_norm(d[..., 0], d[..., 1]), jnp.abs(geometry.wrap_angle(d[..., 2]))


def decision_objective(uparams: dict, robot: Robot, terrain, stance, side, command, risk, cfg: ForwardConfig) -> dict:
    """Relaxed objective of one decision, as named terms (each ()).

    Returns:
      dict with ``objective`` (m), ``command_error`` (m), ``translation_error_m``,
      ``rotation_error_rad``, ``risk`` (expected near-obstacle probability).
    """
    rb = with_params(robot, uparams)
    r = relax.relaxed_select(terrain, rb, stance, side, command, sharpness=cfg.sharpness, tau=cfg.tau,
                             barrier_weight=cfg.barrier_weight, exact=False)
    swing = -side_sign(side)
    et, er = _errors(rb, side, command, side_actions(rb, swing))
    trans = r.probs @ et
    rot = r.probs @ er
    risk_e = r.probs @ risk
    cmd = trans + cfg.rotation_scale * rot
    return {
        "objective": cmd + cfg.risk_weight * risk_e,
        "command_error": cmd,
        "translation_error_m": trans,
        "rotation_error_rad": rot,
        "risk": risk_e,
    }


def objective(uparams: dict, batch: Batch, robot: Robot, cfg: ForwardConfig) -> tuple[jax.Array, dict]:
    """() mean relaxed objective over a minibatch (m), and the mean of each named term.

    Args:
      uparams: dict name -> () unconstrained variable (see :func:`to_unconstrained`).
      batch: :class:`Batch` (from :func:`make_batch_fn`).
      robot: the base Robot (untuned leaves).
      cfg: the config (objective weights and relaxation).

    Example:
      >>> from ijoy_jax.tune import forward
      >>> cfg = forward.ForwardConfig(shape=(40, 40), density=0.1, batch_size=2, num_noise_samples=2)
      >>> robot = forward.paper_robot(cfg)
      >>> batch = forward.make_batch_fn(robot, cfg)(jax.random.key(0))
      >>> loss, terms = forward.objective(forward.to_unconstrained(robot, cfg.tuned_names()), batch, robot, cfg)
      >>> bool(loss > 0), sorted(terms)[:2]
      (True, ['command_error', 'risk'])
    """
    d = batch.decisions
    terms = jax.vmap(lambda t, s, side, c, rk: decision_objective(uparams, robot, t, s, side, c, rk, cfg))(
        d.terrains, d.stances, d.sides, d.commands, batch.risk
    )
    terms = {k: jnp.mean(v) for k, v in terms.items()}
    return terms.pop("objective"), terms


# --------------------------------------------------------------------------- tuning


class ForwardResult(NamedTuple):
    """Result of :func:`tune_forward`.

    robot: the tuned Robot (best run).
    params: dict name -> tuned value (natural units) of the best run.
    result: the :class:`~ijoy_jax.tune.loop.TuneResult` (all runs; unconstrained params).
    best_run: index of the run kept (0 for a single run).
    """

    robot: Robot
    params: dict
    result: loop.TuneResult
    best_run: int


def tune_forward(
    robot: Robot,
    cfg: ForwardConfig,
    *,
    key=None,
    init: dict | None = None,
    num_runs: int | None = None,
    progress: bool = True,
    log_every: int = 10,
    out_dir: str | Path | None = None,
) -> ForwardResult:
    """Minimise the relaxed forward objective with Adam over fresh minibatches each step.

    Args:
      robot: starting Robot (e.g. :func:`paper_robot`); untuned leaves stay fixed.
      cfg: :class:`ForwardConfig`.
      key: int or PRNG key of the training minibatches (default ``cfg.seed``).
      init: optional dict name -> starting value(s) (natural units); (R,) arrays
        with ``num_runs=R`` start R runs at once (vmapped; common minibatches).
      num_runs: None (one run) or R.
      progress, log_every, out_dir: see :func:`ijoy_jax.tune.loop.tune`; the
        config and tuned values are saved in the manifest.

    Returns:
      :class:`ForwardResult`; with several runs the one with the lowest mean
      loss over the last 20% of steps (the same minibatches for every run).
    """
    names = cfg.tuned_names()
    key = cfg.seed if key is None else key
    u0 = to_unconstrained(robot, names, init)
    if num_runs is not None:
        u0 = {n: jnp.broadcast_to(v, (num_runs,)) for n, v in u0.items()}
    elif any(np.ndim(v) for v in u0.values()):
        raise ValueError("init has per-run values: pass num_runs")
    loss = functools.partial(objective, robot=robot, cfg=cfg)
    res = loop.tune(loss, u0, optax.adam(cfg.learning_rate), int(cfg.steps), key=key,
                    batch_fn=make_batch_fn(robot, cfg), num_runs=num_runs, has_aux=True,
                    progress=progress, log_every=log_every)
    best = 0
    if num_runs is not None:
        tail = max(1, int(cfg.steps) // 5)
        best = int(np.argmin(res.losses[:, -tail:].mean(axis=1)))
    ubest = {n: jnp.asarray(v[best] if num_runs is not None else v) for n, v in res.params.items()}
    tuned = with_params(robot, ubest)
    values = {n: float(v) for n, v in natural_values(robot, ubest).items()}
    if out_dir is not None:
        extra = {"tuned": values, "best_run": best, "all_runs": natural_values(robot, res.params)}
        res = res._replace(out_dir=loop.save(out_dir, res, config=cfg, extra=extra))
    return ForwardResult(tuned, values, res, best)


# --------------------------------------------------------------------------- exact evaluation


class Evaluation(NamedTuple):
    """Exact-selector evaluation of B decisions with K noise draws each (per decision, (B,)).

    Fields::

      valid: a valid step exists (else the robot stops: no foothold placed).
      translation_error_m: |dxy| of the choice (the step-in-place pose if none) against p_next.
      rotation_error_rad: |wrap(dtheta)| of the choice against p_next.
      near: int32 noisy placements (of K) within ``distance`` of an obstacle (0 if not valid).
      on_obstacle: int32 noisy placements (of K) whose footprint itself overlaps
        an obstacle or leaves the map (0 if not valid).
      index: int32 chosen action (-1 if none).
    """

    valid: jax.Array
    translation_error_m: jax.Array
    rotation_error_rad: jax.Array
    near: jax.Array
    on_obstacle: jax.Array
    index: jax.Array


def evaluate(robot: Robot, decisions: Decisions, cfg: ForwardConfig) -> Evaluation:
    """Score the EXACT exhaustive selector (against p_next) on decisions, with sampled placement noise.

    Args:
      robot: the parameters to evaluate (tuned, or the paper's :func:`paper_robot`).
      decisions: :class:`Decisions` (e.g. held out: :func:`sample_decisions` with another key).
      cfg: supplies distance, noise std (the decisions carry the draws).

    Returns:
      :class:`Evaluation`; :func:`summarize` reduces it.

    Example:
      >>> from ijoy_jax.tune import forward
      >>> cfg = forward.ForwardConfig(shape=(40, 40), density=0.1, num_noise_samples=4)
      >>> ev = forward.evaluate(forward.paper_robot(cfg), forward.sample_decisions(1, 3, cfg), cfg)
      >>> ev.near.shape
      (3,)
    """
    return _evaluate(robot, probe_robot(robot, cfg.distance), probe_robot(robot, 0.0), decisions, cfg)


@functools.partial(jax.jit, static_argnames=("cfg",))
def _evaluate(robot, probe_near, probe_on, decisions, cfg):
    targets = make_targets(robot)

    def one(t, stance, side, command, noise):
        p = prepare(t, robot, targets=targets)
        c = select_step(t, robot, stance, side, command, SelectOptions(quantize=False), targets=p.targets,
                        index=p.index)
        et, er = _errors(robot, side, command, geometry.relative(stance, c.pose)[None])
        poses = _noisy(c.pose, noise, cfg)  # (K, 3)
        near = _near(t, index_terrain(t, probe_near), probe_near, stance, side, poses)
        on = _near(t, index_terrain(t, probe_on), probe_on, stance, side, poses)
        count = lambda b: jnp.where(c.valid, jnp.sum(b), 0).astype(jnp.int32)  # noqa: E731
        return Evaluation(c.valid, et[0], er[0], count(near), count(on), c.index)

    return jax.vmap(one)(decisions.terrains, decisions.stances, decisions.sides, decisions.commands,
                         decisions.noise)


def summarize(ev: Evaluation, cfg: ForwardConfig) -> dict:
    """Held-out numbers (floats/ints): decisions, stops, mean errors, near/on counts and rates, objective.

    ``objective`` is the exact counterpart of the relaxed one:
    mean(translation + rotation_scale * rotation) + risk_weight * near_rate.
    """
    valid = np.asarray(ev.valid)
    k = int(cfg.num_noise_samples)
    b = valid.size
    trans = float(np.mean(ev.translation_error_m))
    rot = float(np.mean(ev.rotation_error_rad))
    placements = int(valid.sum()) * k
    near = int(np.sum(ev.near))
    on = int(np.sum(ev.on_obstacle))
    near_rate = near / max(placements, 1)
    return {
        "decisions": b,
        "noise_samples": k,
        "no_valid_step": int(b - valid.sum()),
        "translation_error_m": trans,
        "rotation_error_rad": rot,
        "command_error": trans + cfg.rotation_scale * rot,
        "placements": placements,
        "near_obstacle": near,
        "near_obstacle_rate": near_rate,
        "on_obstacle": on,
        "on_obstacle_rate": on / max(placements, 1),
        "objective": trans + cfg.rotation_scale * rot + cfg.risk_weight * near_rate,
    }


def compare(tuned: Robot, cfg: ForwardConfig, *, num: int = 200, key=12345, baseline: Robot | None = None) -> dict:
    """Held-out comparison: :func:`summarize` of the tuned robot and of the paper's parameters on the same decisions.

    Args:
      tuned: the tuned Robot.
      cfg: the config it was tuned with.
      num: held-out decisions (use a key not used in training).
      key: int or PRNG key of the held-out decisions.
      baseline: default :func:`paper_robot` (HRP-2 with the paper's w = 1,
        rotation_weight = 100 and ``cfg.margin``).

    Returns:
      ``{"tuned": {...}, "paper": {...}, "num": num}``.
    """
    baseline = paper_robot(cfg) if baseline is None else baseline
    held = jax.jit(sample_decisions, static_argnums=(1, 2))(as_key(key), int(num), cfg)
    return {
        "tuned": summarize(evaluate(tuned, held, cfg), cfg),
        "paper": summarize(evaluate(baseline, held, cfg), cfg),
        "num": int(num),
    }

"""The cue's tunable numbers: :class:`CueParams`, their defaults, and the checks of their ranges.

C1 (the largest force), the decay depth (ALDURO's C2 per unit of depth), the per-axis distance scales and
the soft-min temperature are the traced leaves of :class:`CueParams`: changing them never recompiles, and
the force is differentiable in them. :func:`check_params` holds the rules a concrete value must meet;
inside a trace the force applies the same rules and flags a value out of range instead of raising.

Units: distances in command-distance units (fractions of a full forward deflection); forces as fractions
of the device's maximum.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.struct import check_numeric, is_traced, pytree_dataclass

DEFAULT_C1 = 0.8
"""Largest cue force, as a fraction of the device's maximum (leaves 20 % for the device's own centring)."""
DEFAULT_DECAY = 0.1
"""Depth (command-distance units: fractions of a full forward deflection) over which the force rises to
``1 - 1/e`` of C1: 63 % at 2 cm of step beyond the last open cell (0.1 * 0.25 m/s * 0.8 s for HRP-2)."""
DEFAULT_TEMPERATURE = 0.001
"""Soft-min temperature and smoothing scale (distance units): well below HRP-2's half cells (0.125 units
forward, 0.05 sideways), so the soft geometry is the cells' to within a few percent of a cell."""


@pytree_dataclass
class CueParams:
    """The cue's tunable numbers, all traced leaves (float32): changing them never recompiles.

    Attributes:
      c1: () C1, the largest force as a fraction of the device's maximum, in [0, 1].
      decay: () > 0, distance units: the force reaches ``1 - 1/e`` of C1 this deep into the blocked region
        (ALDURO's ``C2 = exp(-1 / decay)`` per unit of depth).
      scales: (3,) > 0, dimensionless multipliers of :attr:`FeasibleCommands.unit` per axis (forward,
        sideways, turn): larger makes that axis's distances count less.
      temperature: () > 0, distance units: soft-min temperature and smoothing scale.
    """

    c1: jax.Array
    decay: jax.Array
    scales: jax.Array
    temperature: jax.Array


def make_params(
    *, c1=DEFAULT_C1, decay=None, c2=None, scales=(1.0, 1.0, 1.0), temperature=DEFAULT_TEMPERATURE
) -> CueParams:
    """A fresh :class:`CueParams` (float32 leaves), checked where concrete.

    Args:
      c1: C1 in [0, 1] (fraction of the device's maximum force).
      decay: decay depth > 0 (distance units); default :data:`DEFAULT_DECAY`.
      c2: ALDURO's C2 in (0, 1) per unit of depth, instead of ``decay`` (``decay = -1 / ln C2``).
      scales: (3,) per-axis multipliers of the distance unit, > 0.
      temperature: soft-min temperature > 0 (distance units).

    Raises:
      ValueError: both ``decay`` and ``c2``, or a value out of range, naming it.

    Example:
      >>> from ijoy_jax import cue
      >>> p = cue.make_params(c1=0.5, c2=0.1)
      >>> round(float(p.decay), 4)
      0.4343
    """
    if decay is not None and c2 is not None:
        raise ValueError("give decay or c2 (decay = -1 / ln c2), not both")
    if c2 is not None:
        check_numeric("c2", c2)
        if not is_traced(c2):
            v = np.asarray(c2, np.float64)
            if v.shape != () or not (np.isfinite(v) and 0 < v < 1):
                raise ValueError(f"c2 must be a scalar in (0, 1) (the factor per unit of depth), got {c2!r}")
        decay = -1.0 / jnp.log(jnp.asarray(c2, jnp.float32))
    elif decay is None:
        decay = DEFAULT_DECAY
    scales = _f32(scales)
    if scales.shape not in ((), (3,)):
        raise ValueError(
            f"scales must be a number or have shape (3,) (forward, sideways, turn), got shape {scales.shape}"
        )
    p = CueParams(c1=_f32(c1), decay=_f32(decay), scales=jnp.broadcast_to(scales, (3,)), temperature=_f32(temperature))
    check_params(p)
    return p


def _f32(v):
    check_numeric("a cue parameter", v)
    return jnp.asarray(v, jnp.float32)


_PARAM_RULES = (
    (
        "c1",
        (),
        "finite and in [0, 1] (a fraction of the device's maximum force)",
        lambda xp, v: xp.isfinite(v) & (v >= 0) & (v <= 1),
    ),
    ("decay", (), "finite and > 0 (distance units)", lambda xp, v: xp.isfinite(v) & (v > 0)),
    ("scales", (3,), "finite and > 0 on every axis", lambda xp, v: xp.all(xp.isfinite(v) & (v > 0))),
    ("temperature", (), "finite and > 0 (distance units)", lambda xp, v: xp.isfinite(v) & (v > 0)),
)


def check_params(params: CueParams) -> None:
    """Raise naming the field if a concrete :class:`CueParams` value is out of range (tracers are skipped).

    Inside a trace the same rules give a zero force flagged ``bad_params`` (:class:`CueForce`).

    Raises:
      TypeError: not a CueParams. ValueError: a wrong shape or a value out of range.
    """
    if not isinstance(params, CueParams):
        raise TypeError(f"params must be an ijoy_jax.cue.CueParams (make_params), got {type(params).__name__}")
    for name, shape, must, rule in _PARAM_RULES:
        v = getattr(params, name)
        if np.shape(v) != shape:
            raise ValueError(f"params.{name} must have shape {shape}, got {np.shape(v)}")
        if is_traced(v):
            continue
        check_numeric(f"params.{name}", v)
        arr = np.asarray(v, np.float64)
        if not bool(rule(np, arr)):
            raise ValueError(f"params.{name} must be {must}, got {arr.tolist()}")

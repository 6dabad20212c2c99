"""What a terrain family is: its registry record, its parameters' rules, and the helpers every family shares.

A family (:class:`Family`) carries everything a caller needs: its generator,
its parameter pytree class, its default static ``max_count`` (object or step
slots; None for families without them), the posed objects it rasterises
(object families), its validation of parameter values (:meth:`Family.check`,
:meth:`Family.validate`) and the extra per-scenario metrics it adds to a
sweep's results (:meth:`Family.metrics`, columns :attr:`Family.metric_names`).
Callers ask the record; nothing outside a family tests its name.

Each parameter field declares what it accepts with :func:`param` and a
:class:`Rule` (range, integer count, whether ``inf`` is allowed, the field it
must not exceed). Generators check only that concrete values are finite
(:func:`check_params`; they clip everything else); configs, sweeps and tuners
check the rules before any compute.

The helpers below (the sampling :class:`Grid`, :func:`uniform`,
...) are shared by :mod:`~ijoy_jax.terrain.objects` and
:mod:`~ijoy_jax.terrain.surfaces`; the registry of families by name is
:data:`ijoy_jax.terrain.generators.FAMILIES`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.limits import check_map_shape
from ijoy_jax.terrain.grid import Terrain, grid_spec

__all__ = [
    "ANY",
    "COUNT",
    "NONNEG",
    "Family",
    "Grid",
    "ParamError",
    "Rule",
    "StartZone",
    "check_max",
    "check_params",
    "f32",
    "lerp",
    "make_grid",
    "param",
    "rules",
    "start_zone_reach",
    "uniform",
]


# --------------------------------------------------------------------------- parameter rules


class ParamError(ValueError):
    """A terrain parameter value a family does not accept.

    Attributes:
      cls: the parameter class's name; field: the field; reason: why (``"must be >= 0, got -1.0"``).
    """

    def __init__(self, cls: str, field: str, reason: str):
        super().__init__(f"{cls}.{field}: {reason}")
        self.cls, self.field, self.reason = cls, field, reason


@dataclasses.dataclass(frozen=True, kw_only=True)
class Rule:
    """The values one parameter field accepts (checked on concrete values, before any compute).

    Fields::

      lo, hi: closed range of the value (units of the field).
      integer: an integer (a count); floats are refused.
      count: the count the static ``max_count`` bounds (its generator clips to it).
      allow_inf: +-inf is meaningful (e.g. "no threshold"); NaN never is.
      at_most: name of a field this one must not exceed (``size_min`` <= ``size_max``).
    """

    lo: float = -math.inf
    hi: float = math.inf
    integer: bool = False
    count: bool = False
    allow_inf: bool = False
    at_most: str | None = None


ANY = Rule()
"""Any finite number."""
NONNEG = Rule(lo=0.0)
"""A finite number >= 0 (sizes, spacings, half-ranges of jitter)."""
COUNT = Rule(lo=0, integer=True, count=True)
"""The family's count: an integer >= 0, at most ``max_count``."""


def start_zone_reach(start_x: float, start_y: float, shape, resolution: float) -> float:
    """Distance (m) from the start point to the farthest cell centre of the map: a ``start_radius`` at or
    above it keeps the whole map clear (see :class:`StartZone`).

    Example:
      >>> round(start_zone_reach(0.5, 0.5, (10, 10), 0.1), 4)   # centre of a 1 m map, corner centres
      0.6364
    """
    nx, ny = shape
    res = float(resolution)
    sx, sy = start_x * nx * res, start_y * ny * res  # from the origin
    fx = max(abs(sx - 0.5 * res), abs((nx - 0.5) * res - sx))
    fy = max(abs(sy - 0.5 * res), abs((ny - 0.5) * res - sy))
    return math.hypot(fx, fy)


def param(default, rule: Rule = ANY) -> Any:
    """A parameter field with its default and its :class:`Rule` (kept in the field's metadata)."""
    return dataclasses.field(default=default, metadata={"rule": rule})


def rules(cls) -> dict[str, Rule]:
    """Every field of a parameter class and its :class:`Rule` (``ANY`` where none is declared)."""
    return {f.name: f.metadata.get("rule", ANY) for f in dataclasses.fields(cls)}


@dataclasses.dataclass(frozen=True, kw_only=True)
class StartZone:
    """Keep-clear start zone shared by every family (see :mod:`ijoy_jax.terrain.generators`)."""

    start_x: Any = param(0.15)  # fraction of the map's x extent from the origin
    start_y: Any = param(0.5)  # fraction of the map's y extent from the origin
    start_radius: Any = param(0.35, NONNEG)  # metres; <= 0 disables the zone (configs: >= 0)


# --------------------------------------------------------------------------- the registry record


@dataclasses.dataclass(frozen=True, kw_only=True, eq=False)
class Family:
    """A registered terrain family: everything a caller needs to know about it.

    Fields::

      name: the family's name in :data:`ijoy_jax.terrain.generators.FAMILIES`.
      generator: ``generator(key, params, *, shape, resolution, has_height, origin[, max_count]) -> Terrain``.
      params: the parameter pytree class; ``params()`` builds fresh defaults.
      max_count: default static object/step slots, or None if the family takes no ``max_count``.
      objects: object families: ``objects(key, params, *, shape, resolution, origin, max_count)
        -> Objects``, the posed boxes and cylinders the generator rasterises; None otherwise.
      metric_names: the columns :meth:`metrics` adds to a sweep's results (() for none).
      scenario_metrics: ``f(key, params, feet, foot_length, foot_width, *, shape, resolution,
        origin, max_count) -> {name: () array}`` or None; call it through :meth:`metrics`.
    """

    name: str
    generator: Callable[..., Terrain]
    params: type
    max_count: int | None = None
    objects: Callable[..., Any] | None = None
    metric_names: tuple[str, ...] = ()
    scenario_metrics: Callable[..., dict[str, jax.Array]] | None = None

    @property
    def rules(self) -> dict[str, Rule]:
        """``{field: Rule}`` of the parameter class."""
        return rules(self.params)

    @property
    def count_field(self) -> str | None:
        """The parameter the static ``max_count`` bounds (``count``, ``num_steps``), or None."""
        return next((name for name, r in self.rules.items() if r.count), None)

    def check(self, field: str, value, *, max_count: int | None = None, max_count_key: str = "max_count"):
        """Check one concrete parameter value against its field's :class:`Rule`.

        Args:
          field: a field of :attr:`params`.
          value: a Python or NumPy scalar.
          max_count: the static slots in use (None: the count is not bounded here).
          max_count_key: how the caller names ``max_count`` in its error message.

        Returns:
          The value as an ``int`` (integer fields) or ``float``.

        Raises:
          ParamError: unknown field, not a number, NaN, inf where not allowed,
            out of range, a non-integer count, or a count above ``max_count``.

        Example:
          >>> from ijoy_jax.terrain import generators as gen
          >>> gen.FAMILIES["bars"].check("width", -0.1)
          Traceback (most recent call last):
          ...
          ijoy_jax.terrain.family.ParamError: BarParams.width: must be >= 0, got -0.1
        """
        table = self.rules
        if field not in table:
            raise ParamError(self.params.__name__, field, f"unknown field; known: {', '.join(table)}")
        rule = table[field]

        def fail(reason):
            raise ParamError(self.params.__name__, field, reason)

        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
            fail(f"must be a number, got {type(value).__name__} {value!r}")
        if rule.integer:
            if not isinstance(value, (int, np.integer)):
                fail(f"must be an integer (a count), got {type(value).__name__} {value!r}")
            v = int(value)
        else:
            v = float(value)
            if math.isnan(v):
                fail(f"must be a number, got {value!r}")
            if math.isinf(v) and not rule.allow_inf:
                fail(f"must be finite, got {value!r}")
        if v < rule.lo:
            fail(f"must be >= {rule.lo:g}, got {v}")
        if v > rule.hi:
            fail(f"must be <= {rule.hi:g}, got {v}")
        if rule.count and max_count is not None and v > max_count:
            fail(f"{v} exceeds {max_count_key} = {max_count} (raise {max_count_key})")
        return v

    def validate(self, params, *, max_count: int | None = None, max_count_key: str = "max_count",
                 shape: tuple[int, int] | None = None, resolution: float | None = None) -> None:
        """Check every field of concrete parameters (a params instance or ``{field: value}``), and their order.

        Each value goes through :meth:`check`; then every field with
        ``Rule.at_most`` must not exceed that field (an impossible range).
        Given the map's ``shape`` (cells) and ``resolution`` (m), the start
        zone must leave room for the family's terrain: a ``start_radius``
        that reaches every cell centre (the whole map kept clear, e.g. an
        obstacle-free map) is refused (:func:`start_zone_reach`).

        Raises:
          ParamError: naming the first offending field and the reason.

        Example:
          >>> from ijoy_jax.terrain import generators as gen
          >>> gen.FAMILIES["obstacles"].validate(gen.ObstacleParams(size_min=0.3, size_max=0.1))
          Traceback (most recent call last):
          ...
          ijoy_jax.terrain.family.ParamError: ObstacleParams.size_min: impossible range: size_min (0.3) > size_max (0.1)
        """
        values = params if isinstance(params, Mapping) else {k: getattr(params, k) for k in self.rules}
        checked = {k: self.check(k, v, max_count=max_count, max_count_key=max_count_key) for k, v in values.items()}
        for name, rule in self.rules.items():
            if rule.at_most is not None and name in checked and rule.at_most in checked:
                lo, hi = checked[name], checked[rule.at_most]
                if lo > hi:
                    raise ParamError(self.params.__name__, name,
                                     f"impossible range: {name} ({lo}) > {rule.at_most} ({hi})")
        if shape is not None and resolution is not None and {"start_x", "start_y", "start_radius"} <= checked.keys():
            r = checked["start_radius"]
            reach = start_zone_reach(checked["start_x"], checked["start_y"], shape, resolution)
            if r > 0 and r >= reach:
                nx, ny = shape
                raise ParamError(self.params.__name__, "start_radius",
                                 f"the start zone ({r:g} m around the start point) covers the whole "
                                 f"{nx * resolution:g} x {ny * resolution:g} m map, leaving no room for the "
                                 f"family's terrain (it would be cleared everywhere); use a radius below "
                                 f"{reach:.3g} m")

    def slots(self, params) -> int | None:
        """Static slots just big enough for concrete ``params``: ``max(count, 1)``; None without slots."""
        field = self.count_field
        if self.max_count is None or field is None:
            return None
        return max(int(getattr(params, field)), 1)

    def metrics(self, key, params, feet, foot_length, foot_width, *, shape, resolution: float,
                origin=(0.0, 0.0), max_count: int | None = None) -> dict[str, jax.Array]:
        """The family's extra per-scenario metrics (jit-able; ``{}`` for a family without any).

        Computed from the same terrain the generator made for ``key`` and
        ``params`` (bars: :func:`ijoy_jax.terrain.objects.bar_crossings` of
        the posed bars) and the robot's final stance.

        Args:
          key, params: as given to the generator.
          feet: (2, 3) final foot poses (world x, y, theta; metres, radians).
          foot_length, foot_width: footprint without margin, metres.
          shape, resolution, origin, max_count: the generator's grid and slots
            (``max_count`` None: the family's default).

        Returns:
          ``{name: () array}`` with exactly the keys :attr:`metric_names`.
        """
        if self.scenario_metrics is None:
            return {}
        n = self.max_count if max_count is None else max_count
        return self.scenario_metrics(key, params, feet, foot_length, foot_width, shape=shape,
                                     resolution=resolution, origin=origin, max_count=n)


# --------------------------------------------------------------------------- shared helpers


class Grid(NamedTuple):
    """The sampling grid of one generator call: static shape, resolution and 2D/2.5D flag, traced origin."""

    shape: tuple[int, int]
    res: float
    origin: jax.Array  # (2,) float32
    has_height: bool

    @property
    def size(self) -> jax.Array:
        return jnp.asarray(self.shape, jnp.float32) * self.res

    def centres(self) -> jax.Array:
        """(nx, ny, 2) world (x, y) of cell centres."""
        nx, ny = self.shape
        gx = self.origin[0] + (jnp.arange(nx, dtype=jnp.float32) + 0.5) * self.res
        gy = self.origin[1] + (jnp.arange(ny, dtype=jnp.float32) + 0.5) * self.res
        return jnp.stack(jnp.meshgrid(gx, gy, indexing="ij"), axis=-1)

    def start(self, params) -> jax.Array:
        frac = jnp.stack([jnp.asarray(params.start_x, jnp.float32), jnp.asarray(params.start_y, jnp.float32)])
        return self.origin + frac * self.size

    def in_start_zone(self, params) -> jax.Array:
        """(nx, ny) bool: cell centres within start_radius of the start point."""
        d = self.centres() - self.start(params)
        r = jnp.asarray(params.start_radius, jnp.float32)
        return (jnp.sum(d * d, axis=-1) <= r * r) & (r > 0)

    def terrain(self, height=None, free=None) -> Terrain:
        """A Terrain on this grid; heights are dropped (zeros) on a 2D grid."""
        if height is None or not self.has_height:
            height = jnp.zeros(self.shape, jnp.float32)
        if free is None:
            free = jnp.ones(self.shape, bool)
        height = jnp.broadcast_to(jnp.asarray(height, jnp.float32), self.shape)
        return Terrain(
            height=height,
            free=jnp.broadcast_to(free, self.shape),
            origin=self.origin,
            resolution=self.res,
            has_height=self.has_height,
        )


def make_grid(shape, resolution, origin, has_height) -> Grid:
    """A :class:`Grid` from a generator's static keywords (checked)."""
    nx, ny = check_map_shape(shape)
    res, origin = grid_spec(resolution, origin)
    return Grid((nx, ny), res, origin, bool(has_height))


def check_max(max_count) -> int:
    """``max_count`` as a non-negative int (it sizes arrays: static)."""
    n = int(max_count)
    if n < 0 or n != max_count:
        raise ValueError(f"max_count must be a non-negative integer, got {max_count!r}")
    return n


def check_params(params, cls):
    """Default, type-check and (when concrete) finiteness-check a parameter pytree.

    NaN is refused everywhere and inf where the field's :class:`Rule` does not
    allow it; the generators clip everything else, so ranges are checked by
    :meth:`Family.check` (configs), not here.
    """
    if params is None:
        return cls()
    if not isinstance(params, cls):
        raise TypeError(f"expected {cls.__name__}, got {type(params).__name__}")
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if isinstance(value, jax.core.Tracer):
            continue
        a = np.asarray(value, dtype=np.float64)
        if np.any(np.isnan(a)) or (not f.metadata.get("rule", ANY).allow_inf and not np.all(np.isfinite(a))):
            raise ValueError(f"{cls.__name__}.{f.name} must be finite, got {value!r}")
    return params


def f32(x) -> jax.Array:
    return jnp.asarray(x, jnp.float32)


def uniform(key, shape, normal: bool = False) -> jax.Array:
    """float32 U[0, 1) (or standard normal) draws of ``shape``, from one 1D draw.

    One flat draw per generator, reshaped: XLA on CPU compiles a multi-dimensional
    ``random_bits`` several times slower than a 1D one of the same size.
    """
    size = math.prod(shape)
    draw = jax.random.normal if normal else jax.random.uniform
    return draw(key, (size,), jnp.float32).reshape(shape)


def lerp(u, lo, hi) -> jax.Array:
    """Map U[0, 1) draws ``u`` to [lo, hi)."""
    return f32(lo) + (f32(hi) - f32(lo)) * u

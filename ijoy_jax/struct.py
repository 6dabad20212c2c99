"""The package's shared building blocks: a small frozen-dataclass pytree helper (static fields are metadata,
the rest are leaves), the boundary helpers every public function shares (:func:`is_traced`, :func:`as_array`,
:func:`as_pose`, :func:`check_numeric`), and the range checks of the static configuration classes
(:func:`check_real`, :func:`check_whole`). Public because the modules of every part use them, and so may a
user's own pytree types and entry points.

Like ``mjx._src.dataclasses`` and ``flax.struct``: a field declared with
``static_field()`` is part of the tree's structure (hashable, never traced:
grid sizes, flags); every other field is a leaf that can be traced, vmapped and
differentiated.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Any, TypeVar

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import geometry

__all__ = ["as_array", "as_pose", "check_numeric", "check_real", "check_whole", "is_traced", "pytree_dataclass",
           "static_field"]

T = TypeVar("T")


def static_field(**kwargs: Any) -> Any:
    """A dataclass field that is pytree metadata (static under jit)."""
    metadata = dict(kwargs.pop("metadata", {}))
    metadata["static"] = True
    return dataclasses.field(metadata=metadata, **kwargs)


def pytree_dataclass(cls: type[T]) -> type[T]:
    """Turn ``cls`` into a frozen dataclass registered as a JAX pytree.

    Adds ``replace(**changes)``, returning a copy with some fields changed. A Python number given for a
    floating-point leaf takes that leaf's dtype (``1e39`` becomes ``inf`` in float32, which the boundary checks
    name): left as a Python float it would be a weakly typed leaf, and a jitted function called with it and
    with the original would compile twice.
    """
    cls = dataclasses.dataclass(frozen=True)(cls)
    fields = dataclasses.fields(cls)
    meta = [f.name for f in fields if f.metadata.get("static", False)]
    data = [f.name for f in fields if not f.metadata.get("static", False)]
    jax.tree_util.register_dataclass(cls, data_fields=data, meta_fields=meta)

    def replace(self: T, **changes: Any) -> T:
        for name in set(changes) & set(data):
            changes[name] = _like_leaf(getattr(self, name), changes[name])
        return dataclasses.replace(self, **changes)

    cls.replace = replace  # type: ignore[attr-defined]
    return cls


def _like_leaf(old: Any, value: Any) -> Any:
    """``value`` as an array of ``old``'s floating dtype if it is a plain Python int or float, else as given."""
    dtype = getattr(old, "dtype", None)
    if (dtype is None or isinstance(value, bool) or not isinstance(value, (int, float))
            or not jnp.issubdtype(dtype, jnp.floating)):
        return value
    with np.errstate(over="ignore"):  # float64 leaves stay float32 without x64, as JAX stores them
        return jnp.asarray(value, jax.dtypes.canonicalize_dtype(dtype))


def is_traced(*trees: Any) -> bool:
    """Whether any leaf of ``trees`` is a JAX tracer (the call is inside a user's jit, vmap or grad).

    A public function that is also called inside traces uses it to pick its path: traced, it inlines its
    implementation into the caller's trace; concrete, it calls its own module-level jit, so an eager loop
    compiles once.
    """
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(trees))


def as_array(name: str, value):
    """``value`` as a float32 array if it is a list or tuple (of numbers or of traced scalars), else as given.

    The public functions call it on their pose and command arguments first, so a Python list works inside
    a caller's jit as it does outside (NumPy cannot take the shape of a list of tracers).

    Raises:
      ValueError: a ragged or non-numeric list, naming ``name``.
    """
    if not isinstance(value, (list, tuple)):
        return value
    try:
        with np.errstate(over="ignore"):  # a number beyond float32 becomes inf: the caller's finite check names it
            return jnp.asarray(value, jnp.float32)
    except OverflowError:  # a Python int beyond float64 (10**400): no float holds it
        raise ValueError(f"{name} must be finite numbers, got an integer beyond float64 in {value!r:.80}") from None
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} must be an array of numbers, got {value!r}") from e


def as_pose(name: str, value):
    """A pose argument (``(..., 3)``: x, y, theta) as :func:`as_array` gives it, except that a concrete one whose
    heading lies beyond :data:`ijoy_jax.geometry.MAX_ANGLE` is first reduced by whole turns in float64
    (:func:`ijoy_jax.geometry.reduce_turns`): ``2 pi 1e7`` becomes 0, not a float32 whose spacing is 4 rad.
    A heading beyond :data:`ijoy_jax.geometry.MAX_HEADING` (``1e300``), which float64 cannot place, is refused.

    Raises:
      ValueError: naming ``name``: a heading beyond ``MAX_HEADING``, an integer beyond float64.
    """
    if value is None or is_traced(value):
        return as_array(name, value)
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            poses = np.asarray(value, np.float64)
    except OverflowError:  # a Python int beyond float64 (10**400)
        raise ValueError(f"{name} must be finite numbers, got an integer beyond float64 in {value!r:.80}") from None
    except (TypeError, ValueError):  # a list of tracers, strings: as_array and the checks name what is wrong
        return as_array(name, value)
    if poses.ndim == 0 or poses.shape[-1] != 3:
        return as_array(name, value)
    geometry.check_headings(name, poses)
    reduced = geometry.reduce_turns(poses)
    if np.array_equal(reduced, poses, equal_nan=True):
        return as_array(name, value)
    return reduced


def check_numeric(name: str, value) -> None:
    """Raise a TypeError naming ``name`` if a concrete ``value`` is not numbers (strings, objects); skip tracers.

    Without it an array of strings reaches ``jnp.asarray`` inside a jit and fails in JAX's own wording.
    """
    if value is None or is_traced(value):
        return
    kind = (value.dtype if hasattr(value, "dtype") else np.asarray(value).dtype).kind
    if kind not in "biuf":
        raise TypeError(f"{name} must be numbers, got {value!r}")


def check_real(label: str, value, lo: float = -math.inf, hi: float = math.inf, *, lo_in: bool = True,
               hi_in: bool = True) -> None:
    """Raise a ValueError naming ``label`` unless ``value`` is a finite Python or NumPy real in the range.

    For static configuration (hashed into compiled programs, so never traced): a bool, a string, None, an
    array or a complex number is refused as well as a NaN, an infinity or a value outside ``lo``..``hi``
    (``lo_in``/``hi_in``: whether the end itself is allowed).
    """
    ok = not isinstance(value, bool) and isinstance(value, numbers.Real) and math.isfinite(value)
    ok = ok and (lo <= value if lo_in else lo < value) and (value <= hi if hi_in else value < hi)
    if not ok:
        span = f"{'[' if lo_in and lo > -math.inf else '('}{lo:g}, {hi:g}{']' if hi_in and hi < math.inf else ')'}"
        raise ValueError(f"{label} must be a finite number in {span}, got {value!r}")


def check_whole(label: str, value, lo: int = 0) -> None:
    """Raise a ValueError naming ``label`` unless ``value`` is a Python or NumPy integer (not a bool) >= ``lo``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < lo:
        raise ValueError(f"{label} must be a whole number >= {lo}, got {value!r}")

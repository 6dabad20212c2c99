"""The selector's options as one value: :class:`SelectOptions`, built and checked once, passed through every layer.

Which search a decision runs (the method, the FootCost kernel, the lookahead's horizon and beam, the
refinement) is a program choice; how much a later step weighs (the discount) and how the refinement moves
(its span and minimum gain) are numbers. Like an optax transform or a diffrax solver, the options travel as
one frozen pytree: its static fields are the tree's structure, so they key the compiled programs, and its
leaves are traced, so a sweep or a tuner varies them without recompiling. :func:`ijoy_jax.select_step`,
:func:`ijoy_jax.rollout`, :func:`ijoy_jax.sim.walker.rollout` and everything between take the object, never
its fields one by one; strings become an object only at the edges (a sweep file, the command line).

The fields are checked when the object is built (and by ``replace``); the checks that need the robot (the
beam against the action set's size, the refinement's starts, refinement with the naive joystick) run once
at the API boundary, in :func:`checked`.
"""

from __future__ import annotations

import dataclasses
import numbers
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import lookahead
from ijoy_jax import refine as refine_mod
from ijoy_jax.struct import is_traced, pytree_dataclass, static_field

__all__ = ["KERNELS", "METHODS", "SelectOptions", "checked"]

METHODS = ("exhaustive", "ordered", "naive", "lookahead")
"""The selectors (:class:`SelectOptions` ``method``; :mod:`ijoy_jax.select` describes each)."""

KERNELS = ("xla", "pallas")
"""How FootCost is computed (:class:`SelectOptions` ``kernel``): XLA, or the fused Pallas kernel."""


def _host(value) -> bool:
    """Whether ``value`` is a value a caller typed (a Python or NumPy number or array, a list): what building the
    options checks. JAX arrays, tracers and the placeholders JAX puts in a tree while it maps one pass unchecked:
    the boundary (:func:`checked`) checks a concrete JAX array, the search flags a traced one."""
    return isinstance(value, (numbers.Number, np.ndarray, np.generic, list, tuple, str))


@pytree_dataclass
class SelectOptions:
    """How a decision searches for the next step: the selector's options as one frozen, checked pytree.

    Static fields (the tree's structure: each value compiles its own program)::

      method: "exhaustive" (FootCost of every action, then the argmin), "ordered" (the paper's search:
        the actions in order of dist to the target, stopping once nothing later can win; the same steps.
        Vmapped, a batch searches until its slowest query is done: on a GPU with the fused kernel the
        exhaustive search decides large batches faster, BENCHMARKS.md),
        "naive" (the conventional joystick: the action nearest the target, whatever the terrain) or
        "lookahead" (the first step of the best ``horizon``-step sequence, :mod:`ijoy_jax.lookahead`).
      kernel: how FootCost is computed: "xla" or "pallas", one fused kernel per decision
        (:mod:`ijoy_jax.footcost.pallas`: the same costs to float32 rounding, faster on a GPU; interpreted,
        slowly, on a CPU).
      quantize: bool, score against the nearest target f_i of F (the paper) rather than p_next itself
        (the ordered search always quantises).
      swing_path: bool, check the swing foot's corridor on 2.5D terrains (where the swing foot's start is
        known: ``select_step``'s ``swing_from``, the rollout's swing foot).
      horizon: int >= 1, steps scored per decision: 2 for "lookahead" when not given, 1 (the only value)
        for the other methods. ``replace(method=...)`` with another method and no horizon derives it again.
      beam: None (the exact lookahead: branch and bound, N^horizon FootCost evaluations in the worst case)
        or K >= 1, sequences kept per level (at most the action set's size N; "lookahead" only).
      chunk: None (the method's default) or an int >= 1: actions per chunk of the ordered search (32), or
        first actions expanded per iteration of the exact lookahead
        (:data:`ijoy_jax.lookahead.DEFAULT_CHUNK`; more on a GPU).

    Leaves (traced: new values reuse the compiled program)::

      discount: () float32 gamma >= 0, the weight of each later step of a lookahead relative to the one
        before (unitless; unused by the other methods).
      refine: None (no refinement) or a :class:`ijoy_jax.refine.RefineParams` (its ``span`` and ``min_gain``
        leaves traced, ``levels`` and ``starts`` static): the chosen step refined in continuous
        (dx, dy, dtheta) on the exact cost against p_next (:mod:`ijoy_jax.refine`; not with "naive").
        ``True`` builds :func:`ijoy_jax.refine.params`' defaults, ``False`` is None.

    Built values are checked at once (ValueError or TypeError naming the field); ``replace`` checks what it
    sets. Equal options compare and hash equal, so a jitted function given either reuses one program.

    Example:
      >>> import ijoy_jax as ij
      >>> terrain, robot = ij.terrain.flat((100, 100), 0.02), ij.robots.hrp2()
      >>> options = ij.SelectOptions(method="lookahead", discount=0.5)
      >>> options.horizon, float(options.discount)
      (2, 0.5)
      >>> c = ij.select_step(terrain, robot, [1.0, 1.0, 0.0], -1, [0.25, 0.0, 0.0], options)
      >>> bool(c.valid)
      True
      >>> c2 = ij.select_step(terrain, robot, [1.0, 1.0, 0.0], -1, [0.25, 0.0, 0.0], options.replace(discount=0.9))
    """

    method: str = static_field(default="exhaustive")
    kernel: str = static_field(default="xla")
    quantize: bool = static_field(default=True)
    swing_path: bool = static_field(default=True)
    horizon: int | None = static_field(default=None)
    beam: int | None = static_field(default=None)
    chunk: int | None = static_field(default=None)
    discount: Any = 1.0
    refine: Any = None

    def __post_init__(self):
        if not isinstance(self.method, str) or self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if not isinstance(self.kernel, str) or self.kernel not in KERNELS:
            raise ValueError(f"kernel must be one of {KERNELS}, got {self.kernel!r}")
        for name in ("quantize", "swing_path"):
            v = getattr(self, name)
            if not isinstance(v, (bool, np.bool_)):
                raise TypeError(f"{name} must be True or False (static), got {v!r}")
            object.__setattr__(self, name, bool(v))
        horizon = (2 if self.method == "lookahead" else 1) if self.horizon is None else self.horizon
        discount = self.discount
        if isinstance(discount, (bool, np.bool_, str)) or (
            discount is not None and _host(discount) and np.asarray(discount).dtype.kind not in "iuf"
        ):
            raise TypeError(f"discount must be a number (gamma >= 0), got {discount!r}")
        lookahead.check_options(self.method, horizon, self.beam, None, discount if _host(discount) else None)
        object.__setattr__(self, "horizon", int(horizon))
        if self.beam is not None:
            object.__setattr__(self, "beam", int(self.beam))
        chunk = self.chunk
        if chunk is not None and (
            isinstance(chunk, (bool, np.bool_)) or not isinstance(chunk, (int, np.integer)) or chunk < 1
        ):
            raise ValueError(f"chunk must be an int >= 1 or None (the method's default), got {chunk!r}")
        if chunk is not None:
            object.__setattr__(self, "chunk", int(chunk))
        if _host(discount):
            object.__setattr__(self, "discount", jnp.asarray(discount, jnp.float32))
        object.__setattr__(self, "refine", _as_refine(self.refine))

    def _static(self) -> tuple:
        """The fields that decide the program, the refinement's static ones included (hashable)."""
        r = self.refine
        refine_static = None if not isinstance(r, refine_mod.RefineParams) else (r.levels, r.starts)
        return (
            self.method,
            self.kernel,
            self.quantize,
            self.swing_path,
            self.horizon,
            self.beam,
            self.chunk,
            refine_static,
        )

    def __eq__(self, other) -> bool:
        if not isinstance(other, SelectOptions):
            return NotImplemented
        if self._static() != other._static():
            return False
        mine, theirs = jax.tree_util.tree_leaves(self), jax.tree_util.tree_leaves(other)
        return len(mine) == len(theirs) and all(_same_leaf(a, b) for a, b in zip(mine, theirs, strict=True))

    def __hash__(self) -> int:
        return hash((type(self), self._static()))


def _same_leaf(a, b) -> bool:
    """Equal values (concrete leaves), or the same object (traced ones)."""
    if a is b:
        return True
    if is_traced(a) or is_traced(b):
        return False
    return bool(np.array_equal(np.asarray(a), np.asarray(b)))


def _as_refine(value):
    """The ``refine`` field: None, or a :class:`~ijoy_jax.refine.RefineParams` (True: the defaults); a
    RefineParams of typed numbers is checked and its leaves made float32 arrays (one program for all)."""
    if value is None or (isinstance(value, (bool, np.bool_)) and not value):
        return None
    if isinstance(value, (bool, np.bool_)):
        return refine_mod.params()
    if not isinstance(value, refine_mod.RefineParams):
        refine_mod.check_params(value)  # a TypeError saying what refine must be
    if all(_host(v) for v in (value.span, value.min_gain)):
        return refine_mod.params(value.span, value.min_gain, levels=value.levels, starts=value.starts)
    return value


def _replace(self: SelectOptions, **changes) -> SelectOptions:
    """A copy with some fields changed, checked as a new object is (a new ``method`` without a ``horizon``
    derives the horizon again: 2 for "lookahead", 1 otherwise). A number set here is checked as typed, then
    made a float32 leaf, as when the options are built."""
    if "method" in changes and changes["method"] != self.method and "horizon" not in changes:
        changes["horizon"] = None
    return dataclasses.replace(self, **changes)


SelectOptions.replace = _replace  # type: ignore[attr-defined]


def checked(options: SelectOptions | None, robot) -> SelectOptions:
    """``options`` (None: the defaults) checked against ``robot`` once, at a public function's boundary.

    What building the options cannot know: the beam and the refinement's starts against the action set's
    size N (``robot.num_actions``), a concrete JAX discount or refinement leaf out of range; and refinement
    with ``method="naive"`` (the naive joystick ignores the terrain; refinement is on the terrain's cost).

    Raises:
      TypeError: ``options`` is not a :class:`SelectOptions` (e.g. the strings of a config: build the object).
      ValueError: one of the checks above, naming the field.
    """
    if options is None:
        options = SelectOptions()
    if not isinstance(options, SelectOptions):
        raise TypeError(
            f"options must be an ijoy_jax.SelectOptions (or None: the defaults), got {type(options).__name__}"
        )
    if options.discount is None:
        raise TypeError("options.discount must be a number (gamma >= 0), got None")
    lookahead.check_options(options.method, options.horizon, options.beam, robot.num_actions, options.discount)
    if options.refine is not None:
        if options.method == "naive":
            raise ValueError(
                "refine applies to the terrain-aware methods (exhaustive, ordered, lookahead); "
                "method='naive' is the conventional joystick, which ignores the terrain"
            )
        refine_mod.check_params(options.refine, robot.num_actions)
    return options

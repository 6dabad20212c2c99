"""Sizes the library refuses before it allocates: one memory budget for the library, the CLI, sweep files and
the footstep server.

Every size a caller gives (a map's cells, an image's pixels, an action set's density, a rollout's steps) is
checked against these bounds at the boundary, before any array is made, so a typo such as ``100000x100000``
or ``density=50`` is one line naming the value and its bound instead of minutes of work and an out-of-memory
kill. What each bound costs at its limit, on one device (float32):

- a map of :data:`MAX_MAP_CELLS` cells (2048 x 2048): ~250 MB of FootCost tables (~60 bytes per cell: the
  occupancy prefix sums, the height pyramid and the padded height tables), per map held at once;
- an action set at :data:`MAX_DENSITY` (:data:`MAX_ACTIONS` actions): ~1 GB of targets table (it grows as
  the density's sixth power: ~8 GB at 3);
- a rollout of :data:`MAX_NUM_STEPS` steps: its trajectory, ~100 bytes per step with the perfect robot
  (~10 MB), more with the MJX walker's log;
- a lookahead of :data:`MAX_HORIZON` steps: one search level per step in the compiled program, and up to
  ``(horizon - 1) x beam x N`` FootCost evaluations per decision;
- a footprint or swing window of :data:`MAX_WINDOW_CELLS` cells across: the per-candidate windows FootCost
  reads, ``(cells)**2`` per candidate.

The footstep server's own limits (:class:`ijoy_jax.server.schema.Limits`) are per deployment and may be set
lower, never higher than these.
"""

from __future__ import annotations

import math
import operator

__all__ = [
    "MAX_ACTIONS",
    "MAX_DENSITY",
    "MAX_HORIZON",
    "MAX_MAP_CELLS",
    "MAX_NUM_STEPS",
    "MAX_WINDOW_CELLS",
    "check_map_shape",
    "check_num_steps",
    "check_window",
    "window_cells",
]

MAX_MAP_CELLS = 2**22
"""Most cells of one map (nx * ny, e.g. 2048 x 2048): a generated map, a decoded image, a drive's or a tuner's
map, a sweep's map and the server's largest ``max_cells``."""
MAX_DENSITY = 2.0
"""Largest action-set density (:func:`ijoy_jax.robots.hrp2`'s ``density``: 3307 actions at the paper's reach)."""
MAX_ACTIONS = 3307
"""Most actions per foot (HRP-2's at :data:`MAX_DENSITY` and the paper's reach): the targets table's bound."""
MAX_HORIZON = 8
"""Most steps a lookahead scores per decision (:class:`ijoy_jax.SelectOptions`' ``horizon``, a sweep's): the
program holds one search level per step, so a horizon of a million traced for hours before compiling."""
MAX_NUM_STEPS = 100_000
"""Most decisions per rollout: the trajectory holds every step (a 22-hour walk at 0.8 s per step)."""
MAX_WINDOW_CELLS = 256
"""Most cells across a footprint or swing-path window (``2 * radius / resolution``): a 25 cm foot reaches it
at 1 mm."""


def check_map_shape(shape, label: str = "shape") -> tuple[int, int]:
    """``(nx, ny)`` as ints after checking: two positive integers whose product is at most :data:`MAX_MAP_CELLS`.

    Raises:
      ValueError: naming ``label``, the value and the bound.
    """
    try:
        nx, ny = shape
        if any(isinstance(v, bool) or int(v) != v for v in (nx, ny)):
            raise ValueError
        nx, ny = int(nx), int(ny)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{label} must be two integers (nx, ny), got {shape!r}") from None
    if nx < 1 or ny < 1:
        raise ValueError(f"{label} must be positive, got {shape!r}")
    if nx * ny > MAX_MAP_CELLS:
        raise ValueError(f"{label} {nx} x {ny} is {nx * ny} cells, above ijoy_jax.limits.MAX_MAP_CELLS = "
                         f"{MAX_MAP_CELLS} (~60 bytes per cell of FootCost tables): use a coarser resolution or a "
                         f"smaller map")
    return nx, ny


def check_num_steps(num_steps, label: str = "num_steps") -> int:
    """``num_steps`` as an int after checking: a positive integer at most :data:`MAX_NUM_STEPS`.

    Raises:
      ValueError: naming ``label``, the value and the bound.
    """
    try:
        if isinstance(num_steps, bool):
            raise TypeError
        n = operator.index(num_steps)  # an int or a NumPy integer; a float such as 3.0 is refused
    except TypeError:
        raise ValueError(f"{label} must be a positive int, got {num_steps!r}") from None
    if n < 1:
        raise ValueError(f"{label} must be a positive int, got {num_steps!r}")
    if n > MAX_NUM_STEPS:
        raise ValueError(f"{label} = {n} is above ijoy_jax.limits.MAX_NUM_STEPS = {MAX_NUM_STEPS} (the trajectory "
                         f"holds every step): split the walk into rollouts")
    return n


def window_cells(radius: float, resolution: float) -> int:
    """Columns (and rows) a window needs to hold any shape of half-diagonal ``radius`` (m) at ``resolution`` (m)."""
    return int(math.ceil(2.0 * radius / resolution - 1e-9)) + 1


def check_window(radius: float, resolution: float, what: str) -> int:
    """Cells across a window that holds any shape of half-diagonal ``radius`` (m) on a grid of ``resolution``
    (m), after checking it is at most :data:`MAX_WINDOW_CELLS` (static values: raised at trace time too).

    Raises:
      ValueError: naming ``what`` (e.g. "footprint"), the resolution and the bound.
    """
    try:
        cells = window_cells(radius, resolution) if resolution > 0 else math.inf
    except OverflowError:  # a denormal resolution: beyond any count
        cells = math.inf
    if not cells <= MAX_WINDOW_CELLS:
        finest = 2.0 * radius / (MAX_WINDOW_CELLS - 1)
        raise ValueError(f"at resolution {resolution!r} m the robot's {what} window is {cells} cells across, above "
                         f"ijoy_jax.limits.MAX_WINDOW_CELLS = {MAX_WINDOW_CELLS}: use a map of at least "
                         f"{finest:.2g} m per cell")
    return int(cells)

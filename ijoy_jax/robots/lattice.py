"""Action sets on lattices: evenly spaced actions over ranges, and the lattice of the paper's target set F.

Host NumPy in float64: an action set and its target lattice are built before any device array exists, and the
lattice's ``(lo, step, counts)`` is static metadata of the :class:`~ijoy_jax.robots.Robot`.
"""

from __future__ import annotations

import math

import numpy as np


def target_lattice(actions, refine: int = 2) -> tuple[tuple, tuple, tuple]:
    """Lattice ``(lo, step, counts)`` (3-tuples) of the paper's target set F for an action set.

    Spans the bounding box of the actions extended by one action spacing on
    each side, with ``refine`` points per action spacing along each axis
    (spacing = smallest gap between distinct values of that coordinate).
    """
    acts = np.asarray(actions, np.float64)
    lo, step, counts = [], [], []
    for k in range(3):
        vals = np.unique(np.round(acts[:, k], 7))
        spacing = float(np.min(np.diff(vals))) if len(vals) > 1 else (0.05 if k < 2 else math.radians(5.0))
        lo.append(float(vals[0]) - spacing)
        step.append(spacing / refine)
        counts.append(2 * refine + refine * int(round((vals[-1] - vals[0]) / spacing)) + 1)
    return tuple(lo), tuple(step), tuple(counts)


def lattice_actions(
    counts: tuple[int, int, int],
    dx_range=(-0.20, 0.20),
    dy_range=(0.19, 0.33),
    dtheta_range=(-math.radians(20.0), math.radians(20.0)),
    drop_corners: bool = True,
) -> np.ndarray:
    """A lattice of actions: ``counts = (n_dx, n_dy, n_dtheta)`` evenly spaced values per range.

    With ``drop_corners`` the 8 corners of the (dx, dy, dtheta) box (largest
    step, extreme width and extreme rotation all at once) are left out: they
    lie outside a leg's reach. Ordered by dx, then dy, then dtheta.

    Returns:
      (M, 3) float64 array, M = n_dx n_dy n_dtheta (- 8 with drop_corners).
    """
    axes = [
        np.linspace(lo, hi, n) if n > 1 else np.array([0.5 * (lo + hi)])
        for (lo, hi), n in zip((dx_range, dy_range, dtheta_range), counts, strict=True)
    ]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    if drop_corners and min(counts) > 1:
        corner = np.ones(len(grid), bool)
        for k, ax in enumerate(axes):
            corner &= np.isclose(grid[:, k], ax[0]) | np.isclose(grid[:, k], ax[-1])
        grid = grid[~corner]
    return grid

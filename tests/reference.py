"""Independent NumPy (float64) references for the tests: brute force, no JAX."""

from __future__ import annotations

import numpy as np


def rect_corners(cx, cy, theta, hl, hw):
    c, s = np.cos(theta), np.sin(theta)
    lx = np.array([1, -1, -1, 1]) * hl
    ly = np.array([1, 1, -1, -1]) * hw
    return np.stack([cx + c * lx - s * ly, cy + s * lx + c * ly], -1)


def rect_touches_cells(cx, cy, theta, hl, hw, res, shape, origin=(0.0, 0.0)):
    """(nx, ny) bool: cells whose interior overlaps the rectangle's (separating-axis test).

    Brute force over every cell of the grid, float64; open intervals, so
    touching edges or corners do not count.
    """
    nx, ny = shape
    xl = origin[0] + np.arange(nx)[:, None] * res + np.zeros((1, ny))
    yl = origin[1] + np.arange(ny)[None, :] * res + np.zeros((nx, 1))
    xh, yh = xl + res, yl + res
    P = rect_corners(cx, cy, theta, hl, hw)
    sep = (xh <= P[:, 0].min()) | (xl >= P[:, 0].max()) | (yh <= P[:, 1].min()) | (yl >= P[:, 1].max())
    for ax in (np.array([np.cos(theta), np.sin(theta)]), np.array([-np.sin(theta), np.cos(theta)])):
        proj = P @ ax
        cell = np.stack([xl * ax[0] + yl * ax[1], xh * ax[0] + yl * ax[1], xl * ax[0] + yh * ax[1],
                         xh * ax[0] + yh * ax[1]])
        sep |= (cell.max(0) <= proj.min()) | (cell.min(0) >= proj.max())
    return ~sep


def disc_touches_cells(x, y, r, res, shape, origin=(0.0, 0.0)):
    nx, ny = shape
    xl = origin[0] + np.arange(nx)[:, None] * res
    yl = origin[1] + np.arange(ny)[None, :] * res
    dx = np.maximum(np.maximum(xl - x, x - xl - res), 0.0)
    dy = np.maximum(np.maximum(yl - y, y - yl - res), 0.0)
    return dx**2 + dy**2 < r * r


def foot_metrics(height, res, origin, pose, foot_length, foot_width, margin):
    """Plane fit and metrics of the footprint at ``pose`` (float64 brute force).

    Returns dict(height, slope, roughness, bump, band, obstacle_cells) where the
    plane is the least-squares fit over the cells the footprint touches.
    """
    shape = height.shape
    foot = rect_touches_cells(pose[0], pose[1], pose[2], foot_length / 2, foot_width / 2, res, shape, origin)
    grown = rect_touches_cells(pose[0], pose[1], pose[2], foot_length / 2 + margin, foot_width / 2 + margin,
                               res, shape, origin)
    ix, iy = np.nonzero(foot)
    u = origin[0] + (ix + 0.5) * res - pose[0]
    v = origin[1] + (iy + 0.5) * res - pose[1]
    h = height[ix, iy].astype(np.float64)
    A = np.stack([np.ones_like(u), u, v], 1)
    coef, *_ = np.linalg.lstsq(A, h, rcond=None)
    resid = h - A @ coef
    bx, by = np.nonzero(grown & ~foot)
    bu = origin[0] + (bx + 0.5) * res - pose[0]
    bv = origin[1] + (by + 0.5) * res - pose[1]
    bres = height[bx, by] - (coef[0] + coef[1] * bu + coef[2] * bv)
    return dict(
        height=coef[0],
        slope=np.arctan(np.hypot(coef[1], coef[2])),
        roughness=np.mean(np.abs(resid)),
        bump=max(resid.max(), 0.0),
        band=np.abs(bres).max() if bres.size else 0.0,
    )


def enable_x64():
    """Context manager turning on float64 in JAX (its home moved between jax versions)."""
    import jax

    if hasattr(jax, "enable_x64"):
        return jax.enable_x64(True)
    from jax.experimental import enable_x64 as ctx  # jax < 0.10

    return ctx()

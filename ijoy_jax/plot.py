"""Matplotlib drawings of terrains and footsteps (imported lazily by callers)."""

from __future__ import annotations

import numpy as np

from ijoy_jax.terrain import Terrain


def footprint_polygon(pose, length: float, width: float) -> np.ndarray:
    """(4, 2) corners of a footprint at world pose (x, y, theta), metres."""
    x, y, t = (float(v) for v in pose)
    c, s = np.cos(t), np.sin(t)
    lx = np.array([1, -1, -1, 1]) * length / 2
    ly = np.array([1, 1, -1, -1]) * width / 2
    return np.stack([x + c * lx - s * ly, y + s * lx + c * ly], -1)


def draw_terrain(ax, terrain: Terrain) -> None:
    """Draw a terrain on a matplotlib axis: heights as shading, obstacles in dark grey."""
    t = terrain.to_numpy()
    nx, ny = t["free"].shape
    r = t["resolution"]
    ox, oy = t["origin"]
    extent = (ox, ox + nx * r, oy, oy + ny * r)
    if t["has_height"]:
        im = ax.imshow(t["height"].T, origin="lower", extent=extent, cmap="Greens", interpolation="nearest")
        ax.figure.colorbar(im, ax=ax, label="height (m)", shrink=0.8)
    obstacles = np.ma.masked_where(t["free"].T, np.ones((ny, nx)))
    ax.imshow(obstacles, origin="lower", extent=extent, cmap="Greys", vmin=0, vmax=1.4, interpolation="nearest")
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def draw_footsteps(ax, footsteps, sides, length: float, width: float, *, mask=None, bad=None, style=None,
                   label=None) -> None:
    """Draw footprints: left feet blue, right feet red; ``bad`` (bool per step) drawn with a black X."""
    from matplotlib.patches import Polygon

    footsteps = np.asarray(footsteps)
    sides = np.asarray(sides)
    mask = np.ones(len(footsteps), bool) if mask is None else np.asarray(mask)
    style = dict(fill=False, lw=1.5) if style is None else style
    first = True
    for k, (pose, side) in enumerate(zip(footsteps, sides, strict=True)):
        if not mask[k]:
            continue
        colour = "tab:blue" if side > 0 else "tab:red"
        poly = Polygon(footprint_polygon(pose, length, width), edgecolor=colour, label=label if first else None,
                       **style)
        ax.add_patch(poly)
        first = False
        if bad is not None and bad[k]:
            ax.plot(pose[0], pose[1], "kx", ms=8, mew=2)

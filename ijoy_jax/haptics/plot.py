"""Drawings of linearised workspaces (the paper's Figs. 8-9) and of the platform's workspace.

Host-side NumPy and matplotlib (imported lazily); nothing here is traced.
"""

from __future__ import annotations

import itertools

import numpy as np

from ijoy_jax.extras import require

require("plot", "matplotlib", what="ijoy_jax.haptics.plot")

_PAIR_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink")


def zonotope_points(jacobian, travel_minus, travel_plus) -> np.ndarray:
    """(2^k, 3) all sums of one generator of each pair: the paper's 16 points for k = 4 (m)."""
    jac = np.asarray(jacobian, float)
    tm, tp = np.asarray(travel_minus, float), np.asarray(travel_plus, float)
    k = jac.shape[1]
    choice = np.array(list(itertools.product((0, 1), repeat=k)), bool)  # (2^k, k)
    t = np.where(choice, tp, tm)
    return t @ jac.T


def polytope_vertices(normals, offsets, tol: float = 1e-7) -> np.ndarray:
    """(V, 3) vertices of the bounded polytope ``{x : normals @ x <= offsets}``, brute force.

    Every triple of planes is intersected and the feasible points kept (fine for
    the few dozen planes of a platform workspace). Metres in, metres out.
    """
    a = np.asarray(normals, float)
    b = np.asarray(offsets, float)
    idx = np.array(list(itertools.combinations(range(len(a)), 3)))
    if len(idx) == 0:
        return np.zeros((0, 3))
    mats = a[idx]  # (T, 3, 3)
    det = np.linalg.det(mats)
    ok = np.abs(det) > 1e-12
    pts = np.linalg.solve(mats[ok], b[idx[ok]][..., None])[..., 0]
    scale = 1.0 + np.max(np.abs(b))
    feasible = np.all(pts @ a.T <= b + tol * scale, axis=1)
    pts = pts[feasible]
    if len(pts) == 0:
        return pts
    keep = np.unique(np.round(pts / (tol * scale * 10)), axis=0, return_index=True)[1]
    return pts[np.sort(keep)]


def facet_polygons(normals, offsets, points, tol: float = 1e-5) -> list[np.ndarray]:
    """For each plane (row of ``normals``, ``offsets``), the points on it as an ordered polygon (m, 3)."""
    pts = np.asarray(points, float)
    scale = 1.0 + np.max(np.abs(pts)) if len(pts) else 1.0
    polys = []
    for n, d in zip(np.asarray(normals, float), np.asarray(offsets, float), strict=True):
        on = pts[np.abs(pts @ n - d) <= tol * scale]
        if len(on) < 3:
            continue
        c = on.mean(axis=0)
        u = on[np.argmax(np.linalg.norm(on - c, axis=1))] - c
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        ang = np.arctan2((on - c) @ v, (on - c) @ u)
        polys.append(on[np.argsort(ang)])
    return polys


def _set_equal(ax, pts):
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    mid, half = (lo + hi) / 2, max(np.max(hi - lo) / 2, 1e-6)
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_box_aspect((1, 1, 1))


def _axes3d(ax):
    if ax is None:
        import matplotlib.pyplot as plt

        ax = plt.figure(figsize=(6, 6)).add_subplot(projection="3d")
    return ax


def plot_leg_workspace(
    jacobian,
    travel_minus,
    travel_plus,
    force=None,
    *,
    ax=None,
    scale: float = 1.0,
    force_scale: float | None = None,
    title: str | None = None,
    show_facets: bool = True,
    show_generators: bool = True,
):
    """Draw a linearised workspace: its facets, the generator pairs and the repulsive force.

    Like the paper's Figs. 8-9: the zonotope (scaled by ``scale`` about the
    end-effector, Fig. 9 uses 0.5), one arrow pair ``e_i^-, e_i^+`` per cylinder
    from the end-effector, and the force as a red arrow.

    Args:
      jacobian: (3, k); travel_minus, travel_plus: (k,) (see :mod:`~ijoy_jax.haptics.workspace`).
      force: optional (3,) force (N) to draw from the end-effector.
      ax: a 3D matplotlib axes; a new figure if None.
      scale: scale of the drawn zonotope and generators.
      force_scale: metres per newton for the force arrow (default: half the
        longest generator per unit of the force's magnitude).
      title: axes title (default: the number of planes and the scale).
      show_facets: draw the zonotope's facets (Fig. 9).
      show_generators: draw the generator pairs (Fig. 8).

    Returns:
      The matplotlib 3D axes.

    Example:
      >>> import matplotlib; matplotlib.use("Agg")
      >>> from ijoy_jax.haptics.leg import PAPER_Q, alduro_leg, leg_workspace
      >>> ws = leg_workspace(alduro_leg(-1.0), jnp.array(PAPER_Q))  # doctest: +SKIP
      >>> ax = plot_leg_workspace(ws.jacobian, ws.travel_minus, ws.travel_plus)  # doctest: +SKIP
    """
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from ijoy_jax.haptics.workspace import limiting_planes

    jac = np.asarray(jacobian, float)
    tm, tp = np.asarray(travel_minus, float), np.asarray(travel_plus, float)
    planes = limiting_planes(jac, tm, tp)
    valid = np.asarray(planes.valid)
    normals, offsets = np.asarray(planes.normals)[valid], np.asarray(planes.offsets)[valid]
    pts = zonotope_points(jac, tm, tp)
    polys = [scale * p for p in facet_polygons(normals, offsets, pts)]
    ax = _axes3d(ax)
    if show_facets:
        ax.add_collection3d(Poly3DCollection(polys, facecolor="tab:cyan", edgecolor="k", alpha=0.25, linewidths=0.6))
    e_minus, e_plus = tm[:, None] * jac.T * scale, tp[:, None] * jac.T * scale
    for i in range(jac.shape[1] if show_generators else 0):
        col = _PAIR_COLOURS[i % len(_PAIR_COLOURS)]
        for e, style in ((e_minus[i], "--"), (e_plus[i], "-")):
            ax.plot([0, e[0]], [0, e[1]], [0, e[2]], style, color=col, lw=2)
        ax.text(*(e_plus[i] * 1.08), f"e{i + 1}+", color=col)
        ax.text(*(e_minus[i] * 1.08), f"e{i + 1}-", color=col)
    shown = [scale * pts, np.zeros((1, 3))]
    if force is not None:
        f = np.asarray(force, float)
        fn = np.linalg.norm(f)
        if force_scale is None:
            longest = max(np.max(np.linalg.norm(e_plus, axis=1)), np.max(np.linalg.norm(e_minus, axis=1)))
            force_scale = 0.5 * longest / fn if fn > 0 else 0.0
        tip = f * force_scale
        ax.quiver(0, 0, 0, *tip, color="red", lw=2.5, arrow_length_ratio=0.15)
        ax.text(*(tip * 1.1), "f", color="red")
        shown.append(tip[None])
    ax.scatter([0], [0], [0], color="k", s=15)
    ax.set_xlabel("dx (m)")
    ax.set_ylabel("dy (m)")
    ax.set_zlabel("dz (m)")
    _set_equal(ax, np.concatenate(shown))
    ax.set_title(title or f"linearised workspace: {len(normals)} planes (scale {scale:g})")
    return ax


def plot_platform_workspace(
    platform_ws, force=None, *, ax=None, force_scale: float | None = None, title: str | None = None
):
    """Draw the platform centre's translation workspace (intersection of the legs' flipped workspaces).

    Args:
      platform_ws: a :class:`~ijoy_jax.haptics.platform.PlatformWorkspace`.
      force: optional (3,) platform repulsive force (N).
      ax: 3D matplotlib axes or None.
      force_scale: metres per newton (default: half the workspace's extent per unit force).

    Returns:
      The matplotlib 3D axes.
    """
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from ijoy_jax.haptics.platform import translation_halfspaces

    a, b = translation_halfspaces(platform_ws)
    # Legs in the same pose share planes: keep one row per distinct plane.
    keep = np.unique(np.round(np.hstack([a, b[:, None]]), 6), axis=0, return_index=True)[1]
    a, b = a[np.sort(keep)], b[np.sort(keep)]
    verts = polytope_vertices(a, b)
    polys = facet_polygons(a, b, verts)
    ax = _axes3d(ax)
    ax.add_collection3d(Poly3DCollection(polys, facecolor="tab:olive", edgecolor="k", alpha=0.3, linewidths=0.6))
    ax.scatter([0], [0], [0], color="k", s=15)
    shown = [verts, np.zeros((1, 3))]
    if force is not None:
        f = np.asarray(force, float)
        fn = np.linalg.norm(f)
        if force_scale is None:
            extent = np.max(verts.max(axis=0) - verts.min(axis=0)) if len(verts) else 1.0
            force_scale = 0.5 * extent / fn if fn > 0 else 0.0
        tip = f * force_scale
        ax.quiver(0, 0, 0, *tip, color="red", lw=2.5, arrow_length_ratio=0.15)
        shown.append(tip[None])
    ax.set_xlabel("platform dx (m)")
    ax.set_ylabel("platform dy (m)")
    ax.set_zlabel("platform dz (m)")
    _set_equal(ax, np.concatenate(shown))
    ax.set_title(title or f"platform translation workspace: {len(polys)} facets")
    return ax

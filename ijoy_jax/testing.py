"""Independent NumPy references (float64, brute force, no JAX): what the tests compare the library against.

Written apart from the JAX code: cell coverage by separating-axis tests (:func:`rect_touches_cells` over the
whole grid, :class:`NumpyFootCost` over a bounding box), planes by ``numpy.linalg.lstsq`` (:func:`foot_metrics`),
the rested sole by every triple of its contact points and its contact polygon by its support function
(:func:`rested_sole`),
a sole's orientation on a plane from its normal and heading (:func:`sole_frame`, :func:`sole_rpy`,
:func:`foothold`), the paper's ordered list walked one action at a time with its stopping rule
(:func:`ordered_select`). The
NumPy FootCost and search are also the baseline the benchmarks report their speed-up over.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from ijoy_jax.footcost.xla import LIMIT_TOL


def _touched(x, y, th, hl, hw, res, origin, shape):
    """Cells (ix, iy arrays) whose interior a rotated rectangle overlaps, and whether it leaves the map."""
    c, s = math.cos(th), math.sin(th)
    P = np.array([[x + c * a * hl - s * b * hw, y + s * a * hl + c * b * hw]
                  for a, b in ((1, 1), (-1, 1), (-1, -1), (1, -1))])
    lo = np.floor((P.min(0) - origin) / res).astype(int)
    hi = np.ceil((P.max(0) - origin) / res).astype(int) - 1
    ix, iy = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
    ix, iy = ix.ravel(), iy.ravel()
    xl, yl = origin[0] + ix * res, origin[1] + iy * res
    xh, yh = xl + res, yl + res
    sep = (xh <= P[:, 0].min()) | (xl >= P[:, 0].max()) | (yh <= P[:, 1].min()) | (yl >= P[:, 1].max())
    for ax in ((c, s), (-s, c)):
        proj = P @ np.array(ax)
        corners = np.stack([xl * ax[0] + yl * ax[1], xh * ax[0] + yl * ax[1],
                            xl * ax[0] + yh * ax[1], xh * ax[0] + yh * ax[1]])
        sep |= (corners.max(0) <= proj.min()) | (corners.min(0) >= proj.max())
    ix, iy = ix[~sep], iy[~sep]
    off = (ix < 0) | (iy < 0) | (ix >= shape[0]) | (iy >= shape[1])
    return ix[~off], iy[~off], bool(off.any())


class NumpyFootCost:
    """FootCost of one candidate at a time, from NumPy copies of a terrain and robot."""

    def __init__(self, terrain, robot):
        t = terrain.to_numpy()
        self.height = t["height"].astype(np.float64)
        self.free = t["free"]
        self.res = t["resolution"]
        self.origin = t["origin"].astype(np.float64)
        self.has_height = t["has_height"]
        g = lambda v: np.asarray(v, np.float64)  # noqa: E731
        self.L, self.W, self.m = float(robot.foot_length), float(robot.foot_width), float(robot.margin)
        self.p0 = g(robot.p0)
        self.dt = float(robot.step_time)
        self.actions = g(robot.actions)
        self.action_cost = g(robot.action_cost)
        self.clearance = g(robot.clearance)
        self.max_dh = g(robot.max_step_height)
        self.max_pitch, self.max_roll = float(robot.max_sole_pitch), float(robot.max_sole_roll)
        self.max_distance = float(robot.max_sole_distance)
        self.w, self.rw = float(robot.w), float(robot.rotation_weight)
        self.metrics = {k: float(v) for k, v in vars(robot.metrics).items()}

    def plane(self, pose):
        """(rested height at the centre, slope, roughness, bump, band, support, rested (dz/dx, dz/dy)) of the
        footprint at ``pose``: the least-squares plane's metrics and the rested sole's (:func:`rest_metrics`)."""
        args = (self.res, self.origin, self.height.shape)
        fx, fy, _ = _touched(pose[0], pose[1], pose[2], self.L / 2, self.W / 2, *args)
        gx, gy, _ = _touched(pose[0], pose[1], pose[2], self.L / 2 + self.m, self.W / 2 + self.m, *args)
        u = self.origin[0] + (fx + 0.5) * self.res - pose[0]
        v = self.origin[1] + (fy + 0.5) * self.res - pose[1]
        h = self.height[fx, fy]
        A = np.stack([np.ones_like(u), u, v], 1)
        coef = np.linalg.lstsq(A, h, rcond=None)[0]
        r = h - A @ coef
        foot = set(zip(fx.tolist(), fy.tolist(), strict=True))
        band = [(a, b) for a, b in zip(gx.tolist(), gy.tolist(), strict=True) if (a, b) not in foot]
        band_dev = 0.0
        if band:
            bx, by = np.array(band).T
            bu = self.origin[0] + (bx + 0.5) * self.res - pose[0]
            bv = self.origin[1] + (by + 0.5) * self.res - pose[1]
            band_dev = float(np.abs(self.height[bx, by] - coef[0] - coef[1] * bu - coef[2] * bv).max())
        slope = math.atan(math.hypot(coef[1], coef[2]))
        rest = rest_metrics(self.height, self.res, self.origin, pose, self.L, self.W, self.metrics["contact_inset"],
                            self.metrics["contact_tol"])
        return (rest["height"], slope, float(np.abs(r).mean()), max(float(r.max()), 0.0), band_dev,
                rest["support"], rest["grad"])

    def cost(self, stance, stance_h, start_h, swing_from, pose, a):
        """FootCost of the swing foot at ``pose`` executing action ``a`` from ``stance`` (+inf if invalid)."""
        gx, gy, off = _touched(pose[0], pose[1], pose[2], self.L / 2 + self.m, self.W / 2 + self.m,
                               self.res, self.origin, self.free.shape)
        if off or not self.free[gx, gy].all():
            return math.inf
        total = self.action_cost[a]
        reach = math.hypot(pose[0] - stance[0], pose[1] - stance[1])
        if not self.has_height:
            return total if reach <= self.max_distance + LIMIT_TOL else math.inf
        m = self.metrics
        hgt, slope, rough, bump, band, support, grad = self.plane(pose)
        roll, pitch, _ = sole_rpy(*grad, pose[2])
        for val, lim in ((abs(pitch), self.max_pitch), (abs(roll), self.max_roll),
                         (math.hypot(reach, hgt - stance_h), self.max_distance)):
            if val > lim + LIMIT_TOL:
                return math.inf
        for val, wt, lim in ((slope, m["slope_weight"], m["slope_limit"]),
                             (rough, m["roughness_weight"], m["roughness_limit"]),
                             (bump, m["bump_weight"], m["bump_limit"]),
                             (abs(hgt - stance_h), m["step_weight"], self.max_dh[a]),
                             (band, m["band_weight"], m["band_limit"]),
                             (support, m["support_weight"], m["support_limit"])):
            if val > lim + LIMIT_TOL:  # the library's one rule for limits (footcost.xla.exceeds)
                return math.inf
            total += wt * val
        if swing_from is not None:
            d = np.hypot(pose[0] - swing_from[0], pose[1] - swing_from[1])
            th = math.atan2(pose[1] - swing_from[1], pose[0] - swing_from[0]) if d > 0 else 0.0
            cx, cy, off = _touched(0.5 * (pose[0] + swing_from[0]), 0.5 * (pose[1] + swing_from[1]), th, d / 2,
                                   self.W / 2, self.res, self.origin, self.free.shape)
            if off:
                return math.inf
            if cx.size and self.height[cx, cy].max() - max(start_h, hgt) > self.clearance[a] + LIMIT_TOL:
                return math.inf
        return total


def _compose(base, rel):
    c, s = math.cos(base[2]), math.sin(base[2])
    return np.array([base[0] + c * rel[0] - s * rel[1], base[1] + s * rel[0] + c * rel[1], base[2] + rel[2]])


def ordered_select(fc: NumpyFootCost, targets, stance, stance_side, command, swing_from=None):
    """The paper's search in NumPy: (index, cost, evaluated); index -1 if no valid step.

    ``targets`` is a :class:`ijoy_jax.select.Targets` (its lattice and L_i
    are reused; the walk itself is plain Python).
    """
    swing = -1.0 if stance_side > 0 else 1.0
    mirror = np.array([1.0, swing, swing])
    command = np.asarray(command, np.float64)
    if not np.all(np.isfinite(command)):
        command = np.zeros(3)
    p_next = fc.p0 * mirror + fc.dt * command
    left = p_next * mirror
    idx = [int(np.clip(np.round((left[k] - targets.lo[k]) / targets.step[k]), 0, targets.counts[k] - 1))
           for k in range(3)]
    fi = (idx[0] * targets.counts[1] + idx[1]) * targets.counts[2] + idx[2]
    order = np.asarray(targets.order[fi])
    dist = np.asarray(targets.dist[fi], np.float64)
    stance = np.asarray(stance, np.float64)
    stance_h = start_h = 0.0
    if fc.has_height:
        stance_h = fc.plane(stance)[0]
        if swing_from is not None:
            start_h = fc.plane(swing_from)[0]
    best, best_cost, n = -1, math.inf, len(order)
    for j, a in enumerate(order):
        pose = _compose(stance, fc.actions[a] * mirror)
        c = fc.cost(stance, stance_h, start_h, swing_from, pose, a) + fc.w * dist[a]
        if c < best_cost:
            best, best_cost = int(a), c
        if j + 1 < n and best_cost <= fc.w * dist[order[j + 1]]:
            return best, best_cost, j + 1
    return best, best_cost, n


def _level_dists(fc: NumpyFootCost, targets, stance_side, command):
    """(N,) dist of every action to the quantised target f_i of a step from a stance on ``stance_side``."""
    swing = -1.0 if stance_side > 0 else 1.0
    mirror = np.array([1.0, swing, swing])
    command = np.asarray(command, np.float64)
    if not np.all(np.isfinite(command)):
        command = np.zeros(3)
    left = (fc.p0 * mirror + fc.dt * command) * mirror
    idx = [int(np.clip(np.round((left[k] - targets.lo[k]) / targets.step[k]), 0, targets.counts[k] - 1))
           for k in range(3)]
    return np.asarray(targets.dist[(idx[0] * targets.counts[1] + idx[1]) * targets.counts[2] + idx[2]], np.float64)


def lookahead_values(fc: NumpyFootCost, targets, stance, stance_side, command, swing_from=None, horizon=2,
                     discount=1.0):
    """Brute force over all N^horizon sequences: ``(V (N,), c1 (N,), d1 (N,))`` for each first action.

    ``V[a] = c_1(a) + discount * min over the rest`` (+inf when step 1 is invalid or no valid continuation
    exists), each step's cost ``FootCost + w * dist`` to its quantised target f_i, feet alternating, each
    level's swing foot starting where it stood (:mod:`ijoy_jax.lookahead`'s definition, evaluated by
    enumeration in float64: every sequence's FootCosts are computed, nothing is pruned).
    """
    dists = {s: _level_dists(fc, targets, s, command) for s in (1.0, -1.0)}
    path = swing_from is not None

    def height(pose):
        return fc.plane(pose)[0] if fc.has_height else 0.0

    def costs(stance, side, start):
        mirror = np.array([1.0, -side, -side])
        sh, st = height(stance), (height(start) if path else 0.0)
        out = np.empty(len(fc.actions))
        poses = []
        for a, act in enumerate(fc.actions):
            pose = _compose(stance, act * mirror)
            poses.append(pose)
            out[a] = fc.cost(stance, sh, st, start if path else None, pose, a) + fc.w * dists[side][a]
        return out, poses

    def value(level, stance, side, start):
        c, poses = costs(stance, side, start)
        if level == horizon:
            return float(c.min())
        best = math.inf
        for a in np.flatnonzero(np.isfinite(c)):
            tail = value(level + 1, poses[a], -side, stance)
            if math.isfinite(tail):
                best = min(best, c[a] + discount * tail)
        return best

    side = 1.0 if stance_side > 0 else -1.0
    stance = np.asarray(stance, np.float64)
    start = None if swing_from is None else np.asarray(swing_from, np.float64)
    c1, poses = costs(stance, side, start)
    v = np.full(len(c1), math.inf)
    if horizon == 1:
        v = c1.copy()
    else:
        for a in np.flatnonzero(np.isfinite(c1)):
            tail = value(2, poses[a], -side, stance)
            if math.isfinite(tail):
                v[a] = c1[a] + discount * tail
    return v, c1, dists[side]


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


def ground_under_points(height, res, origin, pose, foot_length, foot_width, inset):
    """(6,) the ground (m) under a sole's contact points at ``pose``: toe, middle and heel of its left edge, then of
    its right edge, ``inset`` in from the edges, interpolated bilinearly between cell centres (indices clamped to
    the map: its edge extended). Returns (points (6, 2) in the sole's frame, heights (6,))."""
    nx, ny = height.shape
    c, s = math.cos(pose[2]), math.sin(pose[2])
    points, ground = [], []
    for across in (0.5 * foot_width - inset, inset - 0.5 * foot_width):
        for along in (0.5 * foot_length - inset, 0.0, inset - 0.5 * foot_length):
            du, dv = along * c - across * s, along * s + across * c
            gx = (pose[0] + du - origin[0]) / res - 0.5
            gy = (pose[1] + dv - origin[1]) / res - 0.5
            i, j = math.floor(gx), math.floor(gy)
            tx, ty = gx - i, gy - j
            cell = lambda a, b: float(height[min(max(a, 0), nx - 1), min(max(b, 0), ny - 1)])  # noqa: E731
            ground.append((1 - tx) * ((1 - ty) * cell(i, j) + ty * cell(i, j + 1))
                          + tx * ((1 - ty) * cell(i + 1, j) + ty * cell(i + 1, j + 1)))
            points.append((along, across))
    return np.array(points), np.array(ground)


def lowest_planes(points, ground, tie=1e-9):
    """(K, 3) every plane (height at the centre, gradient along, across) through three of the points ``points``
    (P, 2) (sole frame, m) that lies above the ground ``ground`` (P,) at every point and lowest at the centre,
    within ``tie`` (m): a float64 loop over the triples. More than one gradient: the lowest planes turn about an
    edge through the centre."""
    planes = []
    for t in itertools.combinations(range(len(points)), 3):
        m = np.column_stack([np.ones(3), points[list(t)]])
        if abs(np.linalg.det(m)) < 1e-12:
            continue
        coef = np.linalg.solve(m, ground[list(t)])
        if np.all(coef[0] + points @ coef[1:] >= ground - 1e-12):
            planes.append(coef)
    planes = np.array(planes)
    return planes[planes[:, 0] <= planes[:, 0].min() + tie]


def rested_sole(points, ground, tol):
    """A rigid sole resting on the ground ``ground`` (P,) under its points ``points`` (P, 2) (sole frame, m), by
    brute force in float64: every triple's plane, kept where it lies above every point; the rest is the one
    lowest at the centre (where several are, the middle of their gradients' range). Its contact polygon (the
    points within ``tol`` of it) is measured by its support function: the distance from the centre to the
    polygon's nearest edge is ``min over unit n of max over contacts k of n . p_k``, taken over the normals of
    every pair of contacts (negative outside; minus the distance to the line for collinear contacts).

    Returns dict(height, grad_along, grad_across, margin, contacts, gaps ((P,) m: the sole above each point's
    ground))."""
    lowest = lowest_planes(points, ground)
    # several lowest planes turn about an edge through the centre: the middle of their range
    best = np.array([lowest[0, 0], *(0.5 * (lowest[:, 1:].min(axis=0) + lowest[:, 1:].max(axis=0)))])
    gaps = best[0] + points @ best[1:] - ground
    contact = points[gaps <= tol + 1e-9]
    # the support function max_k n . p_k is piecewise linear in n's heading, lowest at an edge's normal: its
    # minimum over every pair's two normals (a superset of the edges') is the exact distance
    normals = [np.array([-e[1], e[0]]) / np.hypot(*e) * sign for i, j in itertools.combinations(range(len(contact)), 2)
               if np.hypot(*(e := contact[j] - contact[i])) > 1e-12 for sign in (1.0, -1.0)]
    margin = (float(min(np.max(contact @ n) for n in normals)) if normals
              else -float(np.hypot(*contact[0])) if len(contact) else -np.inf)
    return dict(height=float(best[0]), grad_along=float(best[1]), grad_across=float(best[2]), margin=margin,
                contacts=int(len(contact)), gaps=gaps)


def rest_metrics(height, res, origin, pose, foot_length, foot_width, inset, tol):
    """The rested sole at ``pose`` on a height map (float64 brute force): dict(height (m, at the centre),
    grad (dz/dx, dz/dy in world axes), support (the whole sole's margin less the contact polygon's, m), margin,
    contacts, gaps)."""
    pts, ground = ground_under_points(height, res, origin, pose, foot_length, foot_width, inset)
    r = rested_sole(pts, ground, tol)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    grad = (r["grad_along"] * c - r["grad_across"] * s, r["grad_along"] * s + r["grad_across"] * c)
    full = min(foot_length, foot_width) / 2 - inset
    return dict(height=r["height"], grad=grad, support=max(full - r["margin"], 0.0), margin=r["margin"],
                contacts=r["contacts"], gaps=r["gaps"])


def foot_metrics(height, res, origin, pose, foot_length, foot_width, margin, *, contact_inset=0.009,
                 contact_tol=0.003):
    """Plane fit, metrics and rested sole of the footprint at ``pose`` (float64 brute force).

    Returns dict(height, slope, roughness, bump, band, grad, rest) where the plane is the least-squares fit
    over the cells the footprint touches and ``rest`` is :func:`rest_metrics` (``contact_inset`` and
    ``contact_tol``, m: the defaults of :func:`ijoy_jax.robots.default_metrics`).
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
        grad=(coef[1], coef[2]),
        rest=rest_metrics(height.astype(np.float64), res, origin, pose, foot_length, foot_width, contact_inset,
                          contact_tol),
    )


def sole_frame(grad_x, grad_y, yaw):
    """(3, 3) axes (columns x, y, z) of a sole lying on the plane ``z = grad_x x + grad_y y`` (m/m) heading ``yaw``.

    Built from the plane, not from angles: x is the plane's point one metre ahead along the heading's horizontal
    direction (normalised), z the plane's upward unit normal, y = z cross x.
    """
    ahead = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    ahead[2] = grad_x * ahead[0] + grad_y * ahead[1]  # the plane's rise over that horizontal metre
    x = ahead / np.linalg.norm(ahead)
    z = np.array([-grad_x, -grad_y, 1.0])
    z /= np.linalg.norm(z)
    return np.stack([x, np.cross(z, x), z], 1)


def sole_rpy(grad_x, grad_y, yaw):
    """(roll, pitch, yaw) of :func:`sole_frame` read off as ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (float64, rad)."""
    r = sole_frame(grad_x, grad_y, yaw)
    return math.atan2(r[2, 1], r[2, 2]), -math.asin(r[2, 0]), math.atan2(r[1, 0], r[0, 0])


def foothold(height, res, origin, pose, foot_length, foot_width, contact_inset=0.009, contact_tol=0.003):
    """(6,) the full sole pose (x, y, z, roll, pitch, yaw) at ``pose`` on a height map (float64 brute force):
    the rested sole's (:func:`rest_metrics`) height at the foot centre, roll and pitch those of
    :func:`sole_rpy` on its plane."""
    ref = rest_metrics(np.asarray(height, np.float64), res, origin, pose, foot_length, foot_width, contact_inset,
                       contact_tol)
    roll, pitch, _ = sole_rpy(*ref["grad"], pose[2])
    return np.array([pose[0], pose[1], ref["height"], roll, pitch, pose[2]])


def enable_x64():
    """Context manager turning on float64 in JAX (its home moved between jax versions)."""
    import jax

    if hasattr(jax, "enable_x64"):
        return jax.enable_x64(True)
    from jax.experimental import enable_x64 as ctx  # jax < 0.10

    return ctx()

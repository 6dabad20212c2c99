"""The paper's experiments (section V.A.1 and V.B) as deterministic rollouts on built terrains.

Every scenario is a built map, a start stance, a command schedule, a safety
margin and a weight w. All 2D scenarios share one map shape and one step count
and run as a single vmapped rollout per method, the 2.5D ones likewise, so the
file compiles five rollouts in all (2D exhaustive / ordered / naive, 2.5D
exhaustive / ordered). Margin and w are the only batched robot leaves, and the
ordered method's target set F and lists L_i (which depend on the action set
alone) are built once for the whole file.

Geometry (HRP-2 preset): foot 0.242 x 0.13 m, dx in [-0.2, 0.2] every 0.05 m,
|dy| in [0.19, 0.33] every 0.02 m, dtheta in +-20 deg every 6.67 deg, p0 =
(0, 0.19, 0), step time 0.8 s. The feet start 0.19 m apart at x = 0.3 m and
the left foot swings first, so without rotation every foothold has an x on
the lattice 0.3 + 0.05 k.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ijoy_jax as ij
from ijoy_jax.control import rollout
from ijoy_jax.testing import rect_touches_cells

RES = 0.02
SHAPE_2D = (200, 100)  # 4 m x 2 m
STEPS_2D = 16
SHAPE_25D = (150, 100)  # 3 m x 2 m
STEPS_25D = 12
HL, HW = 0.121, 0.065  # half foot length and width (m)
L_MAX = 0.20  # largest |dx| of an action (m)
DX_STEP = 0.05  # spacing of dx in the action lattice (m)
ROT_STEP = math.radians(20.0) / 3  # spacing of dtheta in the action lattice (rad)
FORWARD = (0.25, 0.0, 0.0)  # full speed forward: a 0.2 m target step
# Tolerance of "as close as possible" / "just below the limit": the map is
# made of 2 cm cells and footholds lie on a 5 cm lattice.
TOL = RES + DX_STEP
# float32 poses and sums carry ~1e-6 m (rad) of rounding; every geometric
# decision below clears its threshold by at least 1 mm.
EPS = 1e-5
ROT_TOL = 1e-4  # rad: two rotations closer than this are the same lattice rotation
X0 = 0.3  # start x of both feet (m)
LANE_Y = 1.0  # centre line between the feet at the start (m)


def _start(x=X0, y=LANE_Y, theta=0.0):
    """(2, 3) start poses: feet 0.19 m apart about (x, y), facing theta (row 0 left)."""
    ox, oy = -0.095 * math.sin(theta), 0.095 * math.cos(theta)
    return np.array([[x + ox, y + oy, theta], [x - ox, y - oy, theta]], np.float32)


def _free(shape, boxes=(), cylinders=(), cells=()):
    """A 2D map: boxes (x, y, yaw, length, width) and cylinders (x, y, r) rasterised, plus cell blocks.

    ``cells`` holds ``(i0, i1, j0, j1)`` index ranges set to obstacle exactly.
    """
    t = ij.terrain.flat(shape, RES)
    boxes = [list(b) + [0.1] for b in boxes]
    cyl = [list(c) + [0.1] for c in cylinders]
    t = ij.terrain.scene.rasterize(t, boxes=boxes or None, cylinders=cyl or None)
    free = np.array(t.free)
    for i0, i1, j0, j1 in cells:
        free[i0:i1, j0:j1] = False
    return free


@dataclasses.dataclass(frozen=True)
class Scenario:
    """One experiment: a map, a start stance, a (T, 3) command schedule, margin and w, plus notes.

    free: (nx, ny) bool; height: (nx, ny) float32 or None (2D); start: (2, 3) left, right.
    """

    free: np.ndarray
    height: np.ndarray | None
    start: np.ndarray
    commands: np.ndarray
    margin: float
    w: float
    info: dict

    def terrain(self) -> ij.Terrain:
        return ij.terrain.from_arrays(self.height, self.free, RES)


def scenario(free, height=None, start=None, command=FORWARD, margin=0.02, w=1.0, steps=STEPS_2D, **info):
    start = _start() if start is None else start
    commands = np.broadcast_to(np.asarray(command, np.float32), (steps, 3))
    return Scenario(free, height, start, commands, margin, w, info)


# ---------------------------------------------------------------------------------------------
# 2D scenarios
# ---------------------------------------------------------------------------------------------

WALL_XS = (1.31, 1.37, 1.44)  # near face of a wall across the whole map (not cell-aligned)
MARGINS = (0.02, 0.05, 0.10)
WALLS = tuple(f"wall-m{m}-x{xw}" for m in MARGINS for xw in WALL_XS)


def _wall_scenarios():
    out = {}
    for m in MARGINS:
        for xw in WALL_XS:
            free = _free(SHAPE_2D, boxes=[(xw + 0.05, 1.0, 0.0, 0.1, 2.5)])
            out[f"wall-m{m}-x{xw}"] = scenario(free, margin=m, wall_x=xw)
    assert tuple(out) == WALLS
    return out


SIDE_COMMAND = (0.25, 0.175, 0.0)  # forward and left: targets dy = 0.33 (left foot), 0.19 (right foot)
SIDE_Y = 0.4  # the sidestepping scenarios start low on the map
ANGLE = math.radians(30.0)
# Walls to sidestep along are thicker than anything a foot can step over
# (b_max < 0.12 m) or straddle (0.33 - 0.13 = 0.2 m between the feet).
THICK = 0.3


def _sidestep_scenarios():
    # A straight wall at 30 deg to the y axis, receding as y grows: its face is
    # x = 1.0 + tan(30 deg) (y - 0.4).
    t = math.tan(ANGLE)
    face = np.array([1.0 + t * (1.0 - SIDE_Y), 1.0])
    normal = np.array([math.cos(ANGLE), -math.sin(ANGLE)])
    centre = face + 0.5 * THICK * normal
    angled = _free(SHAPE_2D, boxes=[(centre[0], centre[1], math.pi / 2 - ANGLE, 3.0, THICK)])
    # An L: a wall across the path (x in [1.2, 1.5], y < 1.0), then a leg running
    # forward along y in [0.7, 1.0] to the end of the map.
    ell = _free(SHAPE_2D, boxes=[(1.2 + THICK / 2, 0.4, 0.0, THICK, 1.2),
                                 (2.7, 1.0 - THICK / 2, 0.0, 3.0, THICK)])
    start = _start(y=SIDE_Y)
    return {
        "side-angled": scenario(angled, start=start, command=SIDE_COMMAND, slope=t),
        "side-ell": scenario(ell, start=start, command=SIDE_COMMAND, corner_y=1.0, wall_x=1.2),
    }


# Stepping over (paper V.B): an obstacle of length b in the RIGHT foot's lane
# only, from the map edge (y = 0) up to just below the left foot's grown
# footprint, so the right foot cannot step around it while the left foot
# passes beside it. Its near edge takes 5 positions that cover every phase of
# the 5 cm foothold lattice against the 2 cm grid (gcd 1 cm).
OVER_X = (1.00, 1.02, 1.04, 1.06, 1.08)
OVER_LENGTHS = {0.02: (0.04, 0.10, 0.12), 0.05: (0.02, 0.04, 0.06), 0.10: (0.02,)}


def b_max(margin):
    """Longest obstacle the swing foot can step over: b < 2 L - foot length - 2 m (metres)."""
    return 2 * L_MAX - 2 * HL - 2 * margin


def _over_scenarios():
    out = {}
    y_left = LANE_Y + 0.095
    for m, lengths in OVER_LENGTHS.items():
        top = int(math.floor((y_left - HW - m) / RES + 1e-6))  # rows below the left foot's grown footprint
        for b in lengths:
            for x in OVER_X:
                i0 = int(round(x / RES))
                i1 = i0 + int(round(b / RES))
                free = _free(SHAPE_2D, cells=[(i0, i1, 0, top)])
                out[f"over-m{m}-b{b}-x{x}"] = scenario(free, margin=m, obstacle=(i0 * RES, i1 * RES), b=b,
                                                       lane=-1)
    # The mirror image (left lane) for the 2 cm margin's extreme lengths.
    y_right = LANE_Y - 0.095
    bottom = int(math.ceil((y_right + HW + 0.02) / RES - 1e-6))
    for b in (0.04, 0.12):
        for x in OVER_X:
            i0 = int(round(x / RES))
            i1 = i0 + int(round(b / RES))
            free = _free(SHAPE_2D, cells=[(i0, i1, bottom, SHAPE_2D[1])])
            out[f"overleft-m0.02-b{b}-x{x}"] = scenario(free, margin=0.02, obstacle=(i0 * RES, i1 * RES), b=b,
                                                        lane=+1)
    # A one-cell bar across both lanes.
    for x in OVER_X:
        i0 = int(round(x / RES))
        free = _free(SHAPE_2D, cells=[(i0, i0 + 1, 0, SHAPE_2D[1])])
        out[f"bar-x{x}"] = scenario(free, margin=0.02, obstacle=(i0 * RES, (i0 + 1) * RES), b=RES, lane=0)
    return out


def _around_scenarios():
    # Small obstacles on the centre line between the feet (the paper's Fig. 8):
    # a foot at the usual 0.19 m stance width would touch them.
    small = _free(SHAPE_2D, boxes=[(1.55, LANE_Y, math.pi / 4, 0.07, 0.07), (2.25, LANE_Y, 0.0, 0.12, 0.06)],
                  cylinders=[(0.95, LANE_Y, 0.04)])
    # Clutter in the feet's lanes, where the naive joystick's footholds fall
    # (x = 0.5 + 0.4 k left, 0.7 + 0.4 k right).
    clutter = _free(SHAPE_2D, boxes=[(1.52, 0.93, 0.0, 0.07, 0.07), (2.28, 0.95, 0.6, 0.12, 0.05)],
                    cylinders=[(0.92, 1.05, 0.03), (2.52, 1.06, 0.035)])
    return {
        "free": scenario(np.ones(SHAPE_2D, bool)),
        "around": scenario(small),
        "clutter": scenario(clutter),
    }


TURN_CENTRE = (2.0, 1.0)
TURN_FLAT = ("turn-1", "turn-2", "turn-3", "turn--2", "turn-forward")


def _turn_scenarios():
    out = {}
    flat = np.ones(SHAPE_2D, bool)
    for k in (1, 2, 3, -2):
        out[f"turn-{k}"] = scenario(flat, start=_start(*TURN_CENTRE), command=(0.0, 0.0, k * ROT_STEP / 0.8),
                                    rot=k * ROT_STEP)
    out["turn-forward"] = scenario(flat, start=_start(1.2, 0.5), command=(0.125, 0.0, ROT_STEP / 0.8),
                                   rot=ROT_STEP)
    # Turning at 20 deg a step in a 0.4 m corridor whose walls are 2 cm clear of
    # the feet's grown footprints: a foot turned by 20 deg often does not fit, and
    # then the valid rotation nearest the target's is taken.
    spin = (0.0, 0.0, 3 * ROT_STEP / 0.8)
    corridor = _free(SHAPE_2D, cells=[(0, SHAPE_2D[0], 0, 40), (0, SHAPE_2D[0], 60, SHAPE_2D[1])])
    out["turn-corridor"] = scenario(corridor, start=_start(*TURN_CENTRE), command=spin, rot=3 * ROT_STEP,
                                    cluttered=True)
    # ... and with a wall 2 cm in front of the feet's grown footprints: turned
    # steps fit only further back, so the rotation is kept by shifting the step.
    front = _free(SHAPE_2D, cells=[(108, SHAPE_2D[0], 0, SHAPE_2D[1])])
    out["turn-wall"] = scenario(front, start=_start(*TURN_CENTRE), command=spin, rot=3 * ROT_STEP,
                                cluttered=True)
    return out


@functools.cache
def scenarios_2d():
    out = {}
    for make in (_wall_scenarios, _sidestep_scenarios, _over_scenarios, _around_scenarios, _turn_scenarios):
        out.update(make())
    return out


# ---------------------------------------------------------------------------------------------
# 2.5D scenarios: platforms drawn as surfaces on a height map
# ---------------------------------------------------------------------------------------------

LANE_HEIGHTS = (0.05, 0.08, 0.12, 0.15)  # raised left lane; max_step_height is 0.10 m
FULL_STEPS = ((0.02, 0.02, 1.0), (0.02, 0.02, 2.0), (0.05, 0.02, 2.0), (0.05, 0.0, 2.0))  # (h, margin, w)


def _height(boxes):
    t = ij.terrain.flat(SHAPE_25D, RES, has_height=True)
    return np.array(ij.terrain.scene.rasterize(t, boxes=boxes).height)


@functools.cache
def scenarios_25d():
    out = {}
    free = np.ones(SHAPE_25D, bool)
    for h in LANE_HEIGHTS:
        # The left lane, y >= 1.0 (1 mm inside the cell edge so no extra cell is
        # covered), from x = 1.0 on: the right foot's grown footprint stays below
        # y = 0.99, the left one's above y = 1.01.
        box = (2.1005, 1.6005, 0.0, 2.199, 1.199, h)
        out[f"lane-{h}"] = scenario(free, _height([box]), steps=STEPS_25D, platform=h, lane=+1, edge_x=1.0)
    # A step across both lanes from x = 1.2 on, with several margins and weights w.
    for h, m, w in FULL_STEPS:
        box = (2.2005, 1.0, 0.0, 1.999, 2.5, h)
        out[f"full-{h}-m{m}-w{w}"] = scenario(free, _height([box]), margin=m, w=w, steps=STEPS_25D,
                                              platform=h, lane=0, edge_x=1.2)
    return out


# ---------------------------------------------------------------------------------------------
# Running: one vmapped rollout per (terrain kind, method); results as NumPy per scenario
# ---------------------------------------------------------------------------------------------

def paper_metrics(robot):
    """The robot scored by the paper's metrics alone (slope, roughness, bump, step height, band): its ``support``
    term off. The experiments replicate the paper's planner, which lets a sole straddle a low edge; the library's
    default also refuses a sole whose contact polygon cannot carry it on such an edge (``support``, for the
    simulated biped: test_the_default_support_refuses_the_straddle_the_papers_metrics_allow). Off is a limit no
    footprint reaches (1 m: limits must be finite) and no weight."""
    return robot.replace(metrics=robot.metrics.replace(support_weight=jnp.float32(0.0),
                                                       support_limit=jnp.float32(1.0)))


ROBOT = paper_metrics(ij.robots.hrp2(margin=0.02))
# Margin and w are the only batched robot leaves; F and L_i depend on the action
# set and rotation weight alone, so one prebuilt set serves every scenario.
ROBOT_AXES = jax.tree_util.tree_map(lambda _: None, ROBOT).replace(margin=0, w=0)


@functools.cache
def _targets():
    return ij.make_targets(ROBOT)


@functools.partial(jax.jit, static_argnames=("num_steps", "method"))
def _rollouts(terrains, margins, ws, starts, commands, targets, num_steps, method):
    robots = ROBOT.replace(margin=margins, w=ws)

    def run(t, r, s, c):
        return rollout(t, r, s, c, num_steps, options=ij.SelectOptions(method=method), targets=targets)

    return jax.vmap(run, in_axes=(0, ROBOT_AXES, 0, 0))(terrains, robots, starts, commands)


def _run(scenarios, method):
    """Roll out every scenario at once (one vmapped call); NumPy trajectories by scenario name."""
    names = list(scenarios)
    sc = [scenarios[n] for n in names]
    terrains = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *[s.terrain() for s in sc])
    margins = jnp.asarray([s.margin for s in sc], jnp.float32)
    ws = jnp.asarray([s.w for s in sc], jnp.float32)
    starts = jnp.asarray(np.stack([s.start for s in sc]))
    commands = jnp.asarray(np.stack([s.commands for s in sc]))
    traj = _rollouts(terrains, margins, ws, starts, commands, _targets(), sc[0].commands.shape[0], method)
    traj = jax.tree_util.tree_map(np.asarray, traj)
    return {n: jax.tree_util.tree_map(lambda x, i=i: x[i], traj) for i, n in enumerate(names)}


@functools.cache
def runs_2d(method):
    return _run(scenarios_2d(), method)


@functools.cache
def runs_25d(method):
    return _run(scenarios_25d(), method)


# ---------------------------------------------------------------------------------------------
# Independent NumPy geometry of the footholds (float64, brute force over cells)
# ---------------------------------------------------------------------------------------------


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def _relative(base, pose):
    """Pose in the frame of ``base`` (NumPy, broadcasting over leading axes)."""
    base, pose = np.asarray(base, np.float64), np.asarray(pose, np.float64)
    c, s = np.cos(base[..., 2]), np.sin(base[..., 2])
    dx, dy = pose[..., 0] - base[..., 0], pose[..., 1] - base[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, _wrap(pose[..., 2] - base[..., 2])], -1)


def _stances(scenario, traj):
    """(T, 3) world pose of the stance foot at each decision, replaying the trajectory."""
    feet = scenario.start.astype(np.float64).copy()
    out = []
    for t in range(len(traj.sides)):
        row = 0 if traj.sides[t] > 0 else 1  # the swing foot's row
        out.append(feet[1 - row].copy())
        if traj.taken[t]:
            feet[row] = traj.footsteps[t]
    return np.array(out)


def _cells(shape, pose, grow, half=(HL, HW)):
    """(nx, ny) cells touched by the footprint at ``pose`` grown by ``grow`` on every side (``half``: the sole's
    half length and width; HRP-2's by default)."""
    return rect_touches_cells(pose[0], pose[1], pose[2], half[0] + grow, half[1] + grow, RES, shape)


def _inside_map(shape, pose, grow, half=(HL, HW)):
    c, s = math.cos(pose[2]), math.sin(pose[2])
    hl, hw = half[0] + grow, half[1] + grow
    ex, ey = abs(c) * hl + abs(s) * hw, abs(s) * hl + abs(c) * hw
    return (pose[0] - ex >= -EPS and pose[0] + ex <= shape[0] * RES + EPS
            and pose[1] - ey >= -EPS and pose[1] + ey <= shape[1] * RES + EPS)


def _front_gap(free, pose, margin):
    """Distance (m) from an unrotated foot's front edge to the nearest obstacle cell (or the map's end)
    ahead of its centre, among the rows its grown footprint overlaps."""
    nx, ny = free.shape
    y0 = np.arange(ny) * RES
    rows = (y0 < pose[1] + HW + margin) & (y0 + RES > pose[1] - HW - margin)
    x0 = np.arange(nx) * RES
    ahead = np.flatnonzero((x0 >= pose[0]) & ~free[:, rows].all(axis=1))
    edge = x0[ahead[0]] if ahead.size else nx * RES
    return edge - (pose[0] + HL)


def _taken(traj):
    return np.flatnonzero(traj.taken)


def _assert_walks_safely(name, sc, traj, half=(HL, HW)):
    """Every step taken, none stopped, and every foothold's grown footprint free and inside the map
    (checked here in NumPy, independently of the library's ``on_obstacle``)."""
    assert traj.taken.all() and not traj.stopped.any(), name
    assert traj.on_obstacle.sum() == 0, name
    for t in _taken(traj):
        pose = traj.footsteps[t]
        assert _inside_map(sc.free.shape, pose, sc.margin, half), (name, t, pose)
        assert sc.free[_cells(sc.free.shape, pose, sc.margin - EPS, half)].all(), (name, t, pose)


def _repeats(traj, last=4):
    """The last ``last`` footholds repeat with period 2: the robot walks in place."""
    f = traj.footsteps[-last - 2:]
    return np.allclose(f[2:], f[:-2], atol=EPS)


METHODS = ("exhaustive", "ordered")
# The paper's ordered search in the fast tier, its exhaustive twin in the slow one (the wall, w's tradeoff).
ORDERED_FAST = (pytest.param("exhaustive", marks=pytest.mark.slow), "ordered")


def test_preset_has_the_papers_geometry():
    """The numbers every expectation below is derived from (paper V: 496 actions, +-20 cm,
    19-33 cm, +-20 deg, 13 x 24.2 cm foot, p0 = (0, 0.19, 0), 0.8 s steps)."""
    a = np.asarray(ROBOT.actions, np.float64)
    assert a.shape == (496, 3)
    np.testing.assert_allclose(np.unique(np.round(a[:, 0], 6)), np.arange(-4, 5) * DX_STEP, atol=1e-6)
    np.testing.assert_allclose(np.unique(np.round(a[:, 1], 6)), 0.19 + 0.02 * np.arange(8), atol=1e-6)
    np.testing.assert_allclose(np.unique(np.round(a[:, 2], 6)), np.arange(-3, 4) * ROT_STEP, atol=1e-6)
    np.testing.assert_allclose([float(ROBOT.foot_length) / 2, float(ROBOT.foot_width) / 2], [HL, HW], atol=1e-7)
    np.testing.assert_allclose(np.asarray(ROBOT.p0), [0.0, 0.19, 0.0], atol=1e-7)
    assert float(ROBOT.step_time) * FORWARD[0] == pytest.approx(L_MAX)
    np.testing.assert_allclose(np.asarray(ROBOT.max_step_height), 0.10, atol=1e-7)
    assert b_max(0.02) == pytest.approx(0.118) and b_max(0.10) < 0


def _names(prefix):
    return [n for n in scenarios_2d() if n.startswith(prefix)]


# ---------------------------------------------------------------------------------------------
# 1. Blockage in the commanded direction
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", WALLS)
@pytest.mark.parametrize("method", ORDERED_FAST)
def test_walks_up_to_a_wall_as_close_as_the_margin_allows_then_steps_in_place(method, name):
    sc, traj = scenarios_2d()[name], runs_2d(method)[name]
    m, wall = sc.margin, sc.info["wall_x"]
    _assert_walks_safely(name, sc, traj)
    fronts = traj.footsteps[:, 0] + HL
    assert np.all(wall - fronts >= m - EPS)  # never closer than the margin
    # Both feet end as close as the margin allows, up to one action step and one cell.
    final = traj.feet[:, 0] + HL
    assert np.all(wall - final >= m - EPS) and np.all(wall - final < m + TOL), (final, wall, m)
    # Once it steps in place, it keeps stepping in place (p0), going nowhere.
    k = int(np.argmax(traj.in_place))
    assert traj.in_place[k] and traj.in_place[k:].all(), traj.in_place
    assert k <= STEPS_2D - 6, k
    np.testing.assert_allclose(traj.footsteps[k:, 0], traj.feet[0, 0], atol=EPS)
    np.testing.assert_array_less(traj.footsteps[:k, 0], traj.feet[0, 0] + EPS)  # it only approached before


@pytest.mark.parametrize("name", ["side-angled", "side-ell"])
@pytest.mark.parametrize("method", METHODS)
def test_sidesteps_along_a_blockage_following_its_shape(method, name):
    """Commanded forward and left into a wall at 30 deg or an L, the robot slides along it."""
    sc, traj = scenarios_2d()[name], runs_2d(method)[name]
    m = sc.margin
    _assert_walks_safely(name, sc, traj)
    stance = _stances(sc, traj)
    rel = _relative(stance, traj.footsteps)
    np.testing.assert_allclose(traj.footsteps[:, 2], 0.0, atol=EPS)  # no rotation was commanded
    # Lateral progress never stops: each left foothold is >= 7 cm left of the previous one
    # (half the 14 cm per step pair commanded; the right foot follows at 0.19 m).
    left = traj.footsteps[traj.sides > 0]
    assert np.all(np.diff(left[:, 1]) >= 0.07), left
    # Every step cut short by the wall ends as close to it as the margin and the 5 cm lattice allow:
    # one lattice step further would touch the wall's cells.
    blocked = rel[:, 0] < L_MAX - EPS
    assert blocked.sum() >= 4
    for t in np.flatnonzero(blocked):
        gap = _front_gap(sc.free, traj.footsteps[t], m)
        assert m - EPS <= gap < m + DX_STEP, (t, traj.footsteps[t], gap)
    if "slope" in sc.info:
        # The wall recedes by tan(30 deg) per metre of y: from first contact, x follows it.
        first, last = traj.footsteps[np.flatnonzero(blocked)[[0, -1]]]
        np.testing.assert_allclose(last[0] - first[0], sc.info["slope"] * (last[1] - first[1]), atol=TOL)
        assert last[1] - first[1] > 0.5
    else:
        # The L: stopped by the wall while beside it, then past the corner it walks on along the leg.
        corner, wall = sc.info["corner_y"], sc.info["wall_x"]
        beside = traj.footsteps[:, 1] - HW - m < corner
        assert np.all(traj.footsteps[beside, 0] + HL + m <= wall + EPS)
        assert np.all(traj.feet[:, 0] - HL - m > wall + THICK), traj.feet
        assert np.all(traj.feet[:, 1] - HW - m >= corner - EPS), traj.feet


# ---------------------------------------------------------------------------------------------
# 2. Stepping over an obstacle in one foot's lane (paper V.B: b < 2 L - foot length - 2 m)
# ---------------------------------------------------------------------------------------------


def _crossed(sc, traj):
    """Did the blocked foot get past the obstacle?  Checks that it never stood on or over it."""
    c0, c1 = sc.info["obstacle"]
    lane = sc.info["lane"]
    feet = traj.footsteps[(traj.sides == lane) | (lane == 0)]
    past = feet[:, 0] - HL >= c1 - EPS
    assert np.all(past | (feet[:, 0] + HL <= c0 + EPS)), feet  # before it or past it, never on it
    return bool(past.any())


def _lattice_predicts_crossing(c0, c1, m, hl=HL, l_max=L_MAX):
    """Exact outcome on this map: the blocked foot reaches the last lattice x whose grown front stays
    before the obstacle, the other foot steps L ahead of it, and the blocked foot then swings 2 L: it
    gets past iff its grown rear then clears the obstacle's far edge (``hl``: the sole's half length,
    ``l_max``: the longest step L; HRP-2's by default)."""
    x_last = X0 + DX_STEP * math.floor((c0 - hl - m - X0) / DX_STEP)
    return x_last + 2 * l_max - hl - m >= c1


@pytest.mark.parametrize("margin", MARGINS)
@pytest.mark.parametrize("method", METHODS)
def test_steps_over_obstacles_only_below_the_papers_length_limit(method, margin):
    runs = runs_2d(method)
    names = [n for n in scenarios_2d() if n.startswith(("over-", "overleft-")) and f"-m{margin}-" in n]
    bound = b_max(margin)
    crossed_lengths = []
    for name in names:
        sc, traj = scenarios_2d()[name], runs[name]
        _assert_walks_safely(name, sc, traj)
        b = sc.info["b"]
        c0, c1 = sc.info["obstacle"]
        crossed = _crossed(sc, traj)
        # The obstacle spans the blocked foot's whole lateral reach and leaves the other lane
        # free: the other foot takes the commanded step (0.2, 0.19, 0) every time, and the
        # blocked foot never leaves its line.
        rel = _relative(_stances(sc, traj), traj.footsteps)
        other = traj.sides == -sc.info["lane"]
        assert np.allclose(np.abs(rel[other]), [L_MAX, 0.19, 0.0], atol=EPS), (name, rel[other])
        assert np.allclose(np.abs(rel[~other, 1:]), [0.19, 0.0], atol=EPS), (name, rel[~other])
        if b <= bound - TOL:
            assert crossed, f"{name}: b = {b} is below b_max - tol = {bound - TOL:.3f} but was not crossed"
        if b > bound:
            assert not crossed, f"{name}: b = {b} is above b_max = {bound:.3f} but was crossed"
        assert crossed == _lattice_predicts_crossing(c0, c1, margin), name
        if crossed:
            crossed_lengths.append(b)
            # and it walks on: the other foot overtakes the obstacle too
            assert traj.feet[:, 0].min() - HL > c1, (name, traj.feet)
        else:
            assert _repeats(traj), name  # stuck behind it, walking in place
    if bound > 0:
        # The limit is tight: at the right phase of the lattice, an obstacle within one cell of
        # b_max is stepped over (2 cm margin: 10 cm of 11.8; 5 cm margin: 4 cm of 5.8).
        assert max(crossed_lengths) >= bound - RES, crossed_lengths
    else:
        # 10 cm margin, as on the real robot: nothing, not even a one-cell bar, is crossable.
        assert not crossed_lengths and min(scenarios_2d()[n].info["b"] for n in names) == RES


@pytest.mark.parametrize("method", METHODS)
def test_a_bar_across_both_lanes_is_never_stepped_over(method):
    """The first foot over must travel foot length + 2 m + b > 0.2 m from a stance foot beside it."""
    for name in _names("bar-"):
        sc, traj = scenarios_2d()[name], runs_2d(method)[name]
        _assert_walks_safely(name, sc, traj)
        assert not _crossed(sc, traj), name
        assert traj.in_place[-4:].all(), name
        assert np.all(sc.info["obstacle"][0] - (traj.feet[:, 0] + HL) < sc.margin + TOL), name


# ---------------------------------------------------------------------------------------------
# 3. Stepping around small obstacles
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["around", "clutter"])
@pytest.mark.parametrize("method", METHODS)
def test_feet_splay_around_small_obstacles_while_progress_continues(method, name):
    runs = runs_2d(method)
    sc, traj, free = scenarios_2d()[name], runs[name], runs["free"]
    _assert_walks_safely(name, sc, traj)
    assert (~sc.free).sum() > 0 and np.all(np.diff(free.footsteps[:, 0][::2]) > 0)
    along, along_free = float(traj.summary()["distance_along"]), float(free.summary()["distance_along"])
    assert along_free > 3.0  # the obstacle-free run: 0.1 + 15 x 0.2 m
    assert along >= along_free - L_MAX - EPS, (along, along_free)  # at most one step's worth lost
    moved = np.abs(traj.footsteps[:, 1] - free.footsteps[:, 1])
    assert moved.max() >= 2 * RES, moved  # some footholds moved sideways ...
    width = np.abs(_relative(_stances(sc, traj), traj.footsteps)[:, 1])
    assert width.max() >= 0.19 + 2 * RES - EPS, width  # ... by splaying the feet wider than 0.19 m
    obstacles_x = np.flatnonzero(~sc.free.all(axis=1)) * RES
    assert traj.feet[:, 0].min() - HL > obstacles_x.max() + RES  # and every obstacle is behind it
    if name == "around":  # obstacles on the centre line: the forward step is never shortened
        np.testing.assert_allclose(traj.footsteps[:, 0], free.footsteps[:, 0], atol=EPS)


# ---------------------------------------------------------------------------------------------
# 4. Stepping onto obstacles (2.5D)
# ---------------------------------------------------------------------------------------------


def _heights_under(sc, pose):
    """(min, max) terrain height under the footprint (no margin) at ``pose``."""
    h = sc.height[_cells(sc.height.shape, pose, 0.0)]
    return float(h.min()), float(h.max())


def _assert_25d_safe(name, sc, traj):
    assert traj.taken.all() and not traj.stopped.any() and traj.valid.all(), name
    assert traj.on_obstacle.sum() == 0, name


@pytest.mark.slow
@pytest.mark.parametrize("name", ["lane-0.05", "lane-0.08", "full-0.02-m0.02-w2.0"])
@pytest.mark.parametrize("method", METHODS)
def test_low_platforms_are_stepped_onto(method, name):
    sc, traj = scenarios_25d()[name], runs_25d(method)[name]
    _assert_25d_safe(name, sc, traj)
    h, edge = sc.info["platform"], sc.info["edge_x"]
    on_top = [t for t in range(len(traj.sides)) if _heights_under(sc, traj.footsteps[t])[0] >= h - 1e-6]
    assert on_top, f"{name}: no foothold reached the platform's height {h}"
    if sc.info["lane"] > 0:  # raised left lane: every left foothold from then on is on top
        assert all(traj.sides[t] > 0 for t in on_top)
        assert on_top == [t for t in range(on_top[0], len(traj.sides)) if traj.sides[t] > 0]
    else:
        assert len(on_top) >= 4 and all(_heights_under(sc, f)[0] >= h - 1e-6 for f in traj.feet)
    assert traj.feet[:, 0].min() > edge + 0.5  # and it walked on along the platform


@pytest.mark.slow
@pytest.mark.parametrize("name", ["lane-0.12", "lane-0.15"])
@pytest.mark.parametrize("method", METHODS)
def test_platforms_above_the_step_height_limit_are_refused(method, name):
    """max_step_height is 0.10 m: the left foot stays on the ground before the raised lane."""
    sc, traj = scenarios_25d()[name], runs_25d(method)[name]
    _assert_25d_safe(name, sc, traj)
    m, edge = sc.margin, sc.info["edge_x"]
    assert all(_heights_under(sc, f)[1] == 0.0 for f in traj.footsteps), "a foot touched the platform"
    assert _repeats(traj)  # stepping in place before it ...
    left = traj.feet[0]
    assert m - EPS <= edge - (left[0] + HL) < m + TOL  # ... as close as the margin allows
    # The foothold the command asks for, p_next = (0.2, 0.19, 0) from the right stance foot (on
    # top of the lane), is rejected by the step-height term alone.
    robot = ROBOT.replace(margin=jnp.float32(m))
    stance = traj.feet[1]
    want = stance + np.array([L_MAX, 0.19, 0.0], np.float32)
    terms = ij.foot_cost_terms(sc.terrain(), robot, stance, -1, want[None], swing_from=left)
    assert np.isinf(terms.step[0])
    assert float(terms.step_height_m[0]) == pytest.approx(sc.info["platform"], abs=1e-4)
    others = [terms.obstacle, terms.slope, terms.roughness, terms.bump, terms.band, terms.swing_path,
              terms.unsupported]
    assert all(np.isfinite(float(o[0])) for o in others)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["full-0.05-m0.02-w2.0", "full-0.05-m0.0-w2.0"])
@pytest.mark.parametrize("method", METHODS)
def test_a_full_width_step_above_the_band_limit_is_never_climbed(method, name):
    """A 5 cm step across both lanes: a foot is valid only wholly below or wholly on top of it
    (straddling breaks the bump/roughness limits; the 3 cm band limit keeps the grown footprint off
    the edge), so the first foot up would land >= 0.242 + 2 m ahead of a stance foot still below:
    beyond L = 0.2 m. Like the bar across both lanes, even with no margin and w = 2 it is never
    climbed: the robot walks in place at the edge."""
    sc, traj = scenarios_25d()[name], runs_25d(method)[name]
    _assert_25d_safe(name, sc, traj)
    assert all(_heights_under(sc, f)[1] == 0.0 for f in traj.footsteps)
    assert traj.in_place[-4:].all()
    assert np.all(sc.info["edge_x"] - (traj.feet[:, 0] + HL) < sc.margin + TOL)


@pytest.mark.parametrize("method", ORDERED_FAST)
def test_w_trades_terrain_cost_against_following_the_command(method):
    """A 2 cm step across both lanes can be straddled (valid, but rough): with w = 1 stepping in
    place (w x 0.2 m) is cheaper than the straddle's FootCost, with w = 2 it is not."""
    runs = runs_25d(method)
    sc1, low_w, high_w = scenarios_25d()["full-0.02-m0.02-w1.0"], runs["full-0.02-m0.02-w1.0"], \
        runs["full-0.02-m0.02-w2.0"]
    _assert_25d_safe("w1", sc1, low_w)
    assert all(_heights_under(sc1, f)[1] == 0.0 for f in low_w.footsteps) and low_w.in_place[-4:].all()
    assert _heights_under(sc1, high_w.feet[0])[0] >= 0.02 - 1e-6  # w = 2 climbed it (see above)
    stance, swing = low_w.feet[1], low_w.feet[0]  # side by side at the edge
    want = stance + np.array([L_MAX, 0.19, 0.0], np.float32)  # p_next: it straddles the edge
    cost = float(ij.foot_cost(sc1.terrain(), ROBOT, stance, -1, want[None], swing_from=swing)[0])
    assert 1.0 * L_MAX < cost < 2.0 * L_MAX, cost


@pytest.mark.slow
def test_the_default_support_refuses_the_straddle_the_papers_metrics_allow():
    """The straddle of test_w_trades_terrain_cost_against_following_the_command (a sole across the 2 cm edge) is
    valid under the paper's metrics; a rigid sole there rests on its points on the upper side and rocks, and the
    default robot's support term (footcost.sole: the contact polygon of the rested sole, against the whole sole's)
    refuses it: its support metric lies beyond that limit, at most the whole sole's margin. The step in place on
    the level ground before the edge stays valid."""
    sc1 = scenarios_25d()["full-0.02-m0.02-w1.0"]
    low_w = runs_25d("exhaustive")["full-0.02-m0.02-w1.0"]
    stance, swing = low_w.feet[1], low_w.feet[0]
    want = stance + np.array([L_MAX, 0.19, 0.0], np.float32)
    level = stance + np.array([0.0, 0.19, 0.0], np.float32)  # the step in place, wholly before the edge
    default = ij.robots.hrp2(margin=0.02)
    terms = ij.foot_cost_terms(sc1.terrain(), default, stance, -1, np.stack([want, level]), swing_from=swing)
    paper = ij.foot_cost_terms(sc1.terrain(), ROBOT, stance, -1, want[None], swing_from=swing)
    assert np.isfinite(float(paper.total[0]))
    full = float(ij.footcost.sole.full_margin(0.5 * default.foot_length, 0.5 * default.foot_width,
                                              default.metrics.contact_inset))
    assert float(default.metrics.support_limit) < float(paper.support_m[0]) <= full + 1e-6
    assert np.isinf(float(terms.support[0])) and np.isinf(float(terms.total[0]))
    assert float(terms.support_m[1]) < 1e-6 and np.isfinite(float(terms.total[1]))


# ---------------------------------------------------------------------------------------------
# 5. Turning: the commanded rotation is kept whenever a step with it is valid
# ---------------------------------------------------------------------------------------------


@jax.jit
def _all_valid(terrain, margin, stances, stance_sides):
    """(T, N) validity of every action of S from each stance (the public FootCost)."""
    robot = ROBOT.replace(margin=margin)
    n = robot.num_actions

    def one(stance, side):
        steps = ij.action_steps(robot, stance, side)
        return jnp.isfinite(ij.foot_cost(terrain, robot, stance, side, steps, action_index=jnp.arange(n)))

    return jax.vmap(one)(stances, stance_sides)


def _rotation_rule(sc, traj):
    """Per step: (target rotation feasible, chosen |rotation error|, least |rotation error| of any
    valid step), all from the public FootCost of every action."""
    stance = _stances(sc, traj)
    sides = -traj.sides.astype(np.float32)  # stance sides
    valid = np.asarray(_all_valid(sc.terrain(), jnp.float32(sc.margin), jnp.asarray(stance, jnp.float32),
                                  jnp.asarray(sides)))
    target = _relative(stance, traj.target)[:, 2]
    chosen = _relative(stance, traj.footsteps)[:, 2]
    swing = traj.sides.astype(np.float64)
    rots = np.asarray(ROBOT.actions[:, 2], np.float64)[None, :] * swing[:, None]  # (T, N) mirrored
    err_all = np.abs(_wrap(rots - target[:, None]))
    best = np.where(valid, err_all, np.inf).min(axis=1)
    return best < ROT_TOL, np.abs(_wrap(chosen - target)), best


@pytest.mark.parametrize("name", TURN_FLAT)
@pytest.mark.parametrize("method", METHODS)
def test_a_commanded_rotation_is_followed_on_flat_ground(method, name):
    sc, traj = scenarios_2d()[name], runs_2d(method)[name]
    _assert_walks_safely(name, sc, traj)
    rot = sc.info["rot"]
    rel = _relative(_stances(sc, traj), traj.footsteps)
    target = _relative(_stances(sc, traj), traj.target)
    # Every step turns by exactly the target's (quantised) rotation, which is the commanded one.
    np.testing.assert_allclose(rel[:, 2], target[:, 2], atol=1e-5)
    np.testing.assert_allclose(rel[:, 2], rot, atol=1e-5)
    np.testing.assert_allclose(traj.rotation_deviation, 0.0, atol=1e-5)
    np.testing.assert_allclose(traj.deviation, 0.0, atol=EPS)  # lattice commands: p_next is an action
    # So after T steps the feet have turned by T (right, last) and T - 1 (left) steps.
    turned = np.array([STEPS_2D - 1, STEPS_2D]) * rot
    np.testing.assert_allclose(_wrap(traj.feet[:, 2] - turned), 0.0, atol=ROT_TOL)
    if sc.commands[0, 0] > 0:
        assert float(traj.summary()["distance_along"]) > 0.1 * STEPS_2D * 0.9


@pytest.mark.parametrize("method", METHODS)
def test_commanded_rotation_is_kept_whenever_a_step_with_it_is_valid(method):
    """The paper's rule (IV.B), over every 2D scenario: a step with the target's rotation is taken
    whenever one is valid; otherwise the valid rotation nearest the target's."""
    runs = runs_2d(method)
    kept_by_translating = rotation_given_up = 0
    for name, sc in scenarios_2d().items():
        traj = runs[name]
        feasible, chosen, best = _rotation_rule(sc, traj)
        t = _taken(traj)
        np.testing.assert_allclose(chosen[t], best[t], atol=ROT_TOL, err_msg=name)
        assert np.all(chosen[t][feasible[t]] < ROT_TOL), name
        if sc.info.get("cluttered"):
            kept_by_translating += int(np.sum(feasible[t] & (traj.deviation[t] > RES)))
            rotation_given_up += int(np.sum(~feasible[t]))
    # The turning-among-walls scenarios exercise both branches of the rule.
    assert kept_by_translating > 0 and rotation_given_up > 0, (kept_by_translating, rotation_given_up)


# ---------------------------------------------------------------------------------------------
# 6. Naive vs intelligent joystick (the paper's Fig. 3), and the two selectors agree
# ---------------------------------------------------------------------------------------------

CLUTTERED = ("around", "clutter", "side-angled", "side-ell", "turn-wall", "turn-corridor", "wall-m0.02-x1.31",
             "over-m0.02-b0.12-x1.0", "bar-x1.0")


@pytest.mark.parametrize("method", METHODS)
def test_naive_joystick_steps_on_obstacles_where_the_intelligent_one_does_not(method):
    naive, smart = runs_2d("naive"), runs_2d(method)
    for name in CLUTTERED:
        sc = scenarios_2d()[name]
        _assert_walks_safely(name, sc, smart[name])
        assert naive[name].summary()["footholds_on_obstacles"] > 0, name
        # The metric itself, recounted: a footprint (no margin) on an obstacle cell or off the map.
        for t in _taken(naive[name]):
            pose = naive[name].footsteps[t]
            on = not (_inside_map(sc.free.shape, pose, 0.0) and sc.free[_cells(sc.free.shape, pose, -EPS)].all())
            assert bool(naive[name].on_obstacle[t]) == on, (name, t, pose)
    # Where nothing is in the way, the two joysticks walk the same steps.
    for name in ("free", "turn-1", "turn-3", "turn-forward"):
        np.testing.assert_allclose(naive[name].footsteps, smart[name].footsteps, atol=EPS, err_msg=name)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["2d", "2.5d"])
def test_exhaustive_and_ordered_walk_identical_trajectories(kind):
    runs = runs_2d if kind == "2d" else runs_25d
    ex, od = runs("exhaustive"), runs("ordered")
    for name in ex:
        a, b = ex[name], od[name]
        for field in ("footsteps", "index", "taken", "valid", "stopped", "in_place", "on_obstacle"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=f"{name}.{field}")
        np.testing.assert_allclose(a.cost, b.cost, rtol=1e-6, err_msg=name)
        assert np.all(b.evaluated <= a.evaluated)


# ---------------------------------------------------------------------------------------------
# 7. Stairs (issue 20): the paper's 20 cm reach stops at a full-width riser; a 30 cm reach climbs
# ---------------------------------------------------------------------------------------------

SHAPE_STAIRS = (200, 60)  # 4 m x 1.2 m
STAIR_X = 1.0  # m: the first riser (a cell edge, 15 cm ahead of a foothold of the 5 cm lattice from x = 0.3)
STAIR_STEPS = 14
NUM_RISERS = 3


def _stairs(rise, run, first_x=STAIR_X):
    """A 2.5D staircase along +x (ijoy_jax.terrain's stairs family): NUM_RISERS risers of ``rise`` (negative: down)
    every ``run`` metres from ``first_x``, the start landing at height 0 around the start feet (x = 0.3)."""
    params = ij.terrain.generators.StairParams(rise=rise, run=run, num_steps=NUM_RISERS, first=first_x - X0,
                                               start_x=X0 / (SHAPE_STAIRS[0] * RES), start_y=0.5, start_radius=0.0)
    return ij.terrain.generators.stairs(0, params, shape=SHAPE_STAIRS, resolution=RES, has_height=True)


@functools.partial(jax.jit, static_argnames="num_steps")
def _stair_rollouts(terrains, robot, targets, command, num_steps):
    start = jnp.asarray(_start(y=0.6))
    return jax.vmap(lambda t: rollout(t, robot, start, command, num_steps, targets=targets))(terrains)


@functools.cache
def _stair_runs(reach, cases):
    """Roll out the perfect robot (hrp2(reach=...), full speed forward) on every (rise, run, first riser) case."""
    robot = paper_metrics(ij.robots.hrp2(margin=0.02, reach=reach))
    terrains = [_stairs(*c) for c in cases]
    batch = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *terrains)
    command = jnp.array([reach / float(robot.step_time), 0.0, 0.0], jnp.float32)  # p_next = the longest step
    traj = jax.tree_util.tree_map(np.asarray, _stair_rollouts(batch, robot, ij.make_targets(robot), command,
                                                              STAIR_STEPS))
    heights = [np.asarray(t.height) for t in terrains]
    return robot, [(heights[i], jax.tree_util.tree_map(lambda x, i=i: x[i], traj)) for i in range(len(cases))]


def _under(height, pose):
    """(min, max) height under the bare footprint at ``pose``."""
    h = height[_cells(height.shape, pose, 0.0)]
    return float(h.min()), float(h.max())


BLOCKING_RISERS = ((0.013, 0.3, STAIR_X), (0.02, 0.3, STAIR_X), (0.02, 0.3, STAIR_X + 0.03), (0.05, 0.3, STAIR_X),
                   (0.10, 0.3, STAIR_X), (0.15, 0.3, STAIR_X), (-0.05, 0.3, STAIR_X), (-0.10, 0.3, STAIR_X),
                   (-0.15, 0.3, STAIR_X), (0.013, 0.3, STAIR_X + 0.03))


@pytest.mark.slow
def test_the_papers_reach_marks_time_before_a_full_width_riser():
    """The 20 cm limit and its geometry. An action lands the swing foot at most L = 0.20 m ahead of the stance
    foot, so the stance foot's toe (+0.121) is always ahead of the swing foot's heel (L - 0.121 = 0.079), and
    further than the margin (0.02) in front of a riser that the swing foot's grown heel has passed: a riser across
    both lanes can only be crossed by a foot straddling it. Straddling is valid for low risers, but with w = 1 it
    costs more than marking time (test_w_trades_terrain_cost_against_following_the_command): the perfect robot
    walks up to the riser and marks time before every full-width riser of 1.3 cm or more, up or down, wherever it
    falls along the lattice (at a slope weight of 0.5, the default before issue #20's image maps, it straddled a
    1.3 cm riser 18 cm ahead of a foothold). Stairs need a longer reach
    (test_a_longer_reach_climbs_and_descends_stairs)."""
    robot, runs = _stair_runs(0.20, BLOCKING_RISERS)
    acts = np.asarray(robot.actions)
    assert acts[:, 0].max() - HL < HL + float(robot.margin)  # the geometry: toe ahead of the heel, by > the margin
    for (rise, _, first), (height, traj) in zip(BLOCKING_RISERS, runs, strict=True):
        name = f"rise {rise} at x = {first}"
        assert traj.taken.all() and not traj.stopped.any() and traj.valid.all(), name
        crossed = [t for t in range(STAIR_STEPS) if min(abs(v) for v in _under(height, traj.footsteps[t])) > 1e-6]
        assert not crossed, (name, traj.footsteps[crossed[0]])  # no foot ever wholly beyond the riser
        assert traj.in_place[-4:].all() and _repeats(traj), name  # marking time ...
        assert np.all(first - (traj.feet[:, 0] + HL) < float(robot.margin) + TOL), (name, traj.feet)  # ... at it
        assert all(_under(height, f) == (0.0, 0.0) for f in traj.feet), name  # on the start landing
        np.testing.assert_array_equal(traj.footholds[-4:, 2:5], 0.0)


STAIR_CASES = tuple((sign * rise, run) for sign in (1.0, -1.0) for rise in (0.05, 0.10, 0.15) for run in (0.30, 0.40))


@pytest.mark.slow
def test_a_longer_reach_climbs_and_descends_stairs():
    """hrp2(reach=0.30): a step lands up to 0.30 m ahead, beyond foot_length + 2 margin = 0.282 m, so a foot
    passes a riser while the stance foot stands before it. The perfect robot climbs and descends three risers of 5,
    10 and 15 cm (max_step_height 0.15 m) to the top (bottom) landing. Treads: a foot with its 2 cm margin needs
    0.282 m; the feet's x stay on one 5 cm lattice (no rotation is commanded), and the 1.8 cm of slack between
    0.282 and 0.30 holds a lattice point only if every riser keeps the first one's phase: a tread of 0.30 m takes
    one step per tread, one of 0.40 m two (the second foot comes up 5 cm further); risers lie on cell edges (2 cm
    cells). Every foothold stands wholly on one tread, with its full foothold there (z the tread's height, level);
    no step changes level by more than one riser, and every step between levels is the longest one."""
    robot, runs = _stair_runs(0.30, tuple((rise, run, STAIR_X) for rise, run in STAIR_CASES))
    foot_plus_margins = float(robot.foot_length) + 2 * float(robot.margin)
    for (rise, run), (height, traj) in zip(STAIR_CASES, runs, strict=True):
        name = f"rise {rise}, tread {run}"
        assert traj.taken.all() and not traj.stopped.any() and traj.valid.all(), name
        levels = []
        for t in range(STAIR_STEPS):
            lo, hi = _under(height, traj.footsteps[t])
            assert hi - lo < 1e-6, (name, t, traj.footsteps[t], lo, hi)  # never straddling a riser
            np.testing.assert_allclose(traj.footholds[t, 2:5], [lo, 0.0, 0.0], atol=1e-5, err_msg=f"{name} {t}")
            levels.append(round(lo / rise))
        top = NUM_RISERS * rise
        for foot in traj.feet:  # both feet on the top (bottom) landing
            assert _under(height, foot) == pytest.approx((top, top), abs=1e-6), (name, traj.feet)
        stance = _stances(types.SimpleNamespace(start=_start(y=0.6)), traj)
        rel = _relative(stance, traj.footsteps)
        stance_levels = np.array([round(_under(height, s)[0] / rise) for s in stance])
        change = np.array(levels) - stance_levels
        assert np.abs(change).max() == 1 and (change != 0).sum() >= NUM_RISERS, (name, change)
        np.testing.assert_allclose(rel[change != 0, 0], 0.30, atol=EPS, err_msg=name)
        assert 0.30 >= foot_plus_margins
        steps_per_tread = {0.30: 1, 0.40: 2}[run]  # one step up per tread, or two (see the docstring)
        first_up = [t for t in range(STAIR_STEPS) if levels[t] == 1][0]
        second_up = [t for t in range(STAIR_STEPS) if levels[t] == 2][0]
        assert second_up - first_up == steps_per_tread, (name, levels)

"""The MJX biped in the joystick loop, end to end: one compile of the batched rollout serves the whole file.

MJX compiles slowly on a CPU (about a minute), so every check here runs on
rollouts of one shape (4 rollouts x 16 steps on a 4 m x 2 m map at 2 cm)
through ``walker.rollout_batch``, compiled once:

* three of the paper's experiments (tests/test_experiments.py) with the
  simulated robot in place of the perfect one: walking up to a wall and
  stepping in place, stepping over a 4 cm obstacle in the right foot's lane,
  turning on the spot; plus two steps in place and fourteen 0.2 m steps
  forward on an empty map. Obstacle cells stand ``BipedParams.obstacle_height``
  (0.1 m) tall in the physics.
* the safety margin in clutter: two clutter maps at 0 and 10 cm (the margin sweep with physics is
  ``sweeps/margin_physics.toml``, run by the sweep engine; tests/test_sweep_physics.py).
* the states recorded for rendering, and the renderer (``ijoy_jax.sim.render``).
* starting on rough ground with no flat pad under the feet (issue #48), in a 2.5D program of its own: two
  robots on 2 m x 1.2 m maps.

The controller's physics is tested with native MuJoCo in test_sim_controller.py.
"""

import os
import subprocess
import sys
from types import SimpleNamespace

import _tiny_walk  # tests/ is on sys.path (pytest rootdir import)
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from test_experiments import HL, RES, SHAPE_2D, STEPS_2D, _start, scenario, scenarios_2d

import ijoy_jax as ij
from ijoy_jax.sim import checks, physics, render
from ijoy_jax.sim import walker as W
from ijoy_jax.terrain import generators

NAMES = ("wall-m0.05-x1.44", "over-m0.02-b0.04-x1.0", "turn-1", "flat-forward")
PLACEMENT_TOL = 0.03  # m (measured up to 0.6 cm on these scenarios, 1.1 cm for action-set steps natively)
FRAMES = 4  # states kept per step
FORWARD_CMDS = np.array([[0.0, 0.0, 0.0]] * 2 + [[0.25, 0.0, 0.0]] * (STEPS_2D - 2), np.float32)


def _batch(scs):
    stack = lambda *a: jnp.stack(a)  # noqa: E731
    terrains = jax.tree_util.tree_map(stack, *[sc.terrain() for sc in scs])
    robots = jax.tree_util.tree_map(stack, *[ij.robots.hrp2(margin=sc.margin, w=sc.w) for sc in scs])
    starts = jnp.stack([jnp.asarray(sc.start) for sc in scs])
    commands = jnp.stack([jnp.asarray(sc.commands) for sc in scs])
    return terrains, robots, starts, commands


# ------------------------------------------------------------------ the fast tier: the README's small walk
# One MJX program (tests/_tiny_walk.py: the README's example, two robots, three steps on a 1.6 m map) checks
# the walker end to end in a contributor's quick run; everything below it is the slow tier's.


def test_the_readmes_small_walk_steps_where_it_was_sent():
    traj = _tiny_walk.walk()
    assert traj.footsteps.shape == (2, _tiny_walk.STEPS, 3)
    assert traj.taken.all() and not traj.log.fallen.any() and not traj.stopped.any()
    assert not traj.log.obstacle_contact.any()
    assert traj.log.placement_error.max() < PLACEMENT_TOL, traj.log.placement_error
    np.testing.assert_allclose(traj.footsteps[..., :2], traj.commanded[..., :2], atol=PLACEMENT_TOL)
    # The robots walked: every step lands ahead of the start feet, the first robot straight on.
    assert (traj.footsteps[:, -1, 0] > _tiny_walk.START[0, 0] + 0.1).all()
    assert abs(traj.footsteps[0, -1, 2]) < 0.05 and traj.footsteps[1, -1, 2] > 0.02  # the second turns left
    assert traj.log.qpos.shape[:3] == (2, _tiny_walk.STEPS, _tiny_walk.FRAMES)
    s = {k: np.asarray(v) for k, v in W.summary(traj).items()}
    assert not s["fell"].any() and (s["steps_taken"] == _tiny_walk.STEPS).all()
    assert all(np.isfinite(v).all() for v in s.values())


def test_the_readmes_small_walk_takes_new_physics_values_without_compiling():
    first = _tiny_walk.walk()
    before = W.compiled_programs()
    other = _tiny_walk.rollout(friction=(0.8, 1.0), stance_noise=(0.0, 0.0))
    assert W.compiled_programs() == before
    assert not other.log.fallen.any()
    # the second robot no longer lands off by a 1 cm stance error: its steps move
    assert np.abs(other.footsteps[1] - first.footsteps[1]).max() > 1e-4


@pytest.mark.slow
def test_capture_point_stepping_moves_pushed_steps_and_they_land_where_sent():
    """``WalkConfig.capture_gain`` (its own compiled walker): under 10 N s pushes the next steps move with the
    capture point's lead (the selector's footholds differ from the default walker's on the same pushes), and
    the robots still land where they were sent, without falling."""
    from ijoy_jax.sim.controller import WalkConfig

    f = _tiny_walk.field()
    sim = W.make_sim(f.shape, f.resolution, cfg=WalkConfig(capture_gain=1.0), robot=ij.robots.hrp2(margin=0.02))
    fields, robots, starts, commands, _ = _tiny_walk.inputs()
    dyn = physics.Dynamics(push=jnp.array([10.0, 10.0]))
    args = (fields, robots, starts, commands)
    kw = dict(num_steps=_tiny_walk.STEPS, frames_per_step=_tiny_walk.FRAMES, dynamics=dyn, key=3)
    moved = jax.tree_util.tree_map(np.asarray, W.rollout_batch(sim, *args, **kw))
    plain = jax.tree_util.tree_map(np.asarray, W.rollout_batch(_tiny_walk.sim(), *args, **kw))
    assert not moved.log.fallen.any() and moved.taken.all()
    assert moved.log.placement_error.max() < PLACEMENT_TOL, moved.log.placement_error
    shift = np.abs(moved.commanded[..., :2] - plain.commanded[..., :2])
    assert shift[:, 0].max() < 1e-5  # the first decision follows a standing step: nothing to catch yet
    assert 1e-3 < shift.max() <= sim.cfg.capture_max + 0.05  # moved; by at most the cap (+ the lattice's pick)


@pytest.mark.slow
def test_the_swing_adjustment_moves_pushed_touch_downs_within_the_step():
    """``WalkConfig.swing_adjust`` (its own compiled walker): under the same 10 N s pushes, the first decision is
    the default walker's (it follows a standing step), but pushed feet come down away from the selector's
    footholds, by up to ``capture_max`` (the default walker lands within PLACEMENT_TOL of them), and no robot
    falls."""
    from ijoy_jax.sim.controller import WalkConfig

    f = _tiny_walk.field()
    sim = W.make_sim(f.shape, f.resolution, cfg=WalkConfig(swing_adjust=2.0), robot=ij.robots.hrp2(margin=0.02))
    fields, robots, starts, commands, _ = _tiny_walk.inputs()
    kw = dict(num_steps=_tiny_walk.STEPS, frames_per_step=_tiny_walk.FRAMES,
              dynamics=physics.Dynamics(push=jnp.array([10.0, 10.0])), key=3)
    args = (fields, robots, starts, commands)
    moved = jax.tree_util.tree_map(np.asarray, W.rollout_batch(sim, *args, **kw))
    plain = jax.tree_util.tree_map(np.asarray, W.rollout_batch(_tiny_walk.sim(), *args, **kw))
    assert not moved.log.fallen.any() and moved.taken.all()
    np.testing.assert_allclose(moved.commanded[:, 0], plain.commanded[:, 0], atol=1e-5)
    assert plain.log.placement_error.max() < PLACEMENT_TOL
    assert PLACEMENT_TOL < moved.log.placement_error.max() <= sim.cfg.capture_max + PLACEMENT_TOL


def _bound_ends(name):
    """A field's two ends as float32 (the smallest float32 above a strict lower bound)."""
    b = physics.BOUNDS[name]
    lo = np.nextafter(np.float32(b.lo), np.float32(1)) if b.strict else np.float32(b.lo)
    return np.array([lo, b.hi], np.float32)


@pytest.mark.parametrize("name", physics.FIELDS)
def test_every_dynamics_field_at_both_ends_of_its_bounds_walks_or_falls_flagged_never_nan(name):
    """The documented bounds are simulated: friction 0 once gave NaN footsteps and distances, unflagged, and
    the boundary refused float32(0.1) s of latency, its own upper bound. A diverged simulation ends as a
    flagged fall; the same compiled program serves every value."""
    _tiny_walk.walk()  # the shared program, compiled once per process
    before = W.compiled_programs()
    fields, robots, starts, commands, _ = _tiny_walk.inputs()
    dyn = physics.Dynamics(**{name: jnp.asarray(_bound_ends(name))})
    traj = W.rollout_batch(_tiny_walk.sim(), fields, robots, starts, commands, num_steps=_tiny_walk.STEPS,
                           frames_per_step=_tiny_walk.FRAMES, dynamics=dyn, key=0)
    traj = jax.tree_util.tree_map(np.asarray, traj)
    assert W.compiled_programs() == before
    assert not traj.log.dynamics_invalid.any()  # in bounds: used as given, not replaced
    for path, leaf in jax.tree_util.tree_leaves_with_path(traj):
        if leaf.dtype.kind == "f":  # costs may be +inf (an invalid foothold); nothing is NaN
            assert not np.isnan(leaf).any(), (name, jax.tree_util.keystr(path))
    for key, value in W.summary(traj).items():
        assert np.isfinite(np.asarray(value, np.float64)).all(), (name, key)


def test_a_nan_terrain_is_refused_where_concrete_and_stands_flagged_where_traced():
    """sim.walker's boundary refuses what ij.rollout's does; inside a trace (the module's jit, as a caller's jit
    reaches it, unchecked) a NaN height makes every decision of that robot unsupported, and the robot stands
    on finite stand-in heights: no NaN in its footsteps or landed soles, the other robot's walk unchanged."""
    fields, robots, starts, commands, dyn = _tiny_walk.inputs()
    bad = fields.replace(height=fields.height.at[0, 5, 5].set(jnp.nan))
    with pytest.raises(ValueError, match="terrain.height must be finite"):
        W.rollout_batch(_tiny_walk.sim(), bad, robots, starts, commands, num_steps=_tiny_walk.STEPS,
                        frames_per_step=_tiny_walk.FRAMES, dynamics=dyn, key=0)
    one = jax.tree_util.tree_map(lambda a: a[0], bad)
    with pytest.raises(ValueError, match="terrain.height must be finite"):
        W.rollout(_tiny_walk.sim(), one, ij.robots.hrp2(), _tiny_walk.START, commands[0], num_steps=1)
    # The heights must be NaN inside the program, past the boundary's concrete check: a caller's jit around
    # W.rollout_batch does that, but compiles a program of its own (minutes on a CPU); the boundary's jitted
    # program itself (W._rollout_batch, the shared tiny program's) takes the NaN heights as they are.
    first = jnp.ones(2, jnp.float32)
    dyn = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(jnp.asarray(x, jnp.float32), (2,)), dyn)  # as given
    traj = W._rollout_batch(_tiny_walk.sim(), bad, robots, jnp.asarray(starts, jnp.float32),
                            jnp.asarray(commands, jnp.float32), first, None, dyn, checks.rollout_keys(0, 2),
                            ij.SelectOptions(), num_steps=_tiny_walk.STEPS, frames_per_step=_tiny_walk.FRAMES)
    traj = jax.tree_util.tree_map(np.asarray, traj)
    assert traj.unsupported[0].all() and not traj.taken[0].any() and not traj.unsupported[1].any()
    for path, leaf in jax.tree_util.tree_leaves_with_path(traj):
        if leaf.dtype.kind == "f":
            assert not np.isnan(leaf).any(), jax.tree_util.keystr(path)
    np.testing.assert_array_equal(traj.footsteps[1], _tiny_walk.walk().footsteps[1])


def test_the_boundary_checks_pass_through_a_callers_trace_with_traced_and_concrete_leaves_mixed():
    """Under a user's jit one traced Dynamics leaf or terrain leaf beside concrete ones once failed at the
    boundary (TracerArrayConversionError: the concrete values were checked with jnp, staged into the trace). The
    boundary checks concrete leaves with NumPy and skips traced ones, so it goes on to the next check: a bad
    ``commands`` shape is still named, before any physics is traced."""
    fields, robots, starts, commands, _ = _tiny_walk.inputs()
    sim = _tiny_walk.sim()  # built outside the trace: a Sim is static

    def walk(friction, origin):
        dyn = physics.Dynamics(friction=friction, latency=0.01, push=np.zeros(2))  # traced beside concrete
        return W.rollout_batch(sim, fields.replace(origin=origin), robots, starts, commands[:, :2],
                               num_steps=_tiny_walk.STEPS, frames_per_step=_tiny_walk.FRAMES, dynamics=dyn, key=0)

    with pytest.raises(ValueError, match="commands must have shape"):
        jax.make_jaxpr(walk)(jnp.array([1.0, 0.5]), fields.origin)
    with pytest.raises(ValueError, match="dynamics.latency must be finite"):  # a concrete bad value, still named
        jax.make_jaxpr(lambda f: W.rollout_batch(
            sim, fields, robots, starts, commands, num_steps=_tiny_walk.STEPS,
            frames_per_step=_tiny_walk.FRAMES, dynamics=physics.Dynamics(friction=f, latency=np.nan), key=0))(
            jnp.ones(2))



def test_a_dynamics_leaf_written_as_a_list_is_one_leaf_per_rollout():
    """``Dynamics(friction=[f, 0.5])`` with a traced ``f`` reached NumPy at the boundary
    (TracerArrayConversionError), and ``kp_scale=[1.0, 1.1]`` for two rollouts was mapped value by value into a
    broadcasting error deep in MJX: a list is a pytree node, not a leaf. The rollouts take it as one (B,) array:
    the traced one passes the boundary to the next check, a concrete one is checked and batched as an array."""
    fields, robots, starts, commands, _ = _tiny_walk.inputs()
    sim = _tiny_walk.sim()

    def walk(f):
        dyn = physics.Dynamics(friction=[f[0], 0.5], kp_scale=[1.0, 1.1])
        return W.rollout_batch(sim, fields, robots, starts, commands[:, :2], num_steps=_tiny_walk.STEPS,
                               frames_per_step=_tiny_walk.FRAMES, dynamics=dyn, key=0)

    with pytest.raises(ValueError, match="commands must have shape"):
        jax.make_jaxpr(walk)(jnp.ones(2))
    with pytest.raises(ValueError, match="dynamics.kp_scale must be finite"):  # each value still checked
        W.rollout_batch(sim, fields, robots, starts, commands, num_steps=_tiny_walk.STEPS,
                        frames_per_step=_tiny_walk.FRAMES, dynamics=physics.Dynamics(kp_scale=[1.0, 20.0]), key=0)
    dyn = physics.array_leaves(physics.Dynamics(friction=[1.0, 0.6], kp_scale=(1.0, 1.1), latency=0.01))
    for name in ("friction", "kp_scale"):
        leaf = getattr(dyn, name)
        assert jax.tree_util.tree_structure(leaf).num_leaves == 1 and leaf.shape == (2,) and leaf.dtype == jnp.float32
    assert dyn.latency == 0.01  # anything else as given
    assert len(jax.tree_util.tree_leaves(dyn)) == len(physics.FIELDS)  # one leaf per field, as an array's

@pytest.fixture(scope="module")
def sim():
    return W.make_sim(SHAPE_2D, RES, robot=ij.robots.hrp2())


@pytest.fixture(scope="module")
def runs(sim):
    scs = scenarios_2d()
    scs = {k: scs[k] for k in NAMES[:3]}
    scs["flat-forward"] = scenario(np.ones(SHAPE_2D, bool), start=_start(), command=FORWARD_CMDS)
    traj = W.rollout_batch(sim, *_batch(scs.values()), num_steps=STEPS_2D, options=ij.SelectOptions(method="ordered"),
                           frames_per_step=FRAMES)
    traj = jax.tree_util.tree_map(np.asarray, traj)
    return {k: (sc, jax.tree_util.tree_map(lambda a, i=i: a[i], traj)) for i, (k, sc) in enumerate(scs.items())}


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_no_fall_no_obstacle_touched(runs, name):
    _, traj = runs[name]
    assert traj.taken.all() and not traj.log.fallen.any()
    assert not traj.log.obstacle_contact.any()  # neither the soles nor the shins touched an obstacle cell
    assert traj.log.placement_error.max() < PLACEMENT_TOL, traj.log.placement_error


@pytest.mark.slow
def test_wall_approach_then_step_in_place(runs):
    sc, traj = runs["wall-m0.05-x1.44"]
    front = traj.footsteps[:, 0] + HL  # the feet face +x (no turning command)
    assert front.max() < sc.info["wall_x"]  # never on the wall
    # but up close: within the margin, one cell and one lattice step (as the perfect robot), plus the placement error
    assert front.max() > sc.info["wall_x"] - sc.margin - (RES + 0.05) - PLACEMENT_TOL
    # and marking time there: the selector plans from the measured stance, which drifts back ~1 mm a step (the
    # DCM feedback's CoP shift), so now and then a lattice step forward fits the margin again and is taken. Which
    # steps those are turns on that millimetre (measured: with XLA's default CPU emitters 6 of the last 8 steps
    # were the step in place p0 and two went 5 cm forward and back; with the suite's classic emitters 5 steps in
    # place, then one foot 5 cm ahead and each foot put back where it stood: 3 of the last 8 in place). So: each
    # of the last 8 steps puts its foot back within a few mm or one lattice step (5 cm) away, at most 3 move it,
    # and the feet make no progress.
    x = traj.commanded[-10:, 0]
    moved = np.abs(x[2:] - x[:-2])  # each foot against its own previous step (the sides alternate)
    assert (traj.sides[-10:][2:] == traj.sides[-10:][:-2]).all()
    assert moved.max() < 0.05 + PLACEMENT_TOL and (moved > 0.01).sum() <= 3, moved
    assert abs(x[-2:].mean() - x[:2].mean()) < 0.05 + PLACEMENT_TOL


@pytest.mark.slow
def test_steps_over_the_obstacle(runs):
    sc, traj = runs["over-m0.02-b0.04-x1.0"]
    x1 = sc.info["obstacle"][1]
    assert traj.feet[:, 0].min() > x1 + HL  # both feet beyond the obstacle's far edge at the end


@pytest.mark.slow
def test_turns_on_the_spot(runs):
    sc, traj = runs["turn-1"]
    heading = np.unwrap(traj.footsteps[:, 2])
    assert abs(heading[-1] - heading[0]) > 0.5 * abs(sc.info["rot"]) * (len(heading) - 1) / 2
    assert np.ptp(traj.footsteps[:, :2], axis=0).max() < 0.5  # on the spot: the feet stay within half a metre


@pytest.mark.slow
def test_steps_in_place_then_walks_forward(runs):
    _, traj = runs["flat-forward"]
    assert traj.valid.all() and not traj.stopped.any()
    assert traj.in_place[:2].all()  # a zero command on flat ground: the step-in-place action p0
    np.testing.assert_allclose(np.diff(traj.commanded[2:, 0]), 0.2, atol=0.03)  # each 0.2 m ahead of the last
    assert traj.footsteps[-1, 0] - traj.footsteps[0, 0] > 0.2 * (STEPS_2D - 3) - 3 * PLACEMENT_TOL


@pytest.mark.slow
def test_footsteps_are_the_measured_touch_downs(runs):
    _, traj = runs["flat-forward"]
    np.testing.assert_allclose(traj.footsteps, traj.log.landed[:, [0, 1, 5]], atol=1e-6)
    err = np.hypot(*(traj.footsteps[:, :2] - traj.commanded[:, :2]).T)
    np.testing.assert_allclose(err, traj.log.placement_error, atol=1e-5)
    assert traj.sides.tolist() == [1, -1] * (STEPS_2D // 2)


@pytest.mark.slow
def test_summary(runs):
    _, traj = runs["flat-forward"]
    s = {k: np.asarray(v) for k, v in W.summary(traj).items()}
    assert not s["fell"] and s["obstacle_contacts"] == 0 and s["steps_taken"] == STEPS_2D
    assert np.isfinite(s["placement_error_p95"]) and s["placement_error_p95"] < PLACEMENT_TOL


@pytest.mark.slow
def test_recorded_states_end_at_the_touch_downs(runs, sim):
    """The last state kept of each step is the one whose sole gave ``log.landed`` (host forward kinematics).

    ``landed`` reads MJX's site positions, computed before the last physics step's integration: the
    sole can move by its touch-down speed times 2 ms (measured 0.12 mm), hence 1 mm.
    """
    _, traj = runs["flat-forward"]
    assert traj.log.qpos.shape == (STEPS_2D, FRAMES, sim.mj_model.nq)
    np.testing.assert_array_equal(W.frame_ticks(sim, FRAMES), [19, 39, 59, 79])
    data = mujoco.MjData(sim.mj_model)
    for k in range(STEPS_2D):
        data.qpos[:] = traj.log.qpos[k, -1]
        mujoco.mj_kinematics(sim.mj_model, data)
        row = 0 if traj.sides[k] > 0 else 1
        np.testing.assert_allclose(data.site_xpos[sim.index.sole_site[row], :2], traj.log.landed[k, :2], atol=1e-3)


@pytest.mark.slow
def test_renders_the_robot_where_it_walks(runs, sim):
    sc, traj = runs["flat-forward"]
    q = render.states(traj)
    assert q.shape == (STEPS_2D * FRAMES, sim.mj_model.nq)
    pick = q[[0, len(q) - 1]]
    robot_geoms = np.flatnonzero(sim.mj_model.geom_bodyid > 0)
    # Tracking camera: the robot stays in view, near the middle of the image, at both ends of the walk.
    seg = render.render(sim, sc.terrain(), q, width=160, height=120, segmentation=True, smooth=5)
    for s in seg[[0, -1]]:
        rows, cols = np.nonzero(np.isin(s, robot_geoms))
        assert rows.size > 200  # pixels of the robot
        assert abs(cols.mean() - 80) < 30
    # A fixed camera looking along -y at the start: the robot walks +x, so it moves right in the image.
    fixed = render.render(sim, sc.terrain(), pick, width=160, height=120, segmentation=True, track=False,
                          azimuth=90.0, elevation=-10.0, distance=5.0)
    cols = [np.nonzero(np.isin(s, robot_geoms))[1].mean() for s in fixed]
    assert cols[1] > cols[0] + 20
    rgb = render.render(sim, sc.terrain(), pick[:1], width=160, height=120, footsteps=traj.commanded[:4],
                        sides=traj.sides[:4])
    plain = render.render(sim, sc.terrain(), pick[:1], width=160, height=120)
    assert rgb.shape == (1, 120, 160, 3) and rgb.dtype == np.uint8
    assert np.abs(rgb.astype(int) - plain).sum(-1).astype(bool).sum() > 50  # the commanded footholds are drawn


def test_headless_rendering_without_egl_says_what_to_set():
    # render checks for a GL context first, before it reads its arguments
    code = "import mujoco\nfrom ijoy_jax.sim import render\nrender.render(None, None, None)"
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "DISPLAY")}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode != 0 and "MUJOCO_GL=egl" in out.stderr


@pytest.mark.slow
def test_margins_in_clutter_reuse_the_compiled_rollout(runs, sim):
    """Margins 0 and 10 cm on two clutter maps (sweeps/margin_physics.toml's clutter), the same maps and commands
    at each: 4 rollouts of the scenarios' shapes, so the same program (no new compile)."""
    params = generators.ObstacleParams(count=14, size_min=0.04, size_max=0.12)
    maps = jax.vmap(lambda k: generators.obstacles(k, params, shape=SHAPE_2D, resolution=RES, max_count=16))(
        jax.random.split(jax.random.key(3), 2))
    terrains = jax.tree_util.tree_map(lambda a: jnp.concatenate([a, a]), maps)
    robots = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *[ij.robots.hrp2(margin=m, w=1.0)
                                                                for m in (0.0, 0.0, 0.10, 0.10)])
    x, y = np.asarray(generators.start_point(params, shape=SHAPE_2D, resolution=RES))
    starts = jnp.stack([ij.robots.start_stance(ij.robots.hrp2(), x, y)] * 4)
    commands = jnp.broadcast_to(jnp.asarray([0.2, 0.0, 0.0], jnp.float32), (4, STEPS_2D, 3))
    before = W.compiled_programs()
    traj = jax.tree_util.tree_map(np.asarray, W.rollout_batch(sim, terrains, robots, starts, commands,
                                                              ij.SelectOptions(method="ordered"), num_steps=STEPS_2D,
                                                              frames_per_step=FRAMES))
    assert W.compiled_programs() == before
    s = {k: np.asarray(v) for k, v in W.summary(traj).items()}
    assert not s["fell"].any() and (s["steps_taken"] == STEPS_2D).all()
    # 10 cm is far beyond the placement error: nothing touched, no foothold on an obstacle
    assert s["obstacle_contacts"][2:].sum() == 0 and s["footholds_on_obstacles"][2:].sum() == 0
    assert s["obstacle_contacts"][:2].sum() >= s["obstacle_contacts"][2:].sum()
    assert (s["distance_along"][:2] >= s["distance_along"][2:] - 0.05).all()  # a wider margin never opens a path
    assert not maps.has_height and (~np.asarray(maps.free[0])).sum() > 50  # clutter, raised in the physics


def test_bad_inputs_are_refused_before_compiling(sim):
    robot = ij.robots.hrp2()
    wrong = ij.terrain.from_arrays(np.zeros((50, 50)), None, 0.02).replace(has_height=True)
    with pytest.raises(ValueError, match="does not match"):
        W.rollout(sim, wrong, robot, np.zeros((2, 3)), np.zeros(3), num_steps=1)
    good = ij.terrain.from_arrays(np.zeros(sim.shape), None, RES).replace(has_height=True)
    with pytest.raises(ValueError, match="step_time"):
        W.rollout(sim, good, ij.robots.hrp2(step_time=0.6), np.zeros((2, 3)), np.zeros(3), num_steps=1)
    with pytest.raises(ValueError, match="frames_per_step"):
        W.rollout(sim, good, robot, np.zeros((2, 3)), np.zeros(3), num_steps=1, frames_per_step=81)
    batch = jax.tree_util.tree_map(lambda a: jnp.stack([a, a]), good)
    robots2 = jax.tree_util.tree_map(lambda a: jnp.stack([a, a]), robot)
    with pytest.raises(ValueError, match="starts must have shape"):
        W.rollout_batch(sim, batch, robots2, np.zeros((3, 2, 3)), np.zeros((3, 3)), num_steps=1)
    with pytest.raises(ValueError, match="commands must have shape"):
        W.rollout_batch(sim, batch, robots2, np.zeros((2, 2, 3)), np.zeros((2, 4, 3)), num_steps=2)
    slow = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), robot, ij.robots.hrp2(step_time=0.6))
    with pytest.raises(ValueError, match="step_time"):
        W.rollout_batch(sim, batch, slow, np.zeros((2, 2, 3)), np.zeros((2, 3)), num_steps=1)
    with pytest.raises(ValueError, match="dynamics.friction must be finite, >= 0"):
        W.rollout_batch(sim, batch, robots2, np.zeros((2, 2, 3)), np.zeros((2, 3)), num_steps=1,
                        dynamics=physics.Dynamics(friction=np.array([1.0, -1.0])))
    with pytest.raises(ValueError, match=r"dynamics.push must be a scalar or shape \(2,\)"):
        W.rollout_batch(sim, batch, robots2, np.zeros((2, 2, 3)), np.zeros((2, 3)), num_steps=1,
                        dynamics=physics.Dynamics(push=np.zeros(3)))
    with pytest.raises(ValueError, match="key must be one PRNG key"):
        W.rollout_batch(sim, batch, robots2, np.zeros((2, 2, 3)), np.zeros((2, 3)), num_steps=1,
                        key=jax.random.split(jax.random.key(0), 3))
    with pytest.raises(ValueError, match="dynamics.latency must be finite"):
        W.rollout(sim, good, robot, np.zeros((2, 3)), np.zeros(3), num_steps=1, dynamics=physics.Dynamics(latency=1.0))
    with pytest.raises(ValueError, match="no states"):
        render.states(SimpleNamespace(log=SimpleNamespace(qpos=np.zeros((3, 0, 19)))))  # rolled out with 0 frames


@pytest.mark.parametrize("argv, message", [
    (["sim", "render", "--size", "big"], "argument --size: takes WIDTHxHEIGHT"),
    (["sim", "render", "--frames", "200", "--steps", "1"], "frames_per_step"),
])
def test_cli_refuses_bad_arguments_before_compiling(argv, message, capsys):
    from ijoy_jax.apps import cli

    assert cli.main(argv) == 2
    assert message in capsys.readouterr().err


def test_gif_and_filmstrip(tmp_path):
    from PIL import Image

    frames = np.zeros((5, 12, 16, 3), np.uint8)
    frames[np.arange(5), :, np.arange(5) * 3] = 255  # a white column moving right, one per frame
    render.write_gif(tmp_path / "a.gif", frames, fps=10)
    with Image.open(tmp_path / "a.gif") as gif:
        assert gif.n_frames == 5 and gif.size == (16, 12)
        gif.seek(4)
        assert np.asarray(gif.convert("RGB"))[:, 12].min() == 255
    strip = render.filmstrip(frames, count=3, columns=2)  # frames 0, 2, 4 on two rows, one blank tile
    assert strip.shape == (24, 32, 3)
    np.testing.assert_array_equal(strip[:12, :16], frames[0])
    np.testing.assert_array_equal(strip[:12, 16:], frames[2])
    np.testing.assert_array_equal(strip[12:, :16], frames[4])
    assert not strip[12:, 16:].any()
    with pytest.raises(ValueError, match="uint8"):
        render.write_gif(tmp_path / "b.gif", frames.astype(np.float32))


@pytest.mark.slow
def test_refine_reaches_the_simulated_walker(sim):
    """``refine=True`` puts the continuous refinement (:mod:`ijoy_jax.refine`, tested with the perfect robot in
    tests/test_refine.py) into the MJX rollout's decisions: traced, not compiled (a compile costs ~75 s here),
    the program gains the refinement's search and keeps the same outputs; a refine that is neither a bool nor a
    RefineParams is refused as the options are built."""
    sc = scenario(np.ones(SHAPE_2D, bool), start=_start(), command=FORWARD_CMDS)
    args = (sim, sc.terrain(), ij.robots.hrp2(margin=sc.margin), jnp.asarray(sc.start), jnp.asarray(sc.commands[:2]))

    def traced(refine):
        options = ij.SelectOptions(method="ordered", refine=refine)
        return jax.make_jaxpr(lambda *a: W.rollout(sim, *a, options, num_steps=2))(*args[1:])

    plain, refined = traced(False), traced(True)
    assert len(str(refined)) > len(str(plain)) + 1000  # the refinement's local search is in the program
    assert jax.tree_util.tree_structure(refined.out_avals) == jax.tree_util.tree_structure(plain.out_avals)
    with pytest.raises(TypeError, match="refine must be a bool or an ijoy_jax.refine.RefineParams"):
        W.rollout(*args, ij.SelectOptions(refine="yes"), num_steps=2)


@pytest.mark.slow
def test_the_biped_starts_standing_on_rough_ground_with_no_flat_pad():
    """Issue #48: no flat pad under the feet. Two robots on 1.5 cm RMS rough maps with ``start_radius`` 0 (the
    ground under each start sole spans over a centimetre, from the terrain arrays): the walker stands each sole
    at its rest pose on the ground there and walks 6 steps held forward without falling, each step landing
    where it was sent on a tilted foothold."""
    shape, res = (100, 60), 0.02
    params = generators.RoughParams(amplitude=0.015, correlation_length=0.15, start_x=0.2, start_y=0.5,
                                    start_radius=0.0)
    fields = jax.vmap(lambda k: generators.rough(k, params, shape=shape, resolution=res, has_height=True))(
        jax.random.split(jax.random.key(7), 2))
    robot = ij.robots.hrp2(margin=0.02)
    x, y = np.asarray(generators.start_point(params, shape=shape, resolution=res))
    start = np.asarray(ij.robots.start_stance(robot, x, y))
    h = np.asarray(fields.height)
    # no pad: the cells under each start sole (its 24 x 13 cm rectangle) span more than a centimetre
    for b in range(2):
        for fx, fy, _ in start:
            i0, j0 = int(fx / res), int(fy / res)
            under = h[b, i0 - 6:i0 + 6, j0 - 3:j0 + 3]
            assert np.ptp(under) > 0.01, np.ptp(under)
    sim = W.make_sim(shape, res, robot=robot)
    commands = np.tile(np.array([[0.25, 0.0, 0.0]], np.float32), (2, 6, 1))
    traj = jax.tree_util.tree_map(np.asarray, W.rollout_batch(
        sim, fields, jax.vmap(lambda _: robot)(jnp.arange(2)), np.stack([start, start]), commands, num_steps=6,
        frames_per_step=2, key=0))
    assert not traj.log.fallen.any()
    assert traj.taken.sum(axis=1).min() >= 5, traj.taken  # measured: all 6 taken
    assert traj.log.placement_error.max() < PLACEMENT_TOL, traj.log.placement_error  # measured 0.74 cm
    progress = traj.footsteps[:, -1, 0] - start[:, 0].mean()
    assert progress.min() > 0.4, progress  # measured 0.86 and 1.12 m: it walks, not only marks time
    tilt = np.degrees(np.abs(traj.footholds[..., 3:5])).max(axis=(1, 2))
    assert tilt.min() > 1.0, tilt  # the footholds rest tilted on the ground (measured 6.6 and 9.6 deg)

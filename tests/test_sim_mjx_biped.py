"""The MJX biped stepped tick by tick (ijoy_jax.sim.mjx_biped): the scanned rollout's steps, compiled once.

MJX compiles slowly on a CPU (the reference rollout and the robot's seven programs: 58 s here), so every robot here
walks the small map of the live tests (tests/_server_util.py: 40 x 32 cells at 5 cm) as a 2.5D map, the map
``ijoy drive --robot mjx --terrain flat --height`` walks in tests/test_live.py: one Sim, one set of the robot's
programs for the file and that drive (in memory, or through the persistent compilation cache), and one
reference rollout program (three steps) for both maps, flat and rough.

The rollout and the robot compile the same operations into one program and into seven: XLA fuses and
vectorises them differently, so their float32 roundings differ (with XLA's default CPU emitters the preview
servo's error sum already differs by 2e-5 relative when the robot stands), and the contacts amplify the
difference step by step; hence the tolerances below. One robot is deterministic, bit for bit.
"""

import dataclasses

import jax
import numpy as np
import pytest
from _server_util import RES, SHAPE  # tests/ is on sys.path (pytest rootdir import)

import ijoy_jax as ij
from ijoy_jax import live, robots
from ijoy_jax.sim import mjx_biped, physics
from ijoy_jax.sim import walker as W

STEPS = 3
COMMANDS = np.array([[0.25, 0.0, 0.0]] * STEPS, np.float32)  # full forward: 0.2 m steps
# Rollout against robot after three steps on these maps (measured): with the classic CPU emitters the tests compile
# with (tests/conftest.py), the landed soles within 0.006 mm and 0.013 mrad, the feet within 0.01 mm and 0.12 mrad;
# with XLA's default fusion emitters the landed soles within 0.11 mm and 0.16 mrad, the feet within 0.5 mm, and the
# stance sole's yaw within 3.8 mrad (it pivots on the ground while the other foot swings; stick-slip makes it the
# most sensitive number). The tolerances hold for both. For scale: the rollout's own feet move by 0.015 mm and
# 0.1 mrad when its start moves by one float32 ulp, its vmapped twin (rollout_batch) differs by 0.01 mm and 0.13
# mrad, and a 10 ms control delay (physics.Dynamics.latency) moves the feet by 3 to 7 mm.
POSITION_TOL = 1e-3  # m
ANGLE_TOL = 1e-2  # rad
SOLE_TOL = np.array([POSITION_TOL] * 3 + [ANGLE_TOL] * 3)  # x, y, z, roll, pitch, yaw
FEET_TOL = np.array([POSITION_TOL, POSITION_TOL, ANGLE_TOL])  # x, y, yaw
MAPS = ("flat", "rough")


def _within(got, want, tol, what):
    """|got - want| < tol elementwise (tol broadcast over the last axis), naming the largest difference."""
    diff = np.abs(np.asarray(got, np.float64) - np.asarray(want, np.float64))
    assert np.all(diff < tol), f"{what}: differences {diff.tolist()} against tolerances {np.asarray(tol).tolist()}"


def _spec(family):
    return {"kind": "family", "family": family, "seed": 1, "shape": list(SHAPE), "resolution": RES,
            "has_height": True}


@pytest.fixture(scope="module")
def sim():
    return W.make_sim(SHAPE, RES, robot=robots.hrp2())


@pytest.fixture(scope="module")
def walks(sim):
    """Per map: the terrain, robot and start (as ``ijoy drive`` opens them), the scanned rollout (walker.rollout,
    3 steps of COMMANDS) and an MjxBiped sent the rollout's footholds: its stance before each decision, its
    StepLogs and its feet after each step."""
    out = {}
    for name in MAPS:
        terrain, robot, start = live.open_terrain(_spec(name))
        traj = jax.tree_util.tree_map(np.asarray, W.rollout(sim, terrain, robot, start, COMMANDS, num_steps=STEPS))
        biped = mjx_biped.MjxBiped(sim, terrain, robot, start)
        warm = biped.execute(np.zeros(6, np.float32), False)  # the rollout's warm-up step: it stands
        stances, logs, feet = [], [], []
        for k in range(STEPS):
            stances.append(biped.stance())
            logs.append(biped.execute(traj.footholds[k], bool(traj.taken[k])))
            feet.append(biped.feet())
        out[name] = dict(terrain=terrain, robot=robot, start=start, traj=traj, biped=biped, warm=warm,
                         stances=stances, logs=logs, feet=np.stack(feet))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", MAPS)
def test_steps_are_the_rollouts(walks, name):
    """Sent the footholds the scanned rollout chose, the robot stepped tick by tick lands where the rollout's did,
    with the same StepLog, and ends with the same feet (to the rounding above)."""
    w = walks[name]
    traj, biped, logs = w["traj"], w["biped"], w["logs"]
    assert traj.taken.all() and not traj.log.fallen.any()  # the premise: three steps walked
    assert not w["warm"].fallen and float(w["warm"].placement_error) == 0.0  # the warm-up stood
    landed = np.stack([g.landed for g in logs])
    _within(landed, traj.log.landed, SOLE_TOL, "landed soles")
    swung = w["feet"][np.arange(STEPS), (traj.sides < 0).astype(int)]  # (STEPS, 3) the swing foot after each step
    _within(swung, traj.footsteps, FEET_TOL, "footsteps")
    _within(biped.feet(), traj.feet, FEET_TOL, "final feet")
    for field, tol in (("placement_error", POSITION_TOL), ("min_pelvis_height", POSITION_TOL),
                       ("yaw_error", ANGLE_TOL), ("tilt_error", ANGLE_TOL), ("max_tilt", ANGLE_TOL)):
        np.testing.assert_allclose([float(getattr(g, field)) for g in logs], getattr(traj.log, field), atol=tol,
                                   err_msg=field)
    for field in ("fallen", "obstacle_contact", "dynamics_invalid"):
        assert [bool(getattr(g, field)) for g in logs] == getattr(traj.log, field).tolist(), field
    assert biped.swing == -1.0 and not biped.fallen and biped.time == pytest.approx(0.8 * (STEPS + 1))
    assert w["feet"][-1, :, 0].mean() - w["start"][:, 0].mean() > 0.15  # it walked forward (0.5 m on flat ground)


@pytest.mark.slow
@pytest.mark.parametrize("name", MAPS)
def test_decides_as_the_rollout(walks, name):
    """The robot's stance (what a drive's decision starts from) is the rollout's: select_step on it with the same
    command chooses the rollout's action each step."""
    w = walks[name]
    for k, info in enumerate(w["stances"]):
        assert info.stance_side == (-1.0 if k % 2 == 0 else 1.0)  # the left foot swings first
        choice = ij.select_step(w["terrain"], w["robot"], info.stance, int(info.stance_side), COMMANDS[k],
                                swing_from=info.swing_from)
        assert bool(choice.valid) and int(choice.index) == int(w["traj"].index[k]), k
        _within(choice.foothold, w["traj"].footholds[k], SOLE_TOL, f"foothold {k}")


@pytest.mark.slow
def test_compiled_once_and_deterministic(walks, sim):
    """A second robot (another map, start, first foot, dynamics and key) and more steps compile nothing; two robots
    given the same inputs end in the same state, bit for bit (what a drive's replay relies on)."""
    w = walks["rough"]
    start = np.asarray(robots.start_stance(w["robot"], 0.5, 0.75), np.float32)
    dyn = physics.Dynamics(friction=0.8, mass_scale=1.1, latency=0.01, stance_noise=0.002, push=2.0)
    finals = []
    for i in range(2):
        biped = mjx_biped.MjxBiped(sim, w["terrain"], w["robot"], start, -1, dynamics=dyn, key=7)
        biped.warm_up()  # every program a drive calls (the fixture's robots called all but measured_soles)
        if i == 0:
            before = mjx_biped.compiled_programs()
            assert before >= 1
        biped.execute(np.zeros(6, np.float32), False)
        info = biped.stance()
        assert info.stance_side == 1.0  # the right foot swings first
        foothold = np.concatenate([info.swing_from[:2] + [0.1, 0.0], [0.0, 0.0, 0.0], info.swing_from[2:]])
        biped.execute(foothold.astype(np.float32), True)
        finals.append(jax.tree_util.tree_leaves((biped.state.data, biped.state.soles, biped.state.ctrl)))
    assert mjx_biped.compiled_programs() == before
    for a, b in zip(*finals, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.slow
def test_future_stance_is_the_foot_in_flight(walks, sim):
    """During a step the next decision's stance is the swinging foot where it was sent (ComputeStanceLocation);
    standing, or sent a non-finite foothold, it is the stance now."""
    w = walks["flat"]
    biped = mjx_biped.MjxBiped(sim, w["terrain"], w["robot"], w["start"])
    biped.execute(np.zeros(6, np.float32), False)
    now = biped.stance()
    foothold = w["traj"].footholds[0]
    biped.begin(foothold, True)
    assert biped.stepping and biped.tick()
    nxt = biped.future_stance()
    np.testing.assert_allclose(nxt.stance[:2], foothold[:2], atol=0.01)  # rested on the ground: x, y as sent
    assert nxt.stance_side == 1.0 and np.array_equal(nxt.swing_from, now.stance)
    assert biped.feet().shape == (2, 3) and biped.qpos().shape == (biped.sim.mj_model.nq,)
    while biped.tick():
        pass
    biped.end()
    biped.begin(np.full(6, np.nan, np.float32), True)  # a non-finite foothold: it stands
    assert np.array_equal(biped.future_stance().stance, biped.stance().stance)
    while biped.tick():
        pass
    log = biped.end()
    assert float(log.placement_error) == 0.0 and not log.fallen and biped.swing == -1.0


# ------------------------------------------------------------------------------------------------ bad input

def _robot_args(sim):
    terrain, robot, start = live.open_terrain(_spec("flat"))
    return dict(sim=sim, terrain=terrain, robot=robot, start=start)


@pytest.mark.parametrize("change, error, match", [
    (lambda a: {"sim": "sim"}, TypeError, "sim must be an ijoy_jax.sim.walker.Sim"),
    (lambda a: {"terrain": np.zeros(SHAPE)}, TypeError, "terrain must be an ijoy_jax.terrain.Terrain"),
    (lambda a: {"terrain": jax.tree_util.tree_map(lambda x: np.stack([x, x]), a["terrain"])}, ValueError,
     "MjxBiped steps one robot on one terrain"),
    (lambda a: {"terrain": ij.terrain.flat((SHAPE[0], SHAPE[1] + 1), RES, has_height=True)}, ValueError,
     r"terrain grid \(40, 33\) at 0.05 m does not match the Sim's \(40, 32\)"),
    (lambda a: {"terrain": ij.terrain.flat(SHAPE, 0.04, has_height=True)}, ValueError, "does not match the Sim's"),
    (lambda a: {"robot": robots.hrp2(step_time=0.6)}, ValueError, "robot.step_time 0.6"),
    (lambda a: {"start": np.zeros((3, 3))}, ValueError, r"start must be finite \(2, 3\) feet"),
    (lambda a: {"start": np.full((2, 3), np.nan)}, ValueError, r"start must be finite \(2, 3\) feet"),
    (lambda a: {"first_swing": 0}, ValueError, r"first_swing must be \+1 \(left\) or -1"),
    (lambda a: {"first_swing": "left"}, ValueError, r"first_swing must be \+1 \(left\) or -1"),
    (lambda a: {"dynamics": physics.Dynamics(friction=-1.0)}, ValueError, "dynamics.friction must be finite"),
    (lambda a: {"dynamics": physics.Dynamics(push=np.zeros(2))}, ValueError, "dynamics.push must be a scalar"),
    (lambda a: {"key": jax.random.split(jax.random.key(0), 2)}, ValueError, "key must be one PRNG key"),
], ids=["sim", "not-a-terrain", "batch-of-terrains", "grid", "resolution", "step-time", "start-shape", "start-nan",
        "first-swing-0", "first-swing-str", "friction", "push-shape", "keys"])
def test_bad_input_is_refused_before_compiling(sim, change, error, match):
    args = _robot_args(sim)
    args.update(change(args))
    before = mjx_biped.compiled_programs()
    with pytest.raises(error, match=match):
        mjx_biped.MjxBiped(**args)
    assert mjx_biped.compiled_programs() == before


@pytest.mark.slow
def test_steps_out_of_order_are_refused(walks, sim):
    w = walks["flat"]
    biped = mjx_biped.MjxBiped(sim, w["terrain"], w["robot"], w["start"])
    with pytest.raises(RuntimeError, match="no step in progress"):
        biped.tick()
    with pytest.raises(RuntimeError, match="has not run all its ticks"):
        biped.end()
    with pytest.raises(ValueError, match=r"foothold must have shape \(6,\)"):
        biped.begin(np.zeros(3), True)
    biped.begin(np.zeros(6), False)
    with pytest.raises(RuntimeError, match="a step is in progress"):
        biped.begin(np.zeros(6), False)
    with pytest.raises(RuntimeError, match="has not run all its ticks"):
        biped.end()
    while biped.tick():
        pass
    with pytest.raises(RuntimeError, match="has run all its ticks"):
        biped.tick()
    biped.end()


def _ankle_speed(sim, terrain, robot, start, latency):
    """RMS tick-to-tick change (rad) of the four measured ankle joints (pitch and roll, both legs) of a robot
    standing three steps on low friction (0.45) with a control delay of ``latency`` s."""
    biped = mjx_biped.MjxBiped(sim, terrain, robot, start, dynamics=physics.Dynamics(friction=0.45, latency=latency))
    biped.execute(np.zeros(6, np.float32), False)  # the warm-up step
    ankles = []
    for _ in range(3):
        biped.begin(np.full(6, np.nan, np.float32), False)  # stand
        while True:
            more = biped.tick()
            ankles.append(biped.qpos()[[11, 12, 17, 18]])  # qpos[7:19]: each leg's 6 joints, the ankle's last two
            if not more:
                break
        assert not biped.end().fallen
    return float(np.sqrt(np.mean(np.diff(np.asarray(ankles), axis=0) ** 2)))


@pytest.mark.slow
def test_the_ankles_stay_steady_through_a_control_delay(walks, sim):
    """The ankles' damping control closes through the stiff ankle actuators at about 2 per 10 ms tick: without
    slowing it by the known delay (WalkConfig.ankle_delay, here made ineffective: the code before) a 20 ms delay
    makes the measured ankles of a standing robot move 1.9x as fast as without a delay (the rocking that felled
    22 % of delayed robots under Playground-like dynamics, docs/walk_families.md); slowed, 0.9x."""
    w = walks["flat"]
    args = (w["terrain"], w["robot"], w["start"])
    undelayed = _ankle_speed(sim, *args, 0.0)
    slowed = _ankle_speed(sim, *args, 0.02)
    unslowed = _ankle_speed(W.make_sim(SHAPE, RES, robot=robots.hrp2(),
                                       cfg=dataclasses.replace(sim.cfg, ankle_delay=1e9)), *args, 0.02)
    assert unslowed > 1.5 * undelayed, (unslowed, undelayed)  # measured 1.86x (1.35 against 0.73 mrad a tick)
    assert slowed < 1.15 * undelayed, (slowed, undelayed)  # measured 0.88x

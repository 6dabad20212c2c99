"""The G1 as a selector robot (ijoy_jax.robots.g1): every number derived again from its MJCF, and it walks.

The constants of ijoy_jax/robots/g1_model.py are held to what ijoy_jax.sim.description and ijoy_jax.sim.reach
derive from MuJoCo Menagerie's model: a change of the model or of the derivation shows up here.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

import ijoy_jax as ij
from ijoy_jax.robots import g1_model
from ijoy_jax.sim import description, menagerie, reach


@functools.cache
def g1_description() -> description.BipedDescription:
    m = menagerie.g1_spec(meshes=False).compile()
    return description.describe(m, soles=menagerie.G1_SOLES, keyframe=menagerie.G1_KEYFRAME)


def test_footprint_and_step_in_place_are_the_mjcfs():
    desc, robot = g1_description(), ij.robots.g1()
    np.testing.assert_allclose([float(robot.foot_length), float(robot.foot_width)], desc.sole_size, atol=1e-7)
    width = desc.soles[0, 1] - desc.soles[1, 1]  # the knees_bent keyframe's feet
    assert abs(width - g1_model.G1_P0[1]) < 0.005  # on the lattice's 2 cm grid
    np.testing.assert_allclose(robot.p0, g1_model.G1_P0, atol=1e-7)
    assert np.any(np.all(np.isclose(np.asarray(robot.actions), g1_model.G1_P0, atol=1e-6), axis=1))


def test_g1_defaults_are_the_leaves_of_g1():
    """Every scalar leaf of ``g1()`` read without building it (float32 leaves: equal to rounding), and its
    density; HRP-2's selector weights and metrics, the G1's body."""
    robot, d = ij.robots.g1(), ij.robots.g1_defaults()
    assert set(d) == set(ij.robots.SCALAR_LEAVES) | {"density"} and d["density"] == 1.0
    for name in ij.robots.SCALAR_LEAVES:
        assert float(ij.robots.get_leaf(robot, name)) == pytest.approx(d[name], rel=1e-7), name
    hrp2 = ij.robots.hrp2_defaults()
    assert {k for k in d if d[k] != hrp2[k]} == {"foot_length", "foot_width", "max_sole_pitch", "max_sole_roll",
                                                  "max_sole_distance", "step_time"}
    assert d["step_time"] == ij.robots.G1_STEP_TIME == 0.5


def test_every_action_is_realisable_by_both_legs_and_a_wider_lattice_is_not_needed():
    desc = g1_description()
    acts = np.asarray(ij.robots.g1().actions)
    assert acts.shape == (496, 3)
    assert reach.feasible(desc, acts, desc.stand_height).all()


def test_sole_limits_are_the_largest_tilts_and_reach_the_legs_realise_rounded_down():
    desc, robot = g1_description(), ij.robots.g1()
    acts = np.asarray(robot.actions)
    for axis, leaf in (("pitch", robot.max_sole_pitch), ("roll", robot.max_sole_roll)):
        derived = reach.realisable_tilt(desc, acts, desc.stand_height, axis)
        assert float(leaf) <= derived < float(leaf) + math.radians(0.5), (axis, math.degrees(derived))
    directions = np.arctan2(acts[:, 1], acts[:, 0])
    reaches = [reach.radial_reach(desc, desc.stand_height, float(a))
               for a in np.linspace(directions.min(), directions.max(), 9)]
    assert float(robot.max_sole_distance) == pytest.approx(min(reaches), abs=0.011)
    assert np.linalg.norm(acts[:, :2], axis=1).max() < float(robot.max_sole_distance)  # its own steps pass


def test_tilts_beyond_the_ankles_are_refused_by_the_legs():
    """The derivation can say no: a sole rolled by twice the ankle's range (+-0.26 rad in the MJCF), or pitched
    beyond it, is not realisable even in the step in place, and a step beyond the legs' reach is not either."""
    desc = g1_description()
    roll_range = desc.legs[0].upper[5]
    in_place = np.array([g1_model.G1_P0])
    assert reach.feasible(desc, in_place, desc.stand_height)[0]
    assert not reach.feasible(desc, in_place, desc.stand_height, tilt=(2 * roll_range, 0.0))[0]
    assert not reach.feasible(desc, in_place, desc.stand_height, tilt=(0.0, 1.2))[0]
    assert not reach.feasible(desc, np.array([[0.6, 0.24, 0.0]]), desc.stand_height)[0]


def test_the_g1_walks_forward_on_flat_ground_with_the_selector():
    robot = ij.robots.g1()
    terrain = ij.terrain.flat((150, 100), 0.02)
    full = 0.2 / float(robot.step_time)  # the full stick: the lattice's longest step (0.2 m) every 0.5 s
    traj = ij.rollout(terrain, robot, ij.robots.start_stance(robot, 0.3, 1.0), [full, 0.0, 0.0], num_steps=6)
    assert float(traj.summary()["distance_along"]) == pytest.approx(1.1, abs=1e-3)  # 0.1 + 5 * 0.2 m

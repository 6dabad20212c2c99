"""The fast tier's one MJX program: the README's simulation example (README.md, "Simulated walking"), built the
same way, so every fast physics test shares one compiled program, and the slow tier's run of the README
(tests/test_readme.py) finds it in the persistent compilation cache (tests/conftest.py) instead of compiling it
again.

Two robots on a 1.6 m x 1.6 m map at 4 cm with a block in the right foot's lane, three steps, four frames per
step, per-robot physics (friction 1.0 / 0.6, stance noise 0 / 1 cm) and a PRNG key: what a reader of the README
runs. Keep :func:`inputs` and the README's block the same program (shapes, dtypes, options); a difference costs
one more compile in CI, not a failure.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

import ijoy_jax as ij
from ijoy_jax.sim import physics, walker

STEPS = 3
FRAMES = 4
START = np.array([[0.3, 0.895, 0.0], [0.3, 0.705, 0.0]])  # left foot, right foot
BLOCK = (slice(20, 23), slice(8, 17))  # cells of the block in the right foot's lane
COMMANDS = np.array([[0.25, 0.0, 0.0], [0.2, 0.0, 0.1]])


def field() -> ij.terrain.Terrain:
    free = np.ones((40, 40), bool)
    free[BLOCK] = False
    return ij.terrain.from_arrays(np.zeros((40, 40), np.float32), free, resolution=0.04)


@functools.cache
def sim() -> walker.Sim:
    f = field()
    return walker.make_sim(f.shape, f.resolution, robot=ij.robots.hrp2(margin=0.02))


def inputs(friction=(1.0, 0.6), stance_noise=(0.0, 0.01)):
    """The README's batch: (fields, robots, starts, commands, dynamics) for two robots (margins 2 and 5 cm)."""
    f = field()
    robot = ij.robots.hrp2(margin=0.02)
    fields = jax.tree_util.tree_map(lambda a: jnp.stack([a, a]), f)
    margins = jax.vmap(lambda m: robot.replace(margin=m))(jnp.array([0.02, 0.05]))
    dyn = physics.Dynamics(friction=jnp.array(friction), stance_noise=jnp.array(stance_noise))
    return fields, margins, np.stack([START, START]), COMMANDS, dyn


def rollout(**dynamics):
    """The README's ``walker.rollout_batch`` call (host NumPy trajectory); ``dynamics`` as :func:`inputs`."""
    fields, robots, starts, commands, dyn = inputs(**dynamics)
    traj = walker.rollout_batch(sim(), fields, robots, starts, commands, num_steps=STEPS, frames_per_step=FRAMES,
                                dynamics=dyn, key=0)
    return jax.tree_util.tree_map(np.asarray, traj)


@functools.cache
def walk():
    """:func:`rollout` at the README's values, computed once per process."""
    return rollout()

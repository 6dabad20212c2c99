"""Who chooses each footstep of a live drive: the selector in this process, or the footstep server over the network.

Both answer Algorithm 1's GetNextStep for one future stance and one command with a :class:`Decision`
(the paper's Fig. 6: the Joystick Control asks the Footstep Server). :class:`LocalDecider` calls
:func:`ijoy_jax.select_step` with the terrain's index and targets built once
(:func:`ijoy_jax.select.prepare`); :class:`RemoteDecider` asks an ``ijoy serve`` process through
:class:`ijoy_jax.server.Client`, whose answers equal :func:`ijoy_jax.select_step` on the same inputs.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ijoy_jax import robots, select
from ijoy_jax.robots import Robot
from ijoy_jax.terrain import Terrain

__all__ = ["Decision", "LocalDecider", "RemoteDecider"]


class Decision(NamedTuple):
    """One footstep decision (host values).

    Fields::

      foothold: (6,) float32 the chosen sole pose x, y, z, roll, pitch, yaw (m, rad): what the robot is sent.
      valid: a valid step exists (False: the robot stands this step, StopWalking).
      cost: FootCost + w dist of the choice (+inf if none).
      index: the action's index in the robot's action set (-1 if none).
    """

    foothold: np.ndarray
    valid: bool
    cost: float
    index: int


class LocalDecider:
    """:func:`ijoy_jax.select_step` (exhaustive) in this process, with the terrain's tables built once."""

    name = "local"

    def __init__(self, terrain: Terrain, robot: Robot, *, prepared: select.Prepared | None = None):
        self.terrain, self.robot = terrain, robot
        self.prepared = select.prepare(terrain, robot) if prepared is None else prepared

    def decide(self, stance, stance_side, command, swing_from=None) -> Decision:
        """The step for a (future) stance (3,), its side (+1 left), a command (3,) and the swing foot's pose (3,)."""
        p = self.prepared
        c = select.select_step(self.terrain, self.robot, jnp.asarray(stance, jnp.float32), int(stance_side),
                               jnp.asarray(command, jnp.float32),
                               swing_from=None if swing_from is None else jnp.asarray(swing_from, jnp.float32),
                               index=p.index, targets=p.targets)
        return Decision(np.asarray(c.foothold, np.float32), bool(c.valid), float(c.cost), int(c.index))

    def close(self) -> None:
        pass


class RemoteDecider:
    """The footstep server (``ijoy serve``) through :class:`ijoy_jax.server.Client`: the terrain is sent once.

    With ``robot`` given, the server's robot is made the drive's: its action set must be the same (a
    ValueError says so otherwise: start ``ijoy serve`` with the drive's ``--density``/``--reach``), and its
    traced scalar leaves (margin, w, ...) are set to the robot's (``Client.set_robot``, no recompile).
    """

    name = "server"

    def __init__(self, client, terrain: Terrain, robot: Robot | None = None):
        self.client = client
        if robot is not None:
            info = client.info()
            theirs, ours = np.asarray(info["actions"], np.float32), np.asarray(robot.actions, np.float32)
            if theirs.shape != ours.shape or not np.array_equal(theirs, ours):
                raise ValueError(f"the footstep server's action set ({theirs.shape[0]} actions) is not the drive's "
                                 f"({ours.shape[0]}); start ijoy serve with the drive robot's --density and --reach")
            client.set_robot({name: float(np.asarray(robots.get_leaf(robot, name)))
                              for name in robots.SCALAR_LEAVES})
        self.client.set_terrain(terrain)

    def decide(self, stance, stance_side, command, swing_from=None) -> Decision:
        r = self.client.step(np.asarray(stance, np.float32), int(stance_side), np.asarray(command, np.float32),
                             swing_from=None if swing_from is None else np.asarray(swing_from, np.float32))
        return Decision(np.asarray(r.foothold, np.float32), bool(r.valid), float(r.cost), int(r.index))

    def close(self) -> None:
        close = getattr(self.client, "close", None)
        if close is not None:
            close()

"""The haptic cue: a force-feedback joystick that tells the biped's operator where it cannot go.

The two papers joined: the intelligent joystick's feasible footholds (:mod:`ijoy_jax.select`) mapped into
joystick space, and an ALDURO-style force (:mod:`ijoy_jax.haptics`) pushing the stick out of the commands the
terrain blocks, toward the nearest one the robot can carry out.

* :mod:`~ijoy_jax.cue.params`: the cue's tunable numbers (:class:`CueParams`), their defaults and checks.
* :mod:`~ijoy_jax.cue.feasible`: the feasible command set of one stance (once per step): every action as a
  joystick command, and whether the terrain allows it.
* :mod:`~ijoy_jax.cue.forces`: the force at one command (per haptic tick), and the prepared tick that splits
  it at the rate boundary.
* :mod:`~ijoy_jax.cue.reachable`: the reach per direction, the polar picture of the feasible commands, and
  whether a command is open in the hard geometry.
* :mod:`~ijoy_jax.cue.effects`: the force as force-feedback effects (a constant force, a spring).
* :mod:`~ijoy_jax.cue.field`: all of the above under one module name.
* :mod:`~ijoy_jax.cue.study`: a simulated operator driving the perfect robot through clutter with the
  cue on and off (time to goal, steps in place, command error, footholds near obstacles, with confidence
  intervals), and the cue's constants tuned by gradient.
* :mod:`~ijoy_jax.cue.plot`: the cue field in command space beside the terrain.
* benchmark: ``ijoy bench cue`` (:mod:`ijoy_jax.apps.bench_cue`); study: ``ijoy cue study``.

Units: metres, seconds, radians; commands in m/s, m/s, rad/s; forces as fractions of the device's maximum.
"""

from ijoy_jax.cue import effects as effects
from ijoy_jax.cue import feasible as feasible
from ijoy_jax.cue import field as field
from ijoy_jax.cue import forces as forces
from ijoy_jax.cue import params as params
from ijoy_jax.cue import reachable as reachable
from ijoy_jax.cue.effects import CueEffects as CueEffects
from ijoy_jax.cue.effects import device_effects as device_effects
from ijoy_jax.cue.feasible import FeasibleCommands as FeasibleCommands
from ijoy_jax.cue.feasible import action_commands as action_commands
from ijoy_jax.cue.feasible import feasible_commands as feasible_commands
from ijoy_jax.cue.forces import CueForce as CueForce
from ijoy_jax.cue.forces import CueTick as CueTick
from ijoy_jax.cue.forces import force as force
from ijoy_jax.cue.forces import force_terms as force_terms
from ijoy_jax.cue.forces import prepare_tick as prepare_tick
from ijoy_jax.cue.forces import tick_force as tick_force
from ijoy_jax.cue.params import DEFAULT_C1 as DEFAULT_C1
from ijoy_jax.cue.params import DEFAULT_DECAY as DEFAULT_DECAY
from ijoy_jax.cue.params import DEFAULT_TEMPERATURE as DEFAULT_TEMPERATURE
from ijoy_jax.cue.params import CueParams as CueParams
from ijoy_jax.cue.params import check_params as check_params
from ijoy_jax.cue.params import make_params as make_params
from ijoy_jax.cue.reachable import is_open as is_open
from ijoy_jax.cue.reachable import reach as reach

__all__ = [
    "DEFAULT_C1",
    "DEFAULT_DECAY",
    "DEFAULT_TEMPERATURE",
    "CueEffects",
    "CueForce",
    "CueParams",
    "CueTick",
    "FeasibleCommands",
    "action_commands",
    "check_params",
    "device_effects",
    "effects",
    "feasible",
    "feasible_commands",
    "field",
    "force",
    "force_terms",
    "forces",
    "is_open",
    "make_params",
    "params",
    "prepare_tick",
    "reach",
    "reachable",
    "tick_force",
]

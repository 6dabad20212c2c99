"""The haptic cue: a force-feedback joystick that tells the biped's operator where it cannot go.

The two papers joined (issue #23): the intelligent joystick's feasible footholds (:mod:`ijoy_jax.select`)
mapped into joystick space, and an ALDURO-style force (:mod:`ijoy_jax.haptics`) pushing the stick out of
the commands the terrain blocks, toward the nearest one the robot can carry out.

* :mod:`~ijoy_jax.cue.field`: the feasible command set and the prepared tick (once per step), the force
  (per haptic tick), the reach per direction, and the force as force-feedback effects.
* :mod:`~ijoy_jax.cue.study`: a simulated operator driving the perfect robot through clutter with the
  cue on and off (time to goal, steps in place, command error, footholds near obstacles, with confidence
  intervals), and the cue's constants tuned by gradient.
* :mod:`~ijoy_jax.cue.plot`: the cue field in command space beside the terrain.
* benchmark: ``ijoy bench cue`` (:mod:`ijoy_jax.apps.bench_cue`); study: ``ijoy cue study``.

Units: metres, seconds, radians; commands in m/s, m/s, rad/s; forces as fractions of the device's maximum.
"""

from ijoy_jax.cue import field as field
from ijoy_jax.cue.field import DEFAULT_C1 as DEFAULT_C1
from ijoy_jax.cue.field import DEFAULT_DECAY as DEFAULT_DECAY
from ijoy_jax.cue.field import DEFAULT_TEMPERATURE as DEFAULT_TEMPERATURE
from ijoy_jax.cue.field import CueEffects as CueEffects
from ijoy_jax.cue.field import CueForce as CueForce
from ijoy_jax.cue.field import CueParams as CueParams
from ijoy_jax.cue.field import CueTick as CueTick
from ijoy_jax.cue.field import FeasibleCommands as FeasibleCommands
from ijoy_jax.cue.field import action_commands as action_commands
from ijoy_jax.cue.field import check_params as check_params
from ijoy_jax.cue.field import device_effects as device_effects
from ijoy_jax.cue.field import feasible_commands as feasible_commands
from ijoy_jax.cue.field import force as force
from ijoy_jax.cue.field import force_terms as force_terms
from ijoy_jax.cue.field import make_params as make_params
from ijoy_jax.cue.field import prepare_tick as prepare_tick
from ijoy_jax.cue.field import reach as reach
from ijoy_jax.cue.field import tick_force as tick_force

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
    "feasible_commands",
    "field",
    "force",
    "force_terms",
    "make_params",
    "prepare_tick",
    "reach",
    "tick_force",
]

"""The cue field in one import: the feasible command set, the parameters, the force, the reach and the effects.

The cue is built from modules of one concept each; this one gathers their public names under one module for
code that reads the whole field through it (``from ijoy_jax.cue import field``; the package root exports the
same objects). Each name is documented at its home:

* :mod:`~ijoy_jax.cue.params`: :class:`~ijoy_jax.cue.CueParams`, :func:`~ijoy_jax.cue.make_params`,
  :func:`~ijoy_jax.cue.check_params` and the defaults.
* :mod:`~ijoy_jax.cue.feasible`: the feasible command set of one stance (:func:`~ijoy_jax.cue.feasible_commands`,
  :func:`~ijoy_jax.cue.action_commands`, :class:`~ijoy_jax.cue.FeasibleCommands`), once per step.
* :mod:`~ijoy_jax.cue.forces`: the force at one command (:func:`~ijoy_jax.cue.force_terms`,
  :func:`~ijoy_jax.cue.force`) and the same split at the rate boundary (:func:`~ijoy_jax.cue.prepare_tick`,
  :func:`~ijoy_jax.cue.tick_force`), per haptic tick.
* :mod:`~ijoy_jax.cue.reachable`: the largest open speed per direction (:func:`~ijoy_jax.cue.reach`) and
  whether a command is open (:func:`~ijoy_jax.cue.is_open`).
* :mod:`~ijoy_jax.cue.effects`: the force as force-feedback effects (:func:`~ijoy_jax.cue.device_effects`).
"""

from __future__ import annotations

from ijoy_jax.cue.effects import DEFAULT_TRAVEL as DEFAULT_TRAVEL
from ijoy_jax.cue.effects import CueEffects as CueEffects
from ijoy_jax.cue.effects import device_effects as device_effects
from ijoy_jax.cue.feasible import GAP_TOL as GAP_TOL
from ijoy_jax.cue.feasible import MIN_UNIT as MIN_UNIT
from ijoy_jax.cue.feasible import FeasibleCommands as FeasibleCommands
from ijoy_jax.cue.feasible import action_commands as action_commands
from ijoy_jax.cue.feasible import feasible_commands as feasible_commands
from ijoy_jax.cue.forces import CLIP_SLACK as CLIP_SLACK
from ijoy_jax.cue.forces import ROUNDING_ULPS as ROUNDING_ULPS
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
from ijoy_jax.cue.reachable import REACH_BISECTIONS as REACH_BISECTIONS
from ijoy_jax.cue.reachable import is_open as is_open
from ijoy_jax.cue.reachable import reach as reach

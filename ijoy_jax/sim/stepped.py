"""What the biped stepped from the host has in common, on native MuJoCo or on MJX.

:class:`ijoy_jax.sim.native.NativeBiped` and :class:`ijoy_jax.sim.mjx_biped.MjxBiped` are the live loop's
physics bodies (``ijoy drive --robot native`` / ``mjx``): one robot, a step begun with ``begin``, advanced one
control period per ``tick`` and closed with ``end``. :class:`SteppedBiped` holds the part of that protocol
that does not depend on the simulator: the clock of a step, whether one is in progress, the feet, and a
whole step.

Units: metres, radians, seconds; feet are planar poses (x, y, yaw), row 0 the left foot.
"""

from __future__ import annotations

import numpy as np

from ijoy_jax.sim.walker import PLANAR, StepLog

__all__ = ["SteppedBiped"]


class SteppedBiped:
    """Base of a biped stepped from the host. A subclass sets ``cfg`` (its
    :class:`~ijoy_jax.sim.controller.WalkConfig`) and keeps the step in progress in ``_step`` (this base's
    attribute: None between steps, whatever the subclass needs during one), and defines ``soles()``
    ((2, 6) measured soles, row 0 left), ``begin(foothold, go)``, ``tick() -> bool`` (False after the step's
    last period) and ``end() -> StepLog``."""

    _step = None

    def feet(self) -> np.ndarray:
        """(2, 3) float32 the measured feet (x, y, yaw; m, rad), row 0 left, now (a swinging foot where it is)."""
        return self.soles()[:, PLANAR]

    @property
    def ticks_per_step(self) -> int:
        """Control periods per step (``step_time / control_dt``)."""
        return self.cfg.ticks_per_step

    @property
    def control_dt(self) -> float:
        """s per control tick (``cfg.control_dt``)."""
        return float(self.cfg.control_dt)

    @property
    def stepping(self) -> bool:
        """A step is in progress (between ``begin`` and ``end``)."""
        return self._step is not None

    def execute(self, foothold, go: bool) -> StepLog:
        """One whole step (``begin``, every ``tick``, ``end``), as fast as the simulator runs it."""
        self.begin(foothold, go)
        while self.tick():
            pass
        return self.end()

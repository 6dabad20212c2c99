"""The robots a live drive steps in real time: the paper's perfect walker, tick by tick, on the host.

A live robot (a *body*) has the host protocol of :class:`ijoy_jax.sim.native.NativeBiped` (and of
:class:`ijoy_jax.sim.mjx_biped.MjxBiped`, the same biped on MJX):
``stance()``, ``future_stance()`` (Algorithm 1's ComputeStanceLocation while a step executes),
``begin(foothold, go)``, ``tick() -> bool`` (one control period of ``control_dt`` s; False at the
step's end), ``end()``, ``feet()``, ``ticks_per_step`` and ``control_dt``. :class:`PerfectBody` is
:func:`ijoy_jax.control.perfect_walker` with that protocol: each step lands exactly where it was
sent, ``step_time`` after it began (the same float32 feet as the scanned rollout's).
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from ijoy_jax import control
from ijoy_jax.robots import LEFT, Robot
from ijoy_jax.stick import DEFAULT_CONTROL_DT

__all__ = ["MIN_CONTROL_DT", "PerfectBody"]

MIN_CONTROL_DT = 1e-4
"""Shortest control period (s) of the perfect body: a shorter one ticks without end in real time."""

_PLANAR = np.array([0, 1, 5])


class PerfectBody:
    """The paper's simulated robot on the host: every commanded step lands exactly, ``robot.step_time`` s later.

    Args:
      robot: the robot (its step time).
      start: (2, 3) feet (x, y, yaw), row 0 left.
      first_swing: +1 if the left foot swings first.
      control_dt: s per tick (``robot.step_time`` must be a whole number of ticks).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax.live import PerfectBody
      >>> body = PerfectBody(ij.robots.hrp2(), ij.robots.start_stance(ij.robots.hrp2(), 0.5, 1.0))
      >>> body.begin(np.array([0.7, 1.095, 0, 0, 0, 0], np.float32), True)
      >>> while body.tick(): pass
      >>> body.end(); body.feet()[0].tolist()
      [0.699999988079071, 1.0950000286102295, 0.0]
    """

    def __init__(self, robot: Robot, start, first_swing=LEFT, control_dt: float = DEFAULT_CONTROL_DT):
        step_time = float(robot.step_time)
        number = isinstance(control_dt, numbers.Real) and not isinstance(control_dt, bool)
        if not (number and math.isfinite(control_dt) and control_dt >= MIN_CONTROL_DT):
            raise ValueError(f"control_dt must be a finite number of seconds >= {MIN_CONTROL_DT:g} (at most "
                             f"{1 / MIN_CONTROL_DT:g} ticks per second), got {control_dt!r}")
        ticks = step_time / control_dt
        if abs(ticks - round(ticks)) > 1e-4:  # float32 step times: 0.8 is 0.80000001
            raise ValueError(f"step_time {step_time} s must be a whole number of control_dt {control_dt} s ticks")
        start = np.array(start, np.float32)
        if start.shape != (2, 3) or not np.all(np.isfinite(start)):
            raise ValueError(f"start must be finite (2, 3) feet (left, right), got shape {start.shape}")
        if float(first_swing) not in (1.0, -1.0):
            raise ValueError(f"first_swing must be +1 (left) or -1 (right), got {first_swing!r}")
        self.control_dt, self.ticks_per_step = float(control_dt), int(round(ticks))
        self._feet = start
        self.swing = np.float32(first_swing)
        self.fallen = False
        self.time = 0.0
        self._step = None

    def feet(self) -> np.ndarray:
        """(2, 3) float32 feet (x, y, yaw), row 0 left (where they stand; a swinging foot counts where it left)."""
        return self._feet.copy()

    def stance(self) -> control.StanceInfo:
        left_swings = self.swing > 0
        st, sw = (self._feet[1], self._feet[0]) if left_swings else (self._feet[0], self._feet[1])
        return control.StanceInfo(st.copy(), np.float32(-self.swing), sw.copy())

    def future_stance(self) -> control.StanceInfo:
        """The next decision's stance: the swinging foot where it was sent (or :meth:`stance` when standing)."""
        st = self.stance()
        if self._step is None or not self._step[1]:
            return st
        return control.StanceInfo(self._step[0].copy(), np.float32(-st.stance_side), st.stance)

    @property
    def stepping(self) -> bool:
        return self._step is not None

    def progress(self) -> float:
        """Fraction of the step in progress (0 when standing)."""
        return 0.0 if self._step is None else self._step[2] / self.ticks_per_step

    def begin(self, foothold, go: bool) -> None:
        if self._step is not None:
            raise RuntimeError("a step is in progress: tick() it to its end and call end() first")
        foothold = np.asarray(foothold, np.float32)
        if foothold.shape != (6,):
            raise ValueError(f"foothold must have shape (6,) (x, y, z, roll, pitch, yaw), got {foothold.shape}")
        self._step = [foothold[_PLANAR], bool(go) and bool(np.all(np.isfinite(foothold))), 0]

    def tick(self) -> bool:
        if self._step is None:
            raise RuntimeError("no step in progress: call begin() first")
        self._step[2] += 1
        self.time += self.control_dt
        return self._step[2] < self.ticks_per_step

    def end(self) -> None:
        if self._step is None or self._step[2] < self.ticks_per_step:
            raise RuntimeError("the step has not run all its ticks: tick() until it returns False")
        pose, go, _ = self._step
        self._step = None
        if go:
            self._feet[0 if self.swing > 0 else 1] = pose
            self.swing = np.float32(-self.swing)
        return None

    def execute(self, foothold, go: bool) -> None:
        """One whole step at once."""
        self.begin(foothold, go)
        while self.tick():
            pass
        return self.end()

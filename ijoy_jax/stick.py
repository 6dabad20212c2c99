"""The joystick's stick: normalised axes mapped onto a robot's command, traces of a stick in time, and the
command each decision of a drive reads from a trace.

Every stick gives three *normalised axes* ``(forward, left, turn)``, each in [-1, 1] (+1: full forward, full
left, full turn to the left), and :func:`axes_to_command` maps them onto a command ``(xdot m/s, ydot m/s,
thetadot rad/s)`` in the robot's range (:func:`ijoy_jax.robots.command_range`) through a dead zone. A
*trace* (:class:`Trace`, :func:`read_trace`) is a stick in time: the scripted input of ``ijoy drive
--script``, a recorded drive exported (:func:`ijoy_jax.live.session.export_trace`) and a sweep's ``[command]
file`` (:mod:`ijoy_jax.sweep.recorded`), whose commands are those of :func:`scripted_commands`, the decisions
a drive of that stick makes. The live sources of a stick (keyboard, gamepad, browser) are
:mod:`ijoy_jax.live.inputs`.

Trace file format (``ijoy drive --script TRACE``): UTF-8 text, one sample per line, comma-separated
``t,forward,left,turn``: the time (s, from the drive's start, strictly increasing, first >= 0) and
the three axes in [-1, 1]. Blank lines and lines starting with ``#`` are ignored, and so is one
header line ``t,forward,left,turn``. The axes hold from their time until the next line's (before
the first line: 0); the last line's time is the drive's end. Example::

    t,forward,left,turn
    0.0, 1.0, 0.0, 0.0     # full forward from the start
    4.0, 0.6, 0.0, 0.5     # slower, turning left, from 4 s
    8.0, 0.0, 0.0, 0.0     # stop; the drive ends here
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ijoy_jax import robots
from ijoy_jax.robots import Robot, command_range

__all__ = ["DEFAULT_CONTROL_DT", "DEFAULT_DEADZONE", "TRACE_HEADER", "InputError", "Trace", "axes_to_command",
           "read_trace", "scripted_commands"]

DEFAULT_DEADZONE = 0.1
"""Fraction of each axis's travel around its centre that reads as 0 (a worn stick rests a few percent off)."""
TRACE_HEADER = ("t", "forward", "left", "turn")
"""The trace file's columns (and its optional header line)."""
DEFAULT_CONTROL_DT = 0.01
"""s: a drive's control tick (the perfect body's and the MuJoCo biped's controller period), the rate the drive
reads the stick at."""


class InputError(ValueError):
    """A bad input source: a malformed trace, no gamepad, no terminal. The message is one line."""


def axes_to_command(axes, robot: Robot | tuple, deadzone: float = DEFAULT_DEADZONE) -> np.ndarray:
    """(3,) float64 command (m/s, m/s, rad/s) for normalised stick axes (3,) (forward, left, turn) in [-1, 1].

    Per axis, with dead zone ``d``: ``|a| <= d`` reads 0; beyond it ``s = (|a| - d) / (1 - d)`` rises
    linearly to 1 at full deflection (no jump at the dead zone's edge), and the command is ``s * hi``
    for a positive deflection and ``s * |lo|`` below the centre (the two ends of each axis's range
    need not be equal). Axes beyond [-1, 1] are clipped; a NaN or infinite axis reads 0.

    Args:
      axes: (3,) forward, left, turn.
      robot: the robot whose :func:`ijoy_jax.robots.command_range` is the range, or its ``(lo, hi)``.
      deadzone: in [0, 1).

    Example:
      >>> import ijoy_jax as ij
      >>> from ijoy_jax.stick import axes_to_command
      >>> axes_to_command([1.0, 0.05, -0.55], ij.robots.hrp2()).round(4).tolist()
      [0.25, 0.0, -0.2182]
    """
    if not (isinstance(deadzone, (int, float)) and 0.0 <= deadzone < 1.0):
        raise ValueError(f"deadzone must be in [0, 1), got {deadzone!r}")
    lo, hi = command_range(robot) if isinstance(robot, Robot) else robot
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    a = np.asarray(axes, np.float64)
    if a.shape != (3,):
        raise ValueError(f"axes must have shape (3,) (forward, left, turn), got {a.shape}")
    a = np.where(np.isfinite(a), np.clip(a, -1.0, 1.0), 0.0)
    s = np.maximum(np.abs(a) - deadzone, 0.0) / (1.0 - deadzone)
    return np.where(a > 0, s * hi, -s * np.abs(lo)) + 0.0  # + 0.0: no -0.0 in records


class Trace(NamedTuple):
    """A scripted stick: ``t`` (T,) s strictly increasing, ``axes`` (T, 3) in [-1, 1] (:func:`read_trace`)."""

    t: np.ndarray
    axes: np.ndarray

    @property
    def duration(self) -> float:
        """s: the last sample's time, the drive's end."""
        return float(self.t[-1])

    def at(self, t: float) -> np.ndarray:
        """(3,) the axes held at time ``t`` (s): the last sample at or before it, zeros before the first."""
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        return np.zeros(3) if i < 0 else self.axes[i].copy()


def read_trace(path) -> Trace:
    """Read a trace file (format: the module docstring). Raises :class:`InputError` naming file, line and fault."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"trace file {str(path)!r} does not exist") from None
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"trace file {str(path)!r} cannot be read: {e}") from None
    ts, rows = [], []
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        cells = [c.strip() for c in line.split(",")]
        if not ts and tuple(c.lower() for c in cells) == TRACE_HEADER:
            continue
        where = f"{path}:{n}"
        if len(cells) != 4:
            raise InputError(f"{where}: expected 4 comma-separated values t,forward,left,turn, got {len(cells)}: "
                             f"{raw.strip()!r}")
        try:
            vals = [float(c) for c in cells]
        except ValueError:
            raise InputError(f"{where}: not a number in {raw.strip()!r}") from None
        if not all(math.isfinite(v) for v in vals):
            raise InputError(f"{where}: values must be finite, got {raw.strip()!r}")
        if vals[0] < 0 or (ts and vals[0] <= ts[-1]):
            raise InputError(f"{where}: times must start at >= 0 and increase strictly, got {vals[0]} after "
                             f"{ts[-1] if ts else 'the start'}")
        if any(abs(v) > 1.0 for v in vals[1:]):
            raise InputError(f"{where}: axes must lie in [-1, 1] (normalised stick deflection), got {vals[1:]}")
        ts.append(vals[0])
        rows.append(vals[1:])
    if not ts:
        raise InputError(f"trace file {str(path)!r} has no samples (lines t,forward,left,turn)")
    return Trace(np.asarray(ts, np.float64), np.asarray(rows, np.float64))


def scripted_commands(trace: Trace, robot: Robot, *, deadzone: float = DEFAULT_DEADZONE, decide_at: float = 0.0,
                      control_dt: float = DEFAULT_CONTROL_DT, num_steps: int | None = None) -> np.ndarray:
    """(n, 3) float64: the command (m/s, m/s, rad/s) of each decision :func:`ijoy_jax.live.drive` makes with the stick
    ``trace`` (host only, nothing is decided).

    The loop's schedule: with ``ticks = round(step_time / control_dt)`` control ticks per step and
    ``d = floor(decide_at * ticks)``, decision ``j`` (0-based; it chooses step ``j + 1``) reads the stick at
    ``t_j = (j * ticks + d) * control_dt`` s, ``trace.at(t_j)`` through :func:`axes_to_command`
    with the robot's command range and ``deadzone``; there is no decision at or after the trace's end
    (``trace.duration``), nor beyond ``num_steps``. The same float64 values as the ``command`` of each recorded
    decision of a drive of that stick (the perfect body, or the MuJoCo biped: both tick at ``control_dt``), so
    a trace file becomes a command sequence for a sweep (``[command] file``, :mod:`ijoy_jax.sweep.recorded`).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax import stick
      >>> trace = stick.Trace(np.array([0.0, 1.0, 2.0]), np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 0]]))
      >>> stick.scripted_commands(trace, ij.robots.hrp2()).round(4).tolist()   # at 0 and 0.8 s, 1.6 s
      [[0.25, 0.0, 0.0], [0.25, 0.0, 0.0], [0.0, 0.175, 0.0]]
    """
    if not 0.0 <= decide_at < 1.0:
        raise ValueError(f"decide_at must be in [0, 1) (a fraction of the step), got {decide_at!r}")
    if num_steps is not None and (isinstance(num_steps, bool) or int(num_steps) != num_steps or num_steps < 0):
        raise ValueError(f"num_steps must be a whole number >= 0, got {num_steps!r}")
    dt = float(control_dt)
    ticks = float(robot.step_time) / dt
    if dt <= 0 or abs(ticks - round(ticks)) > 1e-4:  # as the bodies require (float32 step times: 0.80000001)
        raise ValueError(f"step_time {float(robot.step_time)} s must be a whole number of control_dt {dt} s ticks")
    ticks = int(round(ticks))
    d = int(math.floor(decide_at * ticks))
    duration = trace.duration
    upper = int(duration / (ticks * dt)) + 2  # past the last decision: the loop's test below decides
    if num_steps is not None:
        upper = min(upper, int(num_steps))
    lo, hi = robots.command_range(robot)
    out = []
    for j in range(upper):
        # drive()'s own expressions: t_start + d * dt against the end, then the tick's time tick_count * dt
        if not (j * ticks) * dt + d * dt < duration - 1e-9:
            break
        out.append(axes_to_command(trace.at((j * ticks + d) * dt), (lo, hi), deadzone))
    return np.asarray(out, np.float64).reshape(-1, 3)

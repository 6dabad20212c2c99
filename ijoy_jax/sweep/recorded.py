"""Sweep inputs read from files: a person's commands (a recorded drive or a trace file) and a recorded terrain.

A recorded drive becomes a sweep scenario: its commands, one per decision, take the place of the
``[command]`` distribution and are replayed step by step (step ``k`` of every rollout gets the ``k``-th
command) by the sweep's walker, the perfect robot or the MJX biped (``walker = "mjx"``), on the sweep's
generated terrains or on the recording's own terrain:

.. code-block:: toml

    [command]
    file = "drive.mcap"        # the command of each decision of a recorded drive (ijoy drive --record)
    # file = "drive.csv"       # or a trace file (t,forward,left,turn): the stick read as ijoy drive reads it
    # first_swing = -1         # the foot that swings first (default: the recording's; +1 for a trace)
    # deadzone = 0.1           # trace files only: the stick's dead zone (ijoy drive's default)
    # decide_at = 0.0          # trace files only: the fraction of a step at which the stick is read

    [terrain]
    recording = "drive.mcap"   # the recording's terrain and start feet (instead of family, shape, ...)

Paths are relative to the sweep file's folder. A recording (MCAP, :mod:`ijoy_jax.recordings`) gives the
``command`` of each recorded decision, the float64 values its decider was given (as float32, what the
decider computed with), and its first swing; a trace file (:func:`ijoy_jax.live.read_trace`) gives the
commands :func:`ijoy_jax.stick.scripted_commands` computes, the ones a drive of that stick decides
with, for the sweep's robot (its command range and step time: ``robot.step_time`` and ``robot.density``
are then fixed, not swept). ``sweep.num_steps`` defaults to the number of commands and may be smaller.

The sweep's rollout is Algorithm 1 as the scanned loop runs it (:func:`ijoy_jax.control.loop`): a decision
without a valid step stops the robot for good, where a live drive stands that step and decides again. A
drive without such a decision (every recorded ``valid`` true) takes the same footsteps in the sweep, bit
for bit, on its terrain with its robot (tested); with one, the footsteps agree up to it
(:attr:`CommandSequence.invalid` lists them; ``ijoy drive --export-sweep`` says so).

The file formats belong to :mod:`ijoy_jax.live`, which is read here lazily (only for a sweep that names a
file): :mod:`ijoy_jax.recordings` and :mod:`ijoy_jax.live.inputs` need the terrain and robot modules alone.
"""

from __future__ import annotations

import hashlib
import os
import stat
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ijoy_jax import recordings, stick
from ijoy_jax.robots import Robot
from ijoy_jax.terrain import Terrain

__all__ = ["COMMAND_FILE_KEYS", "CommandSequence", "RecordedTerrain", "is_recording", "read_commands", "read_terrain"]

COMMAND_FILE_KEYS = ("file", "first_swing", "deadzone", "decide_at")
"""The ``[command]`` keys of a sweep whose commands come from a file (instead of ``vx``, ``vy``, ``wz``)."""

_FLOAT32_MAX = float(np.finfo(np.float32).max)


class CommandSequence(NamedTuple):
    """Commands per step from a file (:func:`read_commands`).

    Fields::

      path: the file (str).
      kind: "recording" (an MCAP drive recording) or "trace" (a trace file).
      commands: (n, 3) float32 (m/s, m/s, rad/s), one per decision, in order.
      first_swing: +1 if the left foot swings first, -1 the right.
      invalid: the recorded decisions (1-based steps) without a valid step (a recording; () for a trace).
      sha256: hex digest of the file's bytes (the sweep's plan records it: a changed file is another sweep).
    """

    path: str
    kind: str
    commands: np.ndarray
    first_swing: int
    invalid: tuple
    sha256: str


class RecordedTerrain(NamedTuple):
    """A recording's terrain and start (:func:`read_terrain`).

    Fields::

      path: the recording (str).
      terrain: its :class:`~ijoy_jax.Terrain` (the ``terrain.npz`` attachment, bit for bit).
      start: (2, 3) float32 the feet (left, right; m, rad) the drive started from.
      sha256: hex digest of the file's bytes.
    """

    path: str
    terrain: Terrain
    start: np.ndarray
    sha256: str


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _existing(path) -> Path:
    """``path`` as a Path once it names a regular file this process may read.

    Raises:
      ValueError: one line quoting the path and what it is instead: missing, a directory, not a regular file
        (a device, pipe or socket, which a read could block on or never end), or not readable.
    """
    p = Path(path)
    where = "paths are relative to the sweep file's folder"
    try:
        st = p.stat()
    except FileNotFoundError:
        raise ValueError(f"{str(p)!r} does not exist ({where})") from None
    except NotADirectoryError:
        raise ValueError(f"{str(p)!r} does not exist: a folder on its path is a file ({where})") from None
    except (OSError, ValueError) as e:  # permission on a folder, a name too long, a NUL byte
        raise ValueError(f"{str(p)!r} cannot be read: {getattr(e, 'strerror', None) or e}") from None
    if stat.S_ISDIR(st.st_mode):
        raise ValueError(f"{str(p)!r} is a directory, not a file (name the file in it; {where})")
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"{str(p)!r} is not a regular file (a device, pipe or socket): name a file")
    if not os.access(p, os.R_OK):
        raise ValueError(f"{str(p)!r} cannot be read: permission denied")
    return p


def is_recording(path) -> bool:
    """Whether ``path`` names an MCAP drive recording (by its ``.mcap`` suffix); any other file is a trace."""
    return Path(path).suffix.lower() == ".mcap"


def read_commands(path, robot: Robot | None = None, *, deadzone: float | None = None, decide_at: float | None = None,
                  first_swing: int | None = None, max_steps: int | None = None) -> CommandSequence:
    """The command sequence of a drive recording (``.mcap``) or a trace file (any other name).

    Args:
      path: the file.
      robot: a trace's robot (its command range and step time); not used for a recording.
      deadzone, decide_at: a trace's stick dead zone (default :data:`ijoy_jax.stick.DEFAULT_DEADZONE`)
        and decision point in a step (default 0); a recording refuses them (its commands are recorded).
      first_swing: +1 or -1 (default: the recording's, +1 for a trace).
      max_steps: read at most this many commands of a trace (its schedule is computed up to it).

    Raises:
      ValueError: one line naming the file and what is wrong (missing, not a drive recording, a malformed
        trace line, no decisions, a command beyond float32).
    """
    p = _existing(path)
    if is_recording(p):
        if deadzone is not None or decide_at is not None:
            raise ValueError(f"{str(p)!r} is a recording: its commands are recorded, deadzone and decide_at are "
                             "for trace files")
        rec = recordings.read_recording(p)  # ValueError (one line) for a file that is not one
        steps = [d.get("step") for d in rec.decisions]
        if not steps:
            raise ValueError(f"{str(p)!r}: the recording has no decisions (nothing to replay)")
        if steps != list(range(1, len(steps) + 1)):
            raise ValueError(f"{str(p)!r}: the recorded decisions are not steps 1 to {len(steps)} in order")
        try:
            raw = np.asarray([d["command"] for d in rec.decisions], np.float64)
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"{str(p)!r}: a recorded decision without a command of 3 numbers ({e})") from None
        invalid = tuple(int(d["step"]) for d in rec.decisions if not d.get("valid", False))
        swing = rec.config.get("settings", {}).get("first_swing", 1)
        kind = "recording"
    else:
        if robot is None:
            raise ValueError(f"{str(p)!r} is a trace file: its commands need the robot (command range, step time)")
        trace = stick.read_trace(p)  # InputError (a ValueError): file:line: fault
        dz = stick.DEFAULT_DEADZONE if deadzone is None else float(deadzone)
        if not 0.0 <= dz < 1.0:
            raise ValueError(f"deadzone must be in [0, 1) (a fraction of the stick's travel), got {dz}")
        da = 0.0 if decide_at is None else float(decide_at)
        if not 0.0 <= da < 1.0:
            raise ValueError(f"decide_at must be in [0, 1) (a fraction of the step), got {da}")
        raw = stick.scripted_commands(trace, robot, deadzone=dz, decide_at=da, num_steps=max_steps)
        if not len(raw):
            raise ValueError(f"{str(p)!r}: the trace ends ({trace.duration} s) before its first decision")
        invalid, swing, kind = (), 1, "trace"
    if raw.ndim != 2 or raw.shape[1] != 3:
        raise ValueError(f"{str(p)!r}: commands must be 3 numbers each, got shape {raw.shape}")
    if not np.all(np.isfinite(raw)) or np.any(np.abs(raw) > _FLOAT32_MAX):
        raise ValueError(f"{str(p)!r}: a command is not finite in float32")
    swing = swing if first_swing is None else first_swing
    if isinstance(swing, bool) or swing not in (1, -1):
        raise ValueError(f"first_swing must be +1 (left) or -1 (right), got {swing!r}")
    return CommandSequence(str(p), kind, raw.astype(np.float32), int(swing), invalid, _digest(p))


def read_terrain(path) -> RecordedTerrain:
    """A drive recording's terrain (its ``terrain.npz`` attachment) and start feet (its ``ijoy.drive`` metadata).

    Raises:
      ValueError: one line naming the file (missing, not a drive recording, no start feet of shape (2, 3)).
    """
    p = _existing(path)
    if not is_recording(p):
        raise ValueError(f"{str(p)!r} is not a drive recording (an .mcap file of ijoy drive --record)")
    rec = recordings.read_recording(p)
    try:
        start = np.asarray(rec.config["start"], np.float64)
    except (KeyError, TypeError, ValueError):
        start = np.zeros(0)
    if start.shape != (2, 3) or not np.all(np.isfinite(start)):
        raise ValueError(f"{str(p)!r}: the recording has no start feet of shape (2, 3) (its 'start' metadata)")
    return RecordedTerrain(str(p), rec.terrain, start.astype(np.float32), _digest(p))

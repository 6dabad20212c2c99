"""Where a live drive's command comes from: stick axes, mapped through a dead zone onto the robot's command range.

Every source gives the same thing, three *normalised stick axes* ``(forward, left, turn)``, each in
[-1, 1] (+1: full forward, full left, full turn to the left), and :func:`ijoy_jax.stick.axes_to_command` maps
them onto a command ``(xdot m/s, ydot m/s, thetadot rad/s)`` in the robot's range
(:func:`ijoy_jax.robots.command_range`) through a dead zone. So a script, a keyboard, a gamepad and
the browser view drive the robot alike, and a recorded drive keeps both the axes and the command.

Sources (each has ``axes(t) -> (3,)`` float64, ``t`` the drive's clock in seconds, and ``close()``):

* :class:`ScriptInput`: a trace file (:func:`ijoy_jax.stick.read_trace`, whose module documents the format),
  sampled and held; a scripted virtual joystick, for tests and for repeating a drive.
* :class:`SharedAxes`: the latest axes set by another thread (the live view's keyboard or
  browser gamepad, :mod:`ijoy_jax.live.view`).
* :class:`TerminalKeyboard`: keys typed into a terminal (w/s forward and back, a/d left and
  right, q/e turn, space stop); a key holds its axis for :data:`KEY_HOLD` s, so the terminal's
  key repeat keeps it held.
* :class:`Gamepad`: a gamepad or joystick through SDL (pygame-ce), :data:`GAMEPAD_AXES` by default.
"""

from __future__ import annotations

import os
import threading
import time

import numpy as np

from ijoy_jax.stick import InputError, Trace, read_trace

__all__ = [
    "GAMEPAD_AXES",
    "KEY_HOLD",
    "Gamepad",
    "ScriptInput",
    "SharedAxes",
    "TerminalKeyboard",
    "gamepad_axes",
]

KEY_HOLD = 0.3
"""s: how long a terminal key press holds its axis (longer than a terminal's key-repeat interval, ~33 ms,
and its initial delay, ~250-500 ms, would make a held key flicker; releasing stops within this)."""
GAMEPAD_AXES = ((1, -1.0), (0, -1.0), (3, -1.0))
"""The SDL joystick axes read as forward, left and turn, each an (axis number, sign) pair: the left stick's y (up
is -1 in SDL) and x (right is +1), the right stick's x (axis 3 on the Linux evdev layout of most pads; pass
``axes=`` otherwise)."""


# ---------------------------------------------------------------------------------------------- a trace file


class ScriptInput:
    """A scripted virtual joystick: a :class:`Trace` (or a trace file's path) sampled at the drive's clock."""

    def __init__(self, trace):
        self.trace = trace if isinstance(trace, Trace) else read_trace(trace)

    @property
    def duration(self) -> float:
        return self.trace.duration

    def axes(self, t: float) -> np.ndarray:
        return self.trace.at(t)

    def close(self) -> None:
        pass


class SharedAxes:
    """Axes set by another thread (the live view's keyboard or browser gamepad); ``axes(t)`` reads the latest.

    ``set(axes, source)`` clips to [-1, 1] and keeps the time and source of the update (``source`` e.g.
    ``"keyboard"`` or ``"gamepad"``); ``updates`` counts them.
    """

    def __init__(self):
        self._lock = threading.Lock()
        self._axes = np.zeros(3)
        self.source = "none"
        self.updates = 0

    def set(self, axes, source: str = "view") -> None:
        """Raises ValueError or TypeError for axes that are not 3 numbers (the view ignores such a message)."""
        try:
            a = np.asarray(axes, np.float64).reshape(-1)
        except OverflowError:  # a JSON integer beyond float64 (400 digits): refused as any bad value is
            raise ValueError("axes must be numbers a float holds, got an integer beyond float64") from None
        if a.shape != (3,):
            raise ValueError(f"axes must have 3 values (forward, left, turn), got {a.shape}")
        a = np.where(np.isfinite(a), np.clip(a, -1.0, 1.0), 0.0)
        with self._lock:
            self._axes = a
            self.source = str(source)
            self.updates += 1

    def axes(self, t: float = 0.0) -> np.ndarray:
        with self._lock:
            return self._axes.copy()

    def close(self) -> None:
        pass


# ---------------------------------------------------------------------------------------------- terminal keys

_KEYS = {"w": (0, 1.0), "s": (0, -1.0), "a": (1, 1.0), "d": (1, -1.0), "q": (2, 1.0), "e": (2, -1.0)}


class TerminalKeyboard:
    """Keys typed into a terminal: w/s forward/back, a/d left/right, q/e turn left/right, space stops.

    A terminal reports key presses only (no releases): each press holds its axis at full deflection for
    :data:`KEY_HOLD` s (the key repeat of a held key keeps it), and the opposite key or space cuts it.
    Reads ``fd`` (default: standard input, which must be a terminal; it is put in cbreak mode and
    restored on :meth:`close`) in a background thread.
    """

    def __init__(self, fd: int | None = None, hold: float = KEY_HOLD):
        import termios
        import tty

        self.fd = fd if fd is not None else 0
        if not os.isatty(self.fd):
            raise InputError("keyboard input needs a terminal (standard input is not one); use --script, "
                             "--input view or --input gamepad")
        self.hold = float(hold)
        self._saved = termios.tcgetattr(self.fd)
        tty.setcbreak(self.fd)
        self._until = np.zeros(3)  # monotonic time until which each axis is held
        self._value = np.zeros(3)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name="ijoy-keyboard", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        import select as _select

        while not self._stop.is_set():
            ready, _, _ = _select.select([self.fd], [], [], 0.05)
            if not ready:
                continue
            try:
                chars = os.read(self.fd, 64).decode("utf-8", "ignore").lower()
            except OSError:
                return
            now = time.monotonic()
            with self._lock:
                for ch in chars:
                    if ch == " ":
                        self._until[:] = 0.0
                    elif ch in _KEYS:
                        axis, sign = _KEYS[ch]
                        self._value[axis] = sign
                        self._until[axis] = now + self.hold

    def axes(self, t: float = 0.0) -> np.ndarray:
        now = time.monotonic()
        with self._lock:
            return np.where(self._until > now, self._value, 0.0)

    def close(self) -> None:
        import termios

        self._stop.set()
        self._thread.join(timeout=1.0)
        try:
            termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)
        except termios.error:
            pass


# ---------------------------------------------------------------------------------------------- gamepads


def gamepad_axes(raw, mapping=GAMEPAD_AXES) -> np.ndarray:
    """(3,) forward, left, turn from a joystick's raw SDL axis values (each in [-1, 1]) and ``mapping``.

    ``mapping``: three ``(axis index, sign)``; an index beyond the device's axes reads 0.

    Example:
      >>> from ijoy_jax.live import gamepad_axes
      >>> gamepad_axes([0.5, -1.0, 0.0, 0.25]).tolist()   # stick up and right, right stick right
      [1.0, -0.5, -0.25]
    """
    raw = np.asarray(raw, np.float64).reshape(-1)
    out = np.zeros(3)
    for k, (index, sign) in enumerate(mapping):
        if 0 <= index < raw.shape[0]:
            out[k] = sign * raw[index]
    return np.where(np.isfinite(out), np.clip(out, -1.0, 1.0), 0.0) + 0.0


class Gamepad:
    """A gamepad or joystick through SDL (pygame-ce): the first one found, or ``index``.

    Raises :class:`InputError` when pygame-ce is missing or no joystick is connected. SDL reads
    ``/dev/input/event*``: the user needs read access (the ``input`` group, or a udev rule).
    """

    def __init__(self, index: int = 0, mapping=GAMEPAD_AXES):
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        try:
            import pygame
        except ImportError:
            raise InputError("gamepad input needs pygame-ce: pip install 'ijoy_jax[live]'") from None
        pygame.display.init()  # the event queue SDL fills with the joystick's state (dummy video driver)
        pygame.joystick.init()
        pygame.event.pump()
        count = pygame.joystick.get_count()
        if count <= index:
            pygame.joystick.quit()
            pygame.display.quit()
            raise InputError(f"no gamepad found (SDL sees {count} joystick(s)); connect one, check read access to "
                             "/dev/input/event*, or use --input view / --input keyboard / --script")
        self._pygame = pygame
        self.joystick = pygame.joystick.Joystick(index)
        self.name = self.joystick.get_name()
        self.mapping = mapping

    def axes(self, t: float = 0.0) -> np.ndarray:
        self._pygame.event.pump()
        js = self.joystick
        return gamepad_axes([js.get_axis(i) for i in range(js.get_numaxes())], self.mapping)

    def close(self) -> None:
        self._pygame.joystick.quit()
        self._pygame.display.quit()

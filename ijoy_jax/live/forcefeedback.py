"""Force feedback on a Linux joystick through evdev: the haptic cue and ALDURO's centring and straight-ahead effects.

The effects are the kernel's ``struct ff_effect`` (linux/input.h) as python-evdev's ctypes structures
(:func:`effect`): :func:`ijoy_jax.haptics.linux_constant` and :func:`~ijoy_jax.haptics.linux_spring` give
their fields from :mod:`ijoy_jax.haptics.effects`, :func:`rumble` those of a rumble. An
:class:`EvdevFeedback` device plays

* ALDURO's device-originating forces (the paper's Fig. 4), uploaded once: auto-centring and
  straight-ahead as spring conditions (``FF_SPRING``) when the device has them,
* the cue's force every control tick as a constant force (``FF_CONSTANT``), updated in place, or, on a
  gamepad that only rumbles (``FF_RUMBLE``), as a rumble whose strength is the force's magnitude.

python-evdev's ``upload_effect`` before 1.9 did not write the id the kernel assigned back into the
effect (gvalkov/python-evdev#250): every update with id -1 then allocated a new effect until the device
ran out of slots (``ENOSPC``, typically after 16). Each effect's id is kept here and set on the effect
before every upload, so an update replaces the effect instead of allocating another, whatever the
version.

Without a device (no ``/dev/input``, none with force feedback, no permission, no python-evdev)
:func:`open_device` returns a :class:`NoFeedback` whose ``description`` says why, and the drive goes on
without force. Permissions: the user needs write access to ``/dev/input/eventN`` (the ``input`` group or
a udev rule; docs/drive.md).
"""

from __future__ import annotations

import numpy as np

from ijoy_jax.haptics import effects as fx

__all__ = ["INFINITE", "EvdevFeedback", "NoFeedback", "cue_constant", "effect", "open_device", "rumble"]

INFINITE = 0
"""``replay.length`` of an effect that plays until stopped (ms; 0 = no end in the kernel's ff-memless core)."""

_UNION = {"constant": "ff_constant_effect", "condition": "ff_condition_effect", "rumble": "ff_rumble_effect"}


def effect(fields: dict, *, effect_id: int = -1, length_ms: int = INFINITE, delay_ms: int = 0):
    """A python-evdev ``ff.Effect`` (the kernel's ``struct ff_effect``) from a fields dict.

    ``fields``: ``{"type": FF_*, "direction": u16, "u": {"constant": {"level": s16}}}``, ``{"condition":
    [axis X fields, axis Y fields]}`` or ``{"rumble": {"strong_magnitude": u16, "weak_magnitude": u16}}``
    (:func:`ijoy_jax.haptics.linux_constant`, :func:`~ijoy_jax.haptics.linux_spring`, :func:`rumble`).
    ``effect_id`` -1 asks the kernel for a new effect; an id it gave updates that effect.
    """
    from evdev import ff

    e = ff.Effect()
    e.type = int(fields["type"])
    e.id = int(effect_id)
    e.direction = int(fields.get("direction", 0))
    e.ff_trigger = ff.Trigger(0, 0)
    e.ff_replay = ff.Replay(int(length_ms), int(delay_ms))
    (kind, value), = fields["u"].items()
    if kind == "constant":
        e.u.ff_constant_effect = ff.Constant(int(value["level"]), ff.Envelope(0, 0, 0, 0))
    elif kind == "condition":
        conds = (ff.Condition * 2)()
        for axis, c in enumerate(value):
            conds[axis] = ff.Condition(c["right_saturation"], c["left_saturation"], c["right_coeff"],
                                       c["left_coeff"], c["deadband"], c["center"])
        e.u.ff_condition_effect = conds
    elif kind == "rumble":
        e.u.ff_rumble_effect = ff.Rumble(int(value["strong_magnitude"]), int(value["weak_magnitude"]))
    else:
        raise ValueError(f"unknown effect kind {kind!r} (constant, condition or rumble)")
    return e


def rumble(magnitude) -> dict:
    """An ``FF_RUMBLE`` effect's fields for a strength in [0, 1] (both motors; the light one at half)."""
    from evdev import ecodes

    m = float(np.clip(np.nan_to_num(magnitude), 0.0, 1.0))
    return {"type": ecodes.FF_RUMBLE, "direction": 0,
            "u": {"rumble": {"strong_magnitude": int(round(m * 0xFFFF)), "weak_magnitude": int(round(m * 0x7FFF))}}}


def cue_constant(force, config: fx.JoystickForceConfig) -> dict:
    """The ``FF_CONSTANT`` fields that play a cue force (3,) (forward, sideways, turn; fractions of the device's
    maximum, :func:`ijoy_jax.cue.tick_force`) on a device configured by ``config``: the force in newtons
    reduced onto the device's two axes by projection (``config.axes``), saturated at ``config.max_force``,
    as :func:`ijoy_jax.cue.device_effects` does."""
    max_force = float(config.max_force)
    f = np.nan_to_num(np.asarray(force, np.float64)) * max_force
    planar = np.asarray(config.axes, np.float64) @ f
    norm = float(np.hypot(*planar))
    if norm > max_force > 0:
        planar *= max_force / norm
    return fx.linux_constant(fx.constant(planar), max_force)


class NoFeedback:
    """No force-feedback device: :meth:`update` does nothing; ``description`` says why."""

    def __init__(self, reason: str):
        self.description = f"off ({reason})"
        self.updates = 0

    def update(self, force, command=None) -> None:
        self.updates += 1

    def close(self) -> None:
        pass


class EvdevFeedback:
    """A Linux force-feedback device (``/dev/input/eventN``) playing the cue and ALDURO's device forces.

    Args:
      device: an ``evdev.InputDevice`` with ``EV_FF`` capabilities.
      config: the joystick's :class:`~ijoy_jax.haptics.JoystickForceConfig` (maximum force, axes, the
        centring and straight-ahead springs); :func:`ijoy_jax.haptics.default_joystick_config` by default.
      travel: m of stick deflection at full scale (scales the springs' coefficients).
    """

    def __init__(self, device, config: fx.JoystickForceConfig | None = None, travel: float = 0.03):
        from evdev import ecodes

        self.device = device
        self.config = fx.default_config() if config is None else config
        self.travel = float(travel)
        caps = set(device.capabilities().get(ecodes.EV_FF, []))
        self.has_constant = ecodes.FF_CONSTANT in caps
        self.has_spring = ecodes.FF_SPRING in caps
        self.has_rumble = ecodes.FF_RUMBLE in caps
        self.ids: dict[str, int] = {}
        self.updates = 0
        kinds = [n for n, ok in (("constant", self.has_constant), ("spring", self.has_spring),
                                 ("rumble", self.has_rumble)) if ok]
        self.description = f"{device.name} ({device.path}: {', '.join(kinds) or 'no usable effect'})"
        if self.has_spring:
            mf = float(self.config.max_force)
            self._upload("centring", fx.linux_spring(self.config.centring, mf, self.travel))
            self._upload("straight_ahead", fx.linux_spring(self.config.straight_ahead, mf, self.travel))

    def _upload(self, name: str, fields: dict) -> int:
        """Upload (or update in place) the effect ``name``; start it the first time."""
        from evdev import ecodes

        e = effect(fields, effect_id=self.ids.get(name, -1))
        new = name not in self.ids
        ff_id = self.device.upload_effect(e)
        e.id = ff_id  # gvalkov/python-evdev#250: older versions leave -1 here
        self.ids[name] = ff_id
        if new:
            self.device.write(ecodes.EV_FF, ff_id, 1)
        return ff_id

    def update(self, force, command=None) -> None:
        """Play the cue force (3,) (fractions of the device's maximum) now."""
        self.updates += 1
        if self.has_constant:
            self._upload("cue", cue_constant(force, self.config))
        elif self.has_rumble:
            self._upload("cue", rumble(float(np.linalg.norm(np.nan_to_num(np.asarray(force, np.float64)[:2])))))

    def close(self) -> None:
        from evdev import ecodes

        for ff_id in self.ids.values():
            try:
                self.device.write(ecodes.EV_FF, ff_id, 0)
                self.device.erase_effect(ff_id)
            except OSError:
                pass
        self.ids.clear()
        self.device.close()


def open_device(path: str | None = None, config: fx.JoystickForceConfig | None = None):
    """The force-feedback device at ``path``, or the first one found; a :class:`NoFeedback` saying why if none."""
    try:
        import evdev
        from evdev import ecodes
    except ImportError:
        return NoFeedback("python-evdev is not installed: pip install 'ijoy_jax[live]'")
    if path is not None:
        try:
            dev = evdev.InputDevice(path)
        except OSError as e:
            return NoFeedback(f"cannot open {path}: {e.strerror or e}")
        if ecodes.EV_FF not in dev.capabilities():
            dev.close()
            return NoFeedback(f"{path} ({dev.name}) has no force feedback")
        return EvdevFeedback(dev, config)
    paths = evdev.list_devices()
    if not paths:
        return NoFeedback("no input devices readable in /dev/input (none connected, or no permission: the "
                          "'input' group)")
    for p in paths:
        try:
            dev = evdev.InputDevice(p)
        except OSError:
            continue
        if ecodes.EV_FF in dev.capabilities():
            try:
                return EvdevFeedback(dev, config)
            except OSError as e:
                dev.close()
                return NoFeedback(f"{p} ({dev.name}) refused the effects: {e.strerror or e}")
        dev.close()
    return NoFeedback(f"none of the {len(paths)} input devices has force feedback")

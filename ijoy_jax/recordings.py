"""Recording a live drive to MCAP, and reading it back.

MCAP (https://mcap.dev, the ``mcap`` package) is the log format of ROS 2 and of Foxglove: a recorded
drive opens in Foxglove Studio, ``mcap info``/``mcap cat`` and any MCAP reader, beside a robot's own
logs. Messages are JSON (``message_encoding = "json"``), each channel with a JSON Schema
(``encoding = "jsonschema"``), so a reader needs nothing of this package. Floats are written as
the shortest decimal that reads back to the same float64 (Python's ``repr``); the robot's float32
values convert to float64 exactly, so a reading reproduces every bit.

A file holds::

  metadata "ijoy.drive"   {"config": JSON}: the drive's settings (robot, terrain spec, body, decider,
                          deadzone, decide_at, step time, versions, date) (:class:`DriveConfig`)
  attachment "terrain.npz"  the terrain's arrays (height, free, resolution, origin, has_height), so a
                          replay needs no generator or image file
  attachment "robot.npz"  the robot model's leaves and static fields (:func:`robot_to_npz`)
  /ijoy/input     per control tick: t (s, the drive's clock), axes (3,), command (3,), source
  /ijoy/decision  per decision: step, t (s, when the command was read), axes, command, stance (3,),
                  stance_side, swing_from (3,), foothold (6,), valid, cost, index, terms (the chosen
                  foothold's named FootCost terms, :class:`ijoy_jax.FootCostTerms`), latency_s,
                  deadline_slack_s, decider
  /ijoy/state     per executed step: step, t (s, at its end), sent (6,), go, feet (2, 3) after it, and
                  the physics robot's step log (placement and tilt errors, fallen, obstacle contact)
  /ijoy/summary   once at the end: steps, latency p50/p99/max (s), late decisions, wall time

Log times are the drive's clock in nanoseconds (virtual time when headless, so a replay logs the same
times); publish times are the wall clock's.

:func:`read_recording` checks a file once, where it is read, with ``jsonschema``: every message against its
channel's schema (:data:`CHANNELS`: required keys, types, finite numbers, lengths and ranges), the config against
:data:`CONFIG_SCHEMA`, the attachments decoded and checked as the library checks a terrain and a robot. A
corrupt or hand-edited file is one ValueError line naming the file and what is wrong, never a raw decoder's
exception, so ``ijoy drive --replay`` and a sweep's ``[command] file`` / ``[terrain] recording`` report it
as their own one-line errors.
"""

from __future__ import annotations

import dataclasses
import functools
import io
import json
import math
import struct
import time
import zipfile
import zlib
from pathlib import Path
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ijoy_jax import robots
from ijoy_jax import terrain as terrain_mod
from ijoy_jax.extras import require
from ijoy_jax.robots import Robot, TerrainMetrics
from ijoy_jax.terrain import Terrain

__all__ = ["CHANNELS", "CONFIG_SCHEMA", "Recorder", "Recording", "json_ready", "read_recording", "robot_from_npz",
           "robot_to_npz", "terrain_from_npz", "terrain_to_npz"]

_FLOAT32_MAX = float(np.finfo(np.float32).max)
_OBJ = {"type": "object"}
_NUM = {"type": "number"}  # finite, as JSON's numbers are (_validator)
_TIME = {"type": "number", "minimum": 0}
_F32 = {"type": "number", "minimum": -_FLOAT32_MAX, "maximum": _FLOAT32_MAX}  # read back as float32
_VEC = {"type": "array", "items": _F32}
_INF = {"enum": ["inf"]}  # +inf as json_ready writes it: a rejected foothold's cost


def _vec(n: int) -> dict:
    return {**_VEC, "minItems": n, "maxItems": n}


def _channel(title: str, properties: dict) -> dict:
    return {"title": title, **_OBJ, "properties": properties, "required": list(properties)}


CHANNELS: dict[str, dict] = {
    "/ijoy/input": _channel("ijoy.Input", {
        "t": _TIME, "axes": _vec(3), "command": _vec(3), "source": {"type": "string"}}),
    "/ijoy/decision": _channel("ijoy.Decision", {
        "step": {"type": "integer", "minimum": 1}, "t": _TIME, "axes": _vec(3), "command": _vec(3),
        "stance": _vec(3), "stance_side": {"type": "number", "enum": [1, -1]}, "swing_from": _vec(3),
        "foothold": _vec(6), "valid": {"type": "boolean"}, "cost": {"anyOf": [_NUM, _INF]},
        "index": {"type": "integer", "minimum": -1}, "terms": {**_OBJ, "additionalProperties": {"anyOf": [_NUM, _INF]}},
        "latency_s": _TIME, "deadline_slack_s": _NUM, "decider": {"type": "string"}}),
    "/ijoy/state": _channel("ijoy.State", {
        "step": {"type": "integer", "minimum": 0}, "t": _TIME, "sent": _vec(6), "go": {"type": "boolean"},
        "feet": {"type": "array", "items": _vec(3), "minItems": 2, "maxItems": 2}, "log": _OBJ}),
    "/ijoy/summary": {"title": "ijoy.Summary", **_OBJ},
}
"""Every channel's JSON Schema (draft 2020-12 keywords), by topic: what a message must hold
(:func:`read_recording` refuses a message that breaks it). Vectors are float32 values (finite within float32's
range); a rejected foothold's ``cost`` and terms are ``"inf"``."""

_FRACTION = {"type": "number", "minimum": 0, "exclusiveMaximum": 1}
_SETTINGS = {
    "terrain": _OBJ, "body": {"type": "string"}, "model": {"type": "string", "enum": list(robots.MODELS)},
    "margin": {"type": "number", "minimum": 0},
    "start": {"anyOf": [{"type": "null"}, _vec(3)]}, "first_swing": {"type": "integer", "enum": [1, -1]},
    "deadzone": _FRACTION, "decide_at": _FRACTION, "control_dt": {"type": "number", "exclusiveMinimum": 0},
    "decider": {"type": "string"}, "server": {"anyOf": [{"type": "null"}, {"type": "string"}]},
}
_ADDED = ("model",)  # settings newer than the format: a recording made before one has its default (the biped)
CONFIG_SCHEMA: dict = {
    "title": "ijoy.drive config", **_OBJ, "required": ["settings", "start"], "properties": {
        "settings": {**_OBJ, "properties": _SETTINGS, "required": [k for k in _SETTINGS if k not in _ADDED]},
        "start": {"type": "array", "items": _vec(3), "minItems": 2, "maxItems": 2}},
}
"""The JSON Schema of the ``ijoy.drive`` metadata's ``config``: the drive's settings
(:class:`ijoy_jax.live.DriveSettings`, each field typed and in range; each required but ``model``, which
recordings made before the G1 lack) and its start feet (2, 3) (m, rad).
Other keys (versions, date, machine) are free."""

_POSITIVE = {"type": "number", "exclusiveMinimum": 0}
_STATIC_SCHEMA = {  # robot_to_npz's static fields: radii (m) and robots.target_lattice's (lo, step, counts)
    **_OBJ, "required": ["max_radius", "max_swing", "target_grid"], "additionalProperties": False, "properties": {
        "max_radius": _POSITIVE, "max_swing": _POSITIVE, "target_grid": {
            "type": "array", "minItems": 3, "maxItems": 3, "prefixItems": [
                _vec(3), {**_vec(3), "items": {**_F32, "exclusiveMinimum": 0}},
                {**_vec(3), "items": {"type": "integer", "minimum": 1, "maximum": _FLOAT32_MAX}}]}},
}


def _finite(v) -> bool:
    """``v`` (an int or float) is finite as a float64."""
    try:
        return math.isfinite(v)
    except OverflowError:  # an integer beyond float64
        return False


@functools.cache
def _validator(name: str):
    """The draft 2020-12 validator of the schema ``name`` (a topic of :data:`CHANNELS`, "config" or "static").

    Its numbers and integers are finite, as JSON's are. Python's json module reads the NaN and Infinity literals
    a careless editor writes as float NaN and inf, and an integer literal of any length; no JSON Schema keyword
    refuses a NaN (it passes ``minimum`` and ``maximum`` vacuously), so the type checker does, and the error
    names the field as any type error does.
    """
    from jsonschema import Draft202012Validator, validators

    base = Draft202012Validator.TYPE_CHECKER
    finite = {t: lambda _, v, t=t: base.is_type(v, t) and _finite(v) for t in ("number", "integer")}
    validator = validators.extend(Draft202012Validator, type_checker=base.redefine_many(finite))
    return validator({"config": CONFIG_SCHEMA, "static": _STATIC_SCHEMA}.get(name) or CHANNELS[name])


def _problem(value, name: str) -> str | None:
    """The first way ``value`` breaks the schema ``name`` (:func:`_validator`; jsonschema's best match) as
    "field: what is wrong", the field a path from ``name`` (a topic's messages: from the message) such as
    ``config.start[0][2]``; None if it holds."""
    from jsonschema.exceptions import best_match

    where = "" if name.startswith("/") else name
    try:
        error = best_match(_validator(name).iter_errors(value))
    except RecursionError:  # a value nested almost as deep as json.loads reads, shown in the message
        return f"{where}: nested too deeply" if where else "nested too deeply"
    if error is None:
        return None
    where += "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in error.absolute_path)
    message, shown = error.message, repr(error.instance)
    if error.validator == "anyOf":  # jsonschema says no alternative holds: say how each fails
        message += f" ({'; '.join(e.message.removeprefix(shown).strip() for e in error.context)})"
    elif error.validator in ("minItems", "maxItems"):  # ... that an array is too short or long: say how long
        message += f" ({error.validator} {error.validator_value}, got {len(error.instance)})"
    if len(shown) > 40 and message.startswith(shown):  # jsonschema shows the whole value; its start is enough
        message = shown[:37] + "..." + message[len(shown):]
    return f"{where.removeprefix('.')}: {message}" if where else message


def _one_line(e: BaseException) -> str:
    """An exception as one line: its type (a decoder's error means little without it) and its text."""
    return f"{type(e).__name__}: {' '.join(str(e).split())}"


def json_ready(x):
    """JSON-ready: arrays to lists, NumPy scalars to Python ones; infinities and NaN as strings ("inf")."""
    if isinstance(x, dict):
        return {str(k): json_ready(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_ready(v) for v in x]
    if isinstance(x, np.ndarray) or hasattr(x, "__array__") and not np.isscalar(x):
        return json_ready(np.asarray(x).tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer, int)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if np.isfinite(v) else repr(v)
    return x


def _number(v):
    """A JSON value back to a float where it was one written as a string ("inf", "-inf", "nan")."""
    return float(v) if isinstance(v, str) else v


def terrain_to_npz(terrain: Terrain) -> bytes:
    """The terrain's arrays as ``.npz`` bytes (height, free, resolution, origin, has_height)."""
    buf = io.BytesIO()
    np.savez_compressed(buf, height=np.asarray(terrain.height), free=np.asarray(terrain.free),
                        resolution=np.float64(terrain.resolution), origin=np.asarray(terrain.origin),
                        has_height=np.bool_(terrain.has_height))
    return buf.getvalue()


def _decode_errors() -> tuple:
    """What decoding corrupt bytes raises: zip and zlib (``.npz``), NumPy's ``.npy`` reader, MCAP's reader and
    its chunk decompressors (zstd; lz4's frame errors are RuntimeErrors, as is an encrypted zip member)."""
    from mcap.exceptions import McapError

    errors = (McapError, zipfile.BadZipFile, zlib.error, OSError, EOFError, KeyError, IndexError, ValueError,
              TypeError, struct.error, NotImplementedError, RuntimeError)
    try:
        import zstandard
    except ImportError:
        return errors
    return (*errors, zstandard.ZstdError)


def _npz(data: bytes, what: str, text: tuple = ()) -> dict:
    """The arrays of ``.npz`` bytes, every one read (so a corrupt member fails here) and numeric (bool, int or
    float) but those named in ``text``; ValueError (one line) otherwise."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except _decode_errors() as e:
        raise ValueError(f"not a readable {what} .npz ({_one_line(e)})") from None
    for k, v in arrays.items():
        if k not in text and v.dtype.kind not in "biuf":
            raise ValueError(f"{what} array {k!r} must be numbers, got dtype {v.dtype}")
    return arrays


def terrain_from_npz(data: bytes) -> Terrain:
    """The :class:`~ijoy_jax.Terrain` of :func:`terrain_to_npz`'s bytes (the same arrays, bit for bit).

    Raises:
      ValueError: one line: bytes that are not such an ``.npz`` (corrupt, a missing or extra array), or arrays
        :func:`ijoy_jax.terrain.from_arrays` refuses (shapes, NaN or inf heights, resolution, origin).
    """
    z = _npz(data, "terrain")
    keys = {"height", "free", "resolution", "origin", "has_height"}
    if set(z) != keys:
        raise ValueError(f"a terrain .npz holds the arrays {sorted(keys)}, got {sorted(z)}")
    if z["has_height"].shape != () or z["has_height"].dtype != np.bool_:
        raise ValueError(f"has_height must be one bool, got {z['has_height'].dtype} of shape {z['has_height'].shape}")
    if z["resolution"].shape != () or z["resolution"].dtype.kind not in "iuf":
        raise ValueError(f"resolution must be one number, got {z['resolution'].dtype} of shape "
                         f"{z['resolution'].shape}")
    try:
        t = terrain_mod.from_arrays(z["height"], z["free"], float(z["resolution"]), origin=z["origin"])
    except (TypeError, ValueError) as e:
        raise ValueError(f"the terrain's arrays: {' '.join(str(e).split())}") from None
    return t.replace(has_height=bool(z["has_height"]))


def robot_to_npz(robot: Robot) -> bytes:
    """The robot as ``.npz`` bytes: every leaf (``metrics.*`` for the terrain metrics) and its static fields
    (``static``, JSON), so :func:`robot_from_npz` rebuilds the same robot bit for bit."""
    arrays, static = {}, {}
    for f in dataclasses.fields(robot):
        v = getattr(robot, f.name)
        if f.metadata.get("static"):
            static[f.name] = v
        elif f.name == "metrics":
            arrays.update({f"metrics.{g.name}": np.asarray(getattr(v, g.name)) for g in dataclasses.fields(v)})
        else:
            arrays[f.name] = np.asarray(v)
    buf = io.BytesIO()
    np.savez_compressed(buf, static=np.asarray(json.dumps(static)), **arrays)
    return buf.getvalue()


def _static(static) -> dict:
    """The robot's static fields (their JSON), checked: ``max_radius`` and ``max_swing`` positive (m),
    ``target_grid`` three 3-tuples ``(lo, step, counts)`` with steps > 0 and whole counts >= 1
    (:func:`ijoy_jax.robots.target_lattice`)."""
    if why := _problem(static, "static"):
        raise ValueError(why)
    lo, step, counts = static["target_grid"]
    return {"max_radius": float(static["max_radius"]), "max_swing": float(static["max_swing"]),
            "target_grid": (tuple(lo), tuple(step), tuple(int(c) for c in counts))}


def robot_from_npz(data: bytes) -> Robot:
    """The :class:`~ijoy_jax.Robot` of :func:`robot_to_npz`'s bytes.

    Raises:
      ValueError: one line: bytes that are not such an ``.npz`` (corrupt, a missing or unknown leaf, static
        fields that are not JSON), or a robot :func:`ijoy_jax.robots.check_robot` refuses (a leaf's shape, dtype
        or value: NaN, inf, out of range).
    """
    z = _npz(data, "robot", text=("static",))
    metric_names = [f.name for f in dataclasses.fields(TerrainMetrics)]
    leaf_names = [f.name for f in dataclasses.fields(Robot) if not f.metadata.get("static") and f.name != "metrics"]
    keys = {"static", *leaf_names, *(f"metrics.{n}" for n in metric_names)}
    if set(z) != keys:
        missing, extra = sorted(keys - set(z)), sorted(set(z) - keys)
        raise ValueError("a robot .npz holds every leaf and its static fields: "
                         + (f"missing {missing}" if missing else "") + ("; " if missing and extra else "")
                         + (f"unknown {extra}" if extra else ""))
    try:
        static = json.loads(str(z["static"]))
    except (ValueError, RecursionError) as e:
        raise ValueError(f"static fields are not JSON ({_one_line(e)})") from None
    static = _static(static)
    try:
        metrics = TerrainMetrics(**{n: jnp.asarray(z[f"metrics.{n}"]) for n in metric_names})
        robot = Robot(**{n: jnp.asarray(z[n]) for n in leaf_names}, metrics=metrics, **static)
        robots.check_robot(robot)
    except (TypeError, ValueError) as e:
        raise ValueError(" ".join(str(e).split())) from None
    return robot


class Recorder:
    """Writes one drive to an MCAP file (the layout: the module docstring). Use it as a context manager."""

    def __init__(self, path, config: dict, terrain: Terrain, robot: Robot):
        require("live", "mcap", "jsonschema", what="recording a drive")
        from mcap.writer import Writer

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")
        self._writer = Writer(self._file)
        self._writer.start(profile="", library="ijoy_jax")
        self._channels = {}
        for topic, schema in CHANNELS.items():
            sid = self._writer.register_schema(name=schema["title"], encoding="jsonschema",
                                               data=json.dumps(schema).encode())
            self._channels[topic] = self._writer.register_channel(topic=topic, message_encoding="json",
                                                                  schema_id=sid)
        self._seq = 0
        now = time.time_ns()
        self._writer.add_metadata("ijoy.drive", {"config": json.dumps(json_ready(config))})
        self._writer.add_attachment(create_time=now, log_time=0, name="terrain.npz",
                                    media_type="application/x-npz", data=terrain_to_npz(terrain))
        self._writer.add_attachment(create_time=now, log_time=0, name="robot.npz",
                                    media_type="application/x-npz", data=robot_to_npz(robot))
        self.closed = False

    def write(self, topic: str, t: float, message: dict) -> None:
        """One message on ``topic`` at the drive's time ``t`` (s)."""
        self._seq += 1
        self._writer.add_message(channel_id=self._channels[topic], log_time=max(int(round(t * 1e9)), 0),
                                 data=json.dumps(json_ready(message)).encode(), publish_time=time.time_ns(),
                                 sequence=self._seq)

    def close(self, summary: dict | None = None) -> None:
        if self.closed:
            return
        if summary is not None:
            self.write("/ijoy/summary", float(summary.get("t", 0.0)), summary)
        self._writer.finish()
        self._file.close()
        self.closed = True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class Recording(NamedTuple):
    """A recorded drive (:func:`read_recording`): ``config`` dict, ``terrain``, ``robot``, and each channel's
    messages (lists of dicts, in log order; infinities back as floats)."""

    config: dict
    terrain: Terrain
    robot: Robot
    inputs: list
    decisions: list
    states: list
    summary: dict | None


_ATTACHMENTS = {"terrain.npz": terrain_from_npz, "robot.npz": robot_from_npz}


def read_recording(path) -> Recording:
    """Read an MCAP drive recording, checked (:data:`CHANNELS`, :data:`CONFIG_SCHEMA`, the attachments).

    Raises:
      MissingExtraError: without the ``live`` extra (mcap, jsonschema).
      ValueError: one line naming the file and what is wrong: missing, not MCAP, cut short or corrupt (chunk
        CRCs are checked; an attachment that does not decode), no drive in it, a config, attachment or
        message that breaks its schema (a missing key, a wrong type, NaN or inf, out of range), input times
        out of order, or a ``control_dt`` longer than the robot's step.
    """
    path = Path(path)
    where = repr(str(path))
    if not path.is_file():
        raise ValueError(f"recording {where} does not exist")
    require("live", "mcap", "jsonschema", what=f"reading the drive recording {where}")
    topics: dict[str, list] = {t: [] for t in CHANNELS}
    config, raw = None, {}
    try:
        with open(path, "rb") as f:
            from mcap.reader import make_reader

            reader = make_reader(f, validate_crcs=True)
            for meta in reader.iter_metadata():
                if meta.name == "ijoy.drive":
                    config = meta.metadata.get("config")
            for att in reader.iter_attachments():
                if att.name in _ATTACHMENTS:
                    raw[att.name] = att.data
            for _, channel, message in reader.iter_messages(topics=list(CHANNELS)):
                topics[channel.topic].append(message.data)
    except _decode_errors() as e:  # a short, torn or bit-flipped file
        raise ValueError(f"{where} is not a readable ijoy drive recording (MCAP): {_one_line(e)}") from None
    if config is None or set(raw) != set(_ATTACHMENTS):
        raise ValueError(f"{where} is an MCAP file without an ijoy drive (no 'ijoy.drive' metadata with a "
                         "config, terrain or robot attachment)")
    try:
        config = json.loads(config)
    except (ValueError, RecursionError) as e:  # RecursionError: arrays or objects nested too deep
        raise ValueError(f"{where}: the 'ijoy.drive' metadata's config is not JSON ({_one_line(e)})") from None
    if why := _problem(config, "config"):
        raise ValueError(f"{where}: the 'ijoy.drive' metadata: {why}")
    decoded = {}
    for name, decode in _ATTACHMENTS.items():
        try:
            decoded[name] = decode(raw[name])
        except ValueError as e:
            raise ValueError(f"{where}: attachment {name!r}: {e}") from None
    for topic, messages in topics.items():
        for i, data in enumerate(messages):
            try:
                messages[i] = json.loads(data)
            except (ValueError, RecursionError) as e:  # UnicodeDecodeError is a ValueError
                raise ValueError(f"{where}: {topic} message {i + 1} is not JSON ({_one_line(e)})") from None
            if why := _problem(messages[i], topic):
                raise ValueError(f"{where}: {topic} message {i + 1}: {why}")
    times = [m["t"] for m in topics["/ijoy/input"]]
    if any(b < a for a, b in zip(times, times[1:], strict=False)):
        raise ValueError(f"{where}: the /ijoy/input times are not in order (a replay reads the stick by time)")
    step_time = float(decoded["robot.npz"].step_time)
    control_dt = config["settings"]["control_dt"]
    if control_dt > step_time:
        raise ValueError(f"{where}: the 'ijoy.drive' metadata: config.settings.control_dt: must be at most the "
                         f"robot's step time {step_time:g} s (one tick of a step), got {control_dt}")
    for d in topics["/ijoy/decision"]:
        d["cost"] = _number(d["cost"])
        d["terms"] = {k: _number(v) for k, v in d["terms"].items()}
    summary = topics["/ijoy/summary"][-1] if topics["/ijoy/summary"] else None
    return Recording(config, decoded["terrain.npz"], decoded["robot.npz"], topics["/ijoy/input"],
                     topics["/ijoy/decision"], topics["/ijoy/state"], summary)

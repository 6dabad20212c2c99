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
"""

from __future__ import annotations

import dataclasses
import io
import json
import struct
import time
from pathlib import Path
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ijoy_jax import terrain as terrain_mod
from ijoy_jax.robots import Robot, TerrainMetrics
from ijoy_jax.terrain import Terrain

__all__ = ["CHANNELS", "Recorder", "Recording", "json_ready", "read_recording", "robot_from_npz", "robot_to_npz",
           "terrain_from_npz", "terrain_to_npz"]

_OBJ = {"type": "object"}
_NUM = {"type": "number"}
_VEC = {"type": "array", "items": _NUM}
CHANNELS: dict[str, dict] = {
    "/ijoy/input": {"title": "ijoy.Input", **_OBJ, "properties": {
        "t": _NUM, "axes": _VEC, "command": _VEC, "source": {"type": "string"}}},
    "/ijoy/decision": {"title": "ijoy.Decision", **_OBJ, "properties": {
        "step": {"type": "integer"}, "t": _NUM, "axes": _VEC, "command": _VEC, "stance": _VEC,
        "stance_side": _NUM, "swing_from": _VEC, "foothold": _VEC, "valid": {"type": "boolean"},
        "cost": {"type": ["number", "string"]}, "index": {"type": "integer"}, "terms": _OBJ, "latency_s": _NUM,
        "deadline_slack_s": _NUM, "decider": {"type": "string"}}},
    "/ijoy/state": {"title": "ijoy.State", **_OBJ, "properties": {
        "step": {"type": "integer"}, "t": _NUM, "sent": _VEC, "go": {"type": "boolean"},
        "feet": {"type": "array", "items": _VEC}, "log": _OBJ}},
    "/ijoy/summary": {"title": "ijoy.Summary", **_OBJ},
}
"""Every channel's JSON Schema (draft 2020-12 keywords), by topic."""


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


def terrain_from_npz(data: bytes) -> Terrain:
    """The :class:`~ijoy_jax.Terrain` of :func:`terrain_to_npz`'s bytes (the same arrays, bit for bit)."""
    z = np.load(io.BytesIO(data))
    t = terrain_mod.from_arrays(z["height"], z["free"], float(z["resolution"]), origin=z["origin"])
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


def _tuples(x):
    return tuple(_tuples(v) for v in x) if isinstance(x, list) else x


def robot_from_npz(data: bytes) -> Robot:
    """The :class:`~ijoy_jax.Robot` of :func:`robot_to_npz`'s bytes."""
    z = np.load(io.BytesIO(data))
    static = {k: _tuples(v) for k, v in json.loads(str(z["static"])).items()}
    metrics = TerrainMetrics(**{k.partition(".")[2]: jnp.asarray(z[k]) for k in z.files if k.startswith("metrics.")})
    leaves = {k: jnp.asarray(z[k]) for k in z.files if k != "static" and not k.startswith("metrics.")}
    return Robot(**leaves, metrics=metrics, **static)


class Recorder:
    """Writes one drive to an MCAP file (the layout: the module docstring). Use it as a context manager."""

    def __init__(self, path, config: dict, terrain: Terrain, robot: Robot):
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


def read_recording(path) -> Recording:
    """Read an MCAP drive recording. Raises ValueError (one line) for a file that is not one."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"recording {str(path)!r} does not exist")
    topics: dict[str, list] = {t: [] for t in CHANNELS}
    config, terrain, robot = None, None, None
    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            for meta in reader.iter_metadata():
                if meta.name == "ijoy.drive":
                    config = json.loads(meta.metadata["config"])
            for att in reader.iter_attachments():
                if att.name == "terrain.npz":
                    terrain = terrain_from_npz(att.data)
                elif att.name == "robot.npz":
                    robot = robot_from_npz(att.data)
            for _, channel, message in reader.iter_messages(topics=list(CHANNELS)):
                topics[channel.topic].append(json.loads(message.data))
    except (McapError, OSError, EOFError, KeyError, ValueError, struct.error) as e:  # a short or torn file: struct
        raise ValueError(f"{str(path)!r} is not a readable ijoy drive recording (MCAP): {e}") from None
    if config is None or terrain is None or robot is None:
        raise ValueError(f"{str(path)!r} is an MCAP file without an ijoy drive (no 'ijoy.drive' metadata, "
                         "terrain or robot attachment)")
    for d in topics["/ijoy/decision"]:
        d["cost"] = _number(d["cost"])
    summary = topics["/ijoy/summary"][-1] if topics["/ijoy/summary"] else None
    return Recording(config, terrain, robot, topics["/ijoy/input"], topics["/ijoy/decision"], topics["/ijoy/state"],
                     summary)

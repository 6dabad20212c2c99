"""Corrupt and hand-edited drive recordings (ijoy_jax.recordings): every way a file can be cut, bit-flipped or
edited ends in ONE ValueError line naming the file and what is wrong, in the library (read_recording), in a
sweep (``[command] file``, ``[terrain] recording``: "file: key: reason") and at the command line (``ijoy drive
--replay``: "ijoy: error: ..."), never a decoder's or a KeyError's traceback.

The recordings are written with ijoy_jax.live.Recorder directly (no drive: nothing compiles), one message of
each kind as the drive loop writes them, and edited by copying the MCAP file record by record (the edited
messages are JSON with Python's NaN and Infinity literals allowed, as a careless editor may write them).
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
from collections import Counter

import numpy as np
import pytest
from _sweep_util import write  # tests/ is on sys.path (pytest rootdir import)
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import Writer

import ijoy_jax as ij
from ijoy_jax import live, recordings, sweep
from ijoy_jax.apps import cli

SHAPE, RES = (20, 16), 0.05  # 1 m x 0.8 m, 2.5D
ROBOT = ij.robots.hrp2(margin=0.02, density=0.25)  # 19 actions
FEET = np.asarray(ij.robots.start_stance(ROBOT, 0.3, 0.4), np.float32).tolist()
TERMS = {name: 0.0 for name in live.loop.TERM_NAMES}
DROP = object()  # an edit that removes the key

DECISION = {"step": 1, "t": 0.0, "axes": [1.0, 0.0, 0.0], "command": [0.2, 0.0, 0.0], "stance": FEET[1],
            "stance_side": -1.0, "swing_from": FEET[0], "foothold": [0.5, 0.6, 0.0, 0.0, 0.0, 0.0], "valid": True,
            "cost": 0.25, "index": 7, "terms": TERMS, "latency_s": 0.02, "deadline_slack_s": 0.7, "decider": "local"}
REJECTED = {**DECISION, "step": 2, "t": 0.8, "valid": False, "cost": math.inf, "index": -1,
            "terms": {**TERMS, "total": math.inf, "obstacle": math.inf}}  # written as "inf"
STATE = {"step": 0, "t": 0.8, "sent": [0.0] * 6, "go": False, "feet": FEET, "log": {}}
INPUT = {"t": 0.0, "axes": [1.0, 0.0, 0.0], "command": [0.2, 0.0, 0.0], "source": "script"}

# Every key each kind of record must hold (the messages as the drive loop writes them; the config as live.run)
REQUIRED = [
    *(("config", k) for k in ("settings", "start")),
    *(("config.settings", f.name) for f in dataclasses.fields(live.DriveSettings) if f.name != "model"),
    *(("/ijoy/input", k) for k in INPUT),
    *(("/ijoy/decision", k) for k in DECISION),
    *(("/ijoy/state", k) for k in STATE),
]


def _base(path):
    """A recording as ijoy drive writes it: 2 input ticks, 2 decisions (one rejected: cost and terms inf), 3 step
    periods and the summary (NaN latencies written as "nan")."""
    height = np.linspace(0.0, 0.1, SHAPE[0] * SHAPE[1], dtype=np.float32).reshape(SHAPE)
    free = np.ones(SHAPE, bool)
    free[15:, :] = False  # a wall at x = 0.75 m
    terrain = ij.terrain.from_arrays(height, free, RES)
    config = {"settings": dataclasses.asdict(live.DriveSettings(terrain={"kind": "image", "path": "ground.png"})),
              "start": FEET, "realtime": False, "versions": {"ijoy_jax": "0"}}
    with live.Recorder(path, config, terrain, ROBOT) as rec:
        rec.write("/ijoy/input", 0.0, INPUT)
        rec.write("/ijoy/input", 0.01, {**INPUT, "t": 0.01})
        rec.write("/ijoy/state", 0.8, STATE)
        rec.write("/ijoy/decision", 0.0, DECISION)
        rec.write("/ijoy/state", 1.6, {**STATE, "step": 1, "t": 1.6, "sent": DECISION["foothold"], "go": True})
        rec.write("/ijoy/decision", 0.8, REJECTED)
        rec.write("/ijoy/state", 2.4, {**STATE, "step": 2, "t": 2.4})
        rec.close({"t": 2.4, "steps": 2, "latency_p50_s": math.nan})
    return path


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    return _base(tmp_path_factory.mktemp("recordings") / "drive.mcap")


def _rewrite(src, dst, *, config=None, message=None, attachment=None):
    """Copy a recording record by record, editing on the way.

    config(dict) -> dict | str: the 'ijoy.drive' metadata's config (a str is written as it is); message(topic, i,
    dict) -> dict | bytes: the i-th message of ``topic`` (bytes are written as they are); attachment(name, bytes)
    -> bytes. The writer computes
    the file's CRCs, so what is tested is the edited content, not MCAP's integrity checks.
    """
    with open(src, "rb") as f, open(dst, "wb") as g:
        reader, writer = make_reader(f), Writer(g)
        writer.start(profile="", library="test")
        for m in reader.iter_metadata():
            meta = dict(m.metadata)
            if m.name == "ijoy.drive" and config is not None:
                edited = config(json.loads(meta["config"]))
                meta["config"] = edited if isinstance(edited, str) else json.dumps(edited)
            writer.add_metadata(m.name, meta)
        for a in reader.iter_attachments():
            data = a.data if attachment is None else attachment(a.name, a.data)
            writer.add_attachment(a.create_time, a.log_time, a.name, a.media_type, data)
        ids, seen = {}, Counter()
        for schema, channel, msg in reader.iter_messages():
            if channel.topic not in ids:
                sid = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.topic] = writer.register_channel(channel.topic, channel.message_encoding, sid)
            data = msg.data
            if message is not None:
                data = message(channel.topic, seen[channel.topic], json.loads(data))
                data = data if isinstance(data, bytes) else json.dumps(data).encode()
            seen[channel.topic] += 1
            writer.add_message(ids[channel.topic], msg.log_time, data, msg.publish_time)
        writer.finish()
    return dst


def _set(obj: dict, dotted: str, value):
    """``obj`` with the key at ``dotted`` ("settings.control_dt") set to ``value`` (or removed: DROP)."""
    *parents, key = dotted.split(".")
    inner = obj
    for p in parents:
        inner = inner[p]
    if value is DROP:
        del inner[key]
    else:
        inner[key] = value
    return obj


def _edited(base, dst, where: str, key: str, value):
    """The base recording with ``key`` of ``where`` ("config", "config.settings" or a topic, whose first message
    is edited) set to ``value`` (DROP removes it)."""
    if where.startswith("config"):
        dotted = ".".join([*where.split(".")[1:], key])
        return _rewrite(base, dst, config=lambda c: _set(c, dotted, value))
    return _rewrite(base, dst, message=lambda t, i, m: _set(m, key, value) if (t, i) == (where, 0) else m)


def _npz(data: bytes, **changes) -> bytes:
    """An attachment's ``.npz`` with arrays replaced (a value), added, or removed (DROP): a valid zip, edited."""
    with np.load(io.BytesIO(data)) as z:
        arrays = {k: z[k] for k in z.files}
    for k, v in changes.items():
        if v is DROP:
            del arrays[k]
        else:
            arrays[k] = v
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def _flip(data: bytes, offset: int, bit: int = 4) -> bytes:
    b = bytearray(data)
    b[offset] ^= 1 << bit
    return bytes(b)


def _one_line(path, match: str = "") -> str:
    """read_recording(path) raises one ValueError line naming the file (and ``match``); returns it."""
    with pytest.raises(ValueError) as e:
        recordings.read_recording(path)
    msg = str(e.value)
    assert len(msg.splitlines()) == 1 and repr(str(path)) in msg, msg
    assert match in msg, msg
    return msg


def _read_or_one_line(path) -> recordings.Recording | None:
    """A recording that reads, or one ValueError line naming the file; anything else fails the test."""
    try:
        return recordings.read_recording(path)
    except ValueError as e:
        assert len(str(e).splitlines()) == 1 and repr(str(path)) in str(e), str(e)
        return None


def test_the_base_recording_reads(base):
    """The premise: the unedited file reads, with infinities back as floats, and feeds the sweep and a replay."""
    rec = recordings.read_recording(base)
    assert len(rec.inputs) == 2 and len(rec.decisions) == 2 and len(rec.states) == 3
    assert rec.decisions[1]["cost"] == math.inf and rec.decisions[1]["terms"]["total"] == math.inf
    assert rec.summary["steps"] == 2 and rec.terrain.shape == SHAPE and rec.robot.num_actions == ROBOT.num_actions
    assert len(sweep.recorded.read_commands(base).commands) == 2
    assert sweep.recorded.read_terrain(base).start.shape == (2, 3)
    assert len(live.session.ReplayInput(rec).commands) == 2


def test_the_schemas_a_recording_carries_hold_for_a_standard_validator(base):
    """Each channel's schema in the file is a valid draft 2020-12 schema, and every message holds under it for
    plain jsonschema, as for any reader of the file (read_recording adds only that numbers are finite)."""
    from jsonschema import Draft202012Validator

    with open(base, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            Draft202012Validator.check_schema(json.loads(schema.data))
            Draft202012Validator(json.loads(schema.data)).validate(json.loads(message.data))
    Draft202012Validator.check_schema(recordings.CONFIG_SCHEMA)


# ------------------------------------------------------------------------------------------- cut, flipped bytes


@given(cut=st.floats(0.0, 1.0, exclude_max=True))
@settings(deadline=None)
def test_a_recording_cut_anywhere_is_one_line(base, tmp_path_factory, cut):
    data = base.read_bytes()
    path = tmp_path_factory.mktemp("cut") / "cut.mcap"
    path.write_bytes(data[: int(cut * len(data))])
    _one_line(path)


@given(name=st.sampled_from(["terrain.npz", "robot.npz"]), where=st.floats(0.0, 1.0, exclude_max=True),
       bit=st.integers(0, 7))
@settings(deadline=None)
def test_a_bit_flip_in_an_attachment_is_read_or_one_line(base, tmp_path_factory, name, where, bit):
    """A flipped bit in either attachment (the MCAP file's CRCs made right again): zip's and zlib's errors, a
    changed array or header, all one line naming the attachment; a flip zip does not check (a timestamp) reads."""
    path = tmp_path_factory.mktemp("flip") / "flip.mcap"
    _rewrite(base, path, attachment=lambda n, d: _flip(d, int(where * len(d)), bit) if n == name else d)
    try:
        recordings.read_recording(path)
    except ValueError as e:
        assert len(str(e).splitlines()) == 1 and repr(str(path)) in str(e) and f"attachment {name!r}" in str(e), e


@pytest.mark.parametrize("name", ["terrain.npz", "robot.npz"])
@pytest.mark.parametrize("offset", [lambda n: 30, lambda n: n // 2, lambda n: n - 10],
                         ids=["member name", "middle", "directory"])
def test_known_attachment_flips_name_the_attachment(base, tmp_path, name, offset):
    """The flips the probe found: BadZipFile (a member's name, the central directory) and zlib.error (the data)."""
    path = _rewrite(base, tmp_path / "flip.mcap",
                    attachment=lambda n, d: _flip(d, offset(len(d))) if n == name else d)
    _one_line(path, f"attachment {name!r}: not a readable")


@given(where=st.floats(0.0, 1.0, exclude_max=True), bit=st.integers(0, 7))
@settings(deadline=None)
def test_a_bit_flip_anywhere_in_the_file_is_read_or_one_line(base, tmp_path_factory, where, bit):
    """A flipped bit anywhere in the file as it lies on disk (the chunks' CRCs are checked; the attachments'
    zip members have their own)."""
    data = base.read_bytes()
    path = tmp_path_factory.mktemp("flip") / "flip.mcap"
    path.write_bytes(_flip(data, int(where * len(data)), bit))
    _read_or_one_line(path)


# ------------------------------------------------------------------------------------------- hand-edited content


@pytest.mark.parametrize("where, key", REQUIRED, ids=[f"{w}.{k}" for w, k in REQUIRED])
def test_each_required_key_removed_is_named(base, tmp_path, where, key):
    path = _edited(base, tmp_path / "edited.mcap", where, key, DROP)
    if where.startswith("config"):
        _one_line(path, f"the 'ijoy.drive' metadata: {where}: '{key}' is a required property")
    else:
        _one_line(path, f"{where} message 1: '{key}' is a required property")


def test_a_recording_made_before_the_g1_is_the_bipeds(base, tmp_path):
    # config.settings.model is the one setting a recording may lack: the drives recorded before it were the biped's
    rec = recordings.read_recording(_edited(base, tmp_path / "edited.mcap", "config.settings", "model", DROP))
    assert "model" not in rec.config["settings"]
    assert live.DriveSettings(**rec.config["settings"]).model == "biped"


NUMBER, INTEGER = "is not of type 'number'", "is not of type 'integer'"  # finite ones, as in JSON
NOT_COST = "is not valid under any of the given schemas (is not of type 'number'; is not one of ['inf'])"


def _shown(value) -> str:
    """``value`` as a message shows it: its repr, cut to 40 characters."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


WRONG = [  # (where, key, value, what the message says)
    ("/ijoy/decision", "command", "fast", "command: 'fast' is not of type 'array'"),
    ("/ijoy/decision", "command", [0.2, 0.0], "command: [0.2, 0.0] is too short (minItems 3, got 2)"),
    ("/ijoy/decision", "command", [math.nan, 0.0, 0.0], f"command[0]: nan {NUMBER}"),
    ("/ijoy/decision", "command", ["nan", 0.0, 0.0], f"command[0]: 'nan' {NUMBER}"),
    ("/ijoy/decision", "foothold", [math.inf] * 6, f"foothold[5]: inf {NUMBER}"),  # jsonschema names the last
    ("/ijoy/decision", "foothold", [1e39] + [0.0] * 5,
     "foothold[0]: 1e+39 is greater than the maximum of 3.4028234663852886e+38"),
    ("/ijoy/decision", "stance", [10**400, 0, 0], f"stance[0]: {_shown(10**400)} {NUMBER}"),
    ("/ijoy/decision", "step", True, f"step: True {INTEGER}"),
    ("/ijoy/decision", "step", 1.5, f"step: 1.5 {INTEGER}"),
    ("/ijoy/decision", "step", 0, "step: 0 is less than the minimum of 1"),
    ("/ijoy/decision", "stance_side", 0.0, "stance_side: 0.0 is not one of [1, -1]"),
    ("/ijoy/decision", "valid", "yes", "valid: 'yes' is not of type 'boolean'"),
    ("/ijoy/decision", "cost", None, f"cost: None {NOT_COST}"),
    ("/ijoy/decision", "cost", "nan", f"cost: 'nan' {NOT_COST}"),
    ("/ijoy/decision", "cost", math.nan, f"cost: nan {NOT_COST}"),
    ("/ijoy/decision", "terms", [], "terms: [] is not of type 'object'"),
    ("/ijoy/decision", "terms", {"total": "lots"}, f"terms.total: 'lots' {NOT_COST}"),
    ("/ijoy/decision", "index", -2, "index: -2 is less than the minimum of -1"),
    ("/ijoy/decision", "latency_s", -1.0, "latency_s: -1.0 is less than the minimum of 0"),
    ("/ijoy/decision", "t", -0.5, "t: -0.5 is less than the minimum of 0"),
    ("/ijoy/decision", "deadline_slack_s", math.inf, f"deadline_slack_s: inf {NUMBER}"),
    ("/ijoy/decision", "decider", 3, "decider: 3 is not of type 'string'"),
    ("/ijoy/state", "feet", [FEET[0]], f"feet: {_shown([FEET[0]])} is too short (minItems 2, got 1)"),
    ("/ijoy/state", "feet", [FEET[0][:2], FEET[1]], f"feet[0]: {_shown(FEET[0][:2])} is too short (minItems 3, got 2)"),
    ("/ijoy/state", "feet", [["nan", 0.0, 0.0], FEET[1]], f"feet[0][0]: 'nan' {NUMBER}"),
    ("/ijoy/state", "sent", None, "sent: None is not of type 'array'"),
    ("/ijoy/state", "go", 1, "go: 1 is not of type 'boolean'"),
    ("/ijoy/state", "log", [], "log: [] is not of type 'object'"),
    ("/ijoy/state", "step", -1, "step: -1 is less than the minimum of 0"),
    ("/ijoy/input", "axes", [0.0, 0.0, math.nan], f"axes[2]: nan {NUMBER}"),
    ("/ijoy/input", "t", "0", f"t: '0' {NUMBER}"),
    ("/ijoy/input", "source", None, "source: None is not of type 'string'"),
    ("config", "start", [FEET[0]], f"config.start: {_shown([FEET[0]])} is too short (minItems 2, got 1)"),
    ("config", "start", [[math.nan, 0.0, 0.0], FEET[1]], f"config.start[0][0]: nan {NUMBER}"),
    ("config", "settings", "obstacles", "config.settings: 'obstacles' is not of type 'object'"),
    ("config.settings", "deadzone", 1.0, "config.settings.deadzone: 1.0 is greater than or equal to the maximum of 1"),
    ("config.settings", "decide_at", -0.1, "config.settings.decide_at: -0.1 is less than the minimum of 0"),
    ("config.settings", "first_swing", 0, "config.settings.first_swing: 0 is not one of [1, -1]"),
    ("config.settings", "first_swing", True, f"config.settings.first_swing: True {INTEGER}"),
    ("config.settings", "margin", -0.01, "config.settings.margin: -0.01 is less than the minimum of 0"),
    ("config.settings", "body", 3, "config.settings.body: 3 is not of type 'string'"),
    ("config.settings", "model", "G1", "config.settings.model: 'G1' is not one of ['biped', 'g1']"),
    ("config.settings", "terrain", "obstacles", "config.settings.terrain: 'obstacles' is not of type 'object'"),
    ("config.settings", "start", [0.0, 0.0], "config.settings.start: [0.0, 0.0] is too short (minItems 3, got 2)"),
    ("config.settings", "server", 5, "config.settings.server: 5 is not valid under any of the given schemas (is not of "
                                     "type 'null'; is not of type 'string')"),
]


@pytest.mark.parametrize("where, key, value, match", WRONG, ids=[f"{w[0]}.{w[1]}={w[2]!r}"[:60] for w in WRONG])
def test_wrong_types_non_finite_and_out_of_range_values_are_named(base, tmp_path, where, key, value, match):
    _one_line(_edited(base, tmp_path / "edited.mcap", where, key, value), match)


@pytest.mark.parametrize("control_dt, what", [
    (0, "0 is less than or equal to the minimum of 0"), (0.0, "0.0 is less than or equal to the minimum of 0"),
    (-0.01, "-0.01 is less than or equal to the minimum of 0"), (math.nan, f"nan {NUMBER}"),
    (math.inf, f"inf {NUMBER}"), ("0.01", f"'0.01' {NUMBER}"), (None, f"None {NUMBER}"),
    (1.0, "must be at most the robot's step time 0.8 s")])
def test_control_dt_zero_negative_or_longer_than_a_step_is_named(base, tmp_path, control_dt, what):
    """0 divided the perfect body's step time by zero; 1.0 s is longer than the recorded robot's 0.8 s step."""
    path = _edited(base, tmp_path / "edited.mcap", "config.settings", "control_dt", control_dt)
    _one_line(path, f"config.settings.control_dt: {what}")


DEEP = "[" * 100_000 + "]" * 100_000  # JSON nested past Python's recursion limit (json.loads: RecursionError)


@pytest.mark.parametrize("text", [b'{"t": ', b"\xff\xfe", DEEP.encode()], ids=["torn", "not utf-8", "deep"])
def test_messages_and_configs_that_are_not_json_are_named(base, tmp_path, text):
    for topic in ("/ijoy/input", "/ijoy/decision", "/ijoy/state", "/ijoy/summary"):
        path = _rewrite(base, tmp_path / "bad.mcap", message=lambda t, i, m, topic=topic: text if t == topic else m)
        _one_line(path, f"{topic} message 1 is not JSON")
    if text != b"\xff\xfe":  # (MCAP metadata is text)
        path = _rewrite(base, tmp_path / "config.mcap", config=lambda c: text.decode())
        _one_line(path, "the 'ijoy.drive' metadata's config is not JSON")


def _deepest_json() -> int:
    """How deep json.loads reads nested arrays from here (deeper: RecursionError)."""
    depth = 1
    while True:
        try:
            json.loads("[" * (depth + 1) + "]" * (depth + 1))
        except RecursionError:
            return depth
        depth += 1


def test_values_nested_almost_as_deep_as_json_reads_are_one_line(base, tmp_path):
    """json.loads reads arrays nested almost to the recursion limit; the message that shows such a value (its repr,
    a few frames deeper) must still be one line, not a RecursionError."""
    deepest = _deepest_json()
    for depth in range(deepest - 40, deepest + 1):
        text = "[" * depth + "]" * depth
        path = _rewrite(base, tmp_path / "deep.mcap", message=lambda t, i, m, text=text: text.encode()
                        if t == "/ijoy/summary" else m)
        _one_line(path, "/ijoy/summary message 1")
        path = _rewrite(base, tmp_path / "deep_config.mcap", config=lambda c, text=text: text)
        _one_line(path, "'ijoy.drive' metadata")


def test_messages_and_configs_that_are_not_objects_are_named(base, tmp_path):
    for topic in ("/ijoy/input", "/ijoy/decision", "/ijoy/state", "/ijoy/summary"):
        for value in ([1, 2], 42, None, "x"):
            path = _rewrite(base, tmp_path / "list.mcap", message=lambda t, i, m, topic=topic, value=value: value
                            if t == topic else m)
            _one_line(path, f"{topic} message 1: {_shown(value)} is not of type 'object'")
    path = _rewrite(base, tmp_path / "config.mcap", config=lambda c: [c])
    msg = _one_line(path, "'ijoy.drive' metadata: config: [{")
    assert msg.endswith("is not of type 'object'"), msg


def test_input_times_out_of_order_are_named(base, tmp_path):
    path = _rewrite(base, tmp_path / "order.mcap", message=lambda t, i, m: {**m, "t": 1.0 - i} if t == "/ijoy/input"
                    else m)
    _one_line(path, "the /ijoy/input times are not in order")




def _static(**changes) -> np.ndarray:
    """The robot's static fields (JSON, as robot_to_npz writes them) with ``changes``."""
    static = {"max_radius": ROBOT.max_radius, "max_swing": ROBOT.max_swing, "target_grid": ROBOT.target_grid}
    return np.asarray(json.dumps({**static, **changes}))


ATTACHMENT_EDITS = [  # (attachment, arrays changed, what the message says)
    ("terrain.npz", {"height": np.full(SHAPE, np.nan, np.float32)}, "height"),
    ("terrain.npz", {"free": DROP}, "a terrain .npz holds the arrays"),
    ("terrain.npz", {"extra": np.zeros(1)}, "a terrain .npz holds the arrays"),
    ("terrain.npz", {"resolution": np.zeros(2)}, "resolution must be one number"),
    ("terrain.npz", {"resolution": np.float64(0.0)}, "resolution"),
    ("terrain.npz", {"origin": np.array([np.inf, 0.0])}, "origin"),
    ("terrain.npz", {"has_height": np.array([True, False])}, "has_height must be one bool"),
    ("terrain.npz", {"height": np.zeros((3, 3), np.float32)}, "must have the same shape"),
    ("robot.npz", {"margin": np.float32(np.nan)}, "robot.margin must be"),
    ("robot.npz", {"step_time": np.float32(-0.8)}, "robot.step_time must be"),
    ("robot.npz", {"actions": np.array(["a", "b", "c"])}, "robot array 'actions' must be numbers, got dtype <U1"),
    ("robot.npz", {"actions": np.zeros((19, 2), np.float32)}, "robot.actions must have shape (19, 3)"),
    ("terrain.npz", {"height": np.full(SHAPE, "0")}, "terrain array 'height' must be numbers"),
    ("robot.npz", {"p0": DROP}, "missing ['p0']"),
    ("robot.npz", {"wings": np.zeros(2)}, "unknown ['wings']"),
    ("robot.npz", {"metrics.slope_limit": DROP}, "missing ['metrics.slope_limit']"),
    ("robot.npz", {"static": np.asarray("{not json")}, "static fields are not JSON"),
    ("robot.npz", {"static": np.asarray("[1, 2]")}, "static: [1, 2] is not of type 'object'"),
    ("robot.npz", {"static": _static(max_radius=-1)},
     "static.max_radius: -1 is less than or equal to the minimum of 0"),
    ("robot.npz", {"static": _static(target_grid=[[0, 0, 0], [1, 1, 1]])},
     "static.target_grid: [[0, 0, 0], [1, 1, 1]] is too short (minItems 3, got 2)"),
    ("robot.npz", {"static": _static(target_grid=[[0, 0, 0], [1, 0, 1], [1, 1, 1]])},
     "static.target_grid[1][1]: 0 is less than or equal to the minimum of 0"),
    ("robot.npz", {"static": _static(target_grid=[[0, 0, 0], [1, 1, 1], [1, 1.5, 1]])},
     f"static.target_grid[2][1]: 1.5 {INTEGER}"),
    ("robot.npz", {"static": _static(target_grid=[[0, 0, 0], [1, 1, 1], [1, 0, 1]])},
     "static.target_grid[2][1]: 0 is less than the minimum of 1"),
    ("robot.npz", {"static": _static(max_swing=None)}, f"static.max_swing: None {NUMBER}"),
    ("robot.npz", {"static": _static(max_swing=math.nan)}, f"static.max_swing: nan {NUMBER}"),
    ("robot.npz", {"static": _static(wings=1)},
     "static: Additional properties are not allowed ('wings' was unexpected)"),
]


@pytest.mark.parametrize("name, changes, match", ATTACHMENT_EDITS,
                         ids=[f"{a[0]}:{','.join(a[1])}" for a in ATTACHMENT_EDITS])
def test_hand_edited_attachments_are_named(base, tmp_path, name, changes, match):
    path = _rewrite(base, tmp_path / "edited.mcap", attachment=lambda n, d: _npz(d, **changes) if n == name else d)
    _one_line(path, f"attachment {name!r}: ")
    _one_line(path, match)


@pytest.mark.parametrize("data", [b"", b"hello", b"PK\x03\x04" + b"\0" * 40], ids=["empty", "text", "zip header"])
def test_attachments_that_are_not_npz_are_named(base, tmp_path, data):
    for name in ("terrain.npz", "robot.npz"):
        path = _rewrite(base, tmp_path / "edited.mcap", attachment=lambda n, d, name=name: data if n == name else d)
        _one_line(path, f"attachment {name!r}: not a readable")


_JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-(10**30), 10**30) | st.sampled_from([10**400, -(10**400)])
    | st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from(["inf", "-inf", "nan", "", "x"]),
    lambda inner: st.lists(inner, max_size=7) | st.dictionaries(st.sampled_from(["total", "a", "t"]), inner,
                                                                max_size=3),
    max_leaves=12)
_FIELDS = [(w, k) for w, k in REQUIRED if w != "config"] + [("config", "start"), ("config", "settings")]


@given(field=st.sampled_from(_FIELDS), value=_JSON)
@settings(deadline=None)
def test_any_value_in_any_field_is_read_or_one_line(base, tmp_path_factory, field, value):
    """Whatever JSON value a field holds: the recording reads, and its readers (a sweep's commands and terrain,
    the replay's stick, a trace export) take it without another exception; or it is one ValueError line."""
    folder = tmp_path_factory.mktemp("any")
    path = _edited(base, folder / "edited.mcap", *field, value)
    rec = _read_or_one_line(path)
    if rec is None:
        return
    for read in (sweep.recorded.read_commands, sweep.recorded.read_terrain):
        try:
            read(path)
        except ValueError as e:
            assert len(str(e).splitlines()) == 1, e
    stick = live.session.ReplayInput(rec)
    assert np.all(np.isfinite(np.asarray(stick.commands, np.float32)))
    live.session.export_trace(rec, folder / "trace.csv")
    live.read_trace(folder / "trace.csv")


# ------------------------------------------------------------------------------------------- a sweep, the command line

VARIANTS = {  # name: (edit of the base recording, what the message says)
    "flipped terrain": (dict(attachment=lambda n, d: _flip(d, len(d) // 2) if n == "terrain.npz" else d),
                        "attachment 'terrain.npz'"),
    "flipped robot": (dict(attachment=lambda n, d: _flip(d, 30) if n == "robot.npz" else d), "attachment 'robot.npz'"),
    "decision without cost": (dict(message=lambda t, i, m: _set(m, "cost", DROP) if t == "/ijoy/decision" else m),
                              "/ijoy/decision message 1: 'cost' is a required property"),
    "state without feet": (dict(message=lambda t, i, m: _set(m, "feet", DROP) if t == "/ijoy/state" else m),
                           "/ijoy/state message 1: 'feet' is a required property"),
    "config without start": (dict(config=lambda c: _set(c, "start", DROP)), "config: 'start' is a required property"),
    "control_dt 0": (dict(config=lambda c: _set(c, "settings.control_dt", 0)),
                     "control_dt: 0 is less than or equal to the minimum of 0"),
    "NaN command": (dict(message=lambda t, i, m: _set(m, "command", [math.nan, 0, 0]) if t == "/ijoy/decision"
                         else m), f"command[0]: nan {NUMBER}"),
}


@pytest.fixture(scope="module")
def variants(base, tmp_path_factory):
    folder = tmp_path_factory.mktemp("variants")
    out = {name: (_rewrite(base, folder / f"{name.replace(' ', '_')}.mcap", **edit), match)
           for name, (edit, match) in VARIANTS.items()}
    cut = folder / "truncated.mcap"
    cut.write_bytes(base.read_bytes()[: len(base.read_bytes()) // 2])
    out["truncated"] = (cut, "is not a readable ijoy drive recording")
    return out


@pytest.mark.parametrize("variant", [*VARIANTS, "truncated"])
@pytest.mark.parametrize("key, text", [("command.file", '[command]\nfile = "{}"\n'),
                                       ("terrain.recording", '[terrain]\nrecording = "{}"\n')],
                         ids=["command.file", "terrain.recording"])
def test_a_sweep_names_file_key_and_reason(variants, variant, key, text):
    path, match = variants[variant]
    toml = write(path.parent, text.format(path.name), "bad_sweep.toml")
    with pytest.raises(sweep.SweepConfigError) as e:
        sweep.load_config(toml)
    msg = str(e.value)
    assert msg.startswith(f"{toml}: {key}: ") and len(msg.splitlines()) == 1, msg
    assert repr(str(path)) in msg and match in msg, msg


@pytest.mark.parametrize("variant", [*VARIANTS, "truncated"])
@pytest.mark.parametrize("extra", [[], ["--export-trace", "TRACE"]], ids=["replay", "export"])
def test_ijoy_drive_replay_says_it_in_one_line(variants, variant, extra, tmp_path, capsys):
    path, match = variants[variant]
    extra = [str(tmp_path / "t.csv") if a == "TRACE" else a for a in extra]
    assert cli.main(["drive", "--replay", str(path), "--headless", "--ff", "off", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("ijoy: error: ") and len(err.splitlines()) == 1, err
    assert repr(str(path)) in err and match in err, err
    assert not (tmp_path / "t.csv").exists()


@pytest.mark.parametrize("edit, match", [
    (lambda c: _set(c, "settings.turbo", True), "config.settings has keys a drive does not know: turbo"),
    (lambda c: _set(c, "settings.body", "hovercraft"), "config.settings.body must be one of"),
], ids=["unknown setting", "unknown body"])
def test_ijoy_drive_replay_refuses_settings_a_drive_cannot_take(base, tmp_path, capsys, edit, match):
    """Settings the format allows but a replay cannot drive with: refused before anything is built."""
    path = _rewrite(base, tmp_path / "edited.mcap", config=edit)
    assert cli.main(["drive", "--replay", str(path), "--headless", "--ff", "off"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"ijoy: error: {str(path)!r}: ") and len(err.splitlines()) == 1 and match in err, err


def test_ijoy_sweep_run_says_it_in_one_line(variants, capsys, tmp_path):
    path, _ = variants["state without feet"]
    toml = write(path.parent, f'[command]\nfile = "{path.name}"\n', "bad_sweep.toml")
    assert cli.main(["sweep", "run", str(toml), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"ijoy: error: {toml}: command.file: ") and len(err.splitlines()) == 1, err
    assert not (tmp_path / "out").exists()

"""The footstep server's wire format in-process (fast, no sockets): hostile input at the decode layer.

:func:`ijoy_jax.server.schema.decode_request` is the server's whole input boundary: whatever bytes arrive, it
returns a checked request or raises a ProtocolError with a known code, never another exception; a Service
answers every message with a reply that obeys the shipped JSON Schema. Arrays round-trip bit for bit.
"""

import fnmatch
import json
import math
import tomllib
from importlib import resources
from pathlib import Path, PurePosixPath

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from jsonschema import Draft202012Validator

import ijoy_jax as ij
from ijoy_jax.footcost.index import index_terrain, update_columns
from ijoy_jax.server import Service, schema
from ijoy_jax.server.schema import ERROR_CODES, Limits, ProtocolError

LIMITS = Limits(max_cells=400, max_side=40, max_maps=2, max_header_bytes=4096)

json_leaf = st.one_of(st.none(), st.booleans(), st.integers(-(2**70), 2**70),
                      st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=20))
json_value = st.recursive(json_leaf, lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=10), c,
                                                                                          max_size=4), max_leaves=20)
hostile_number = st.one_of(st.floats(), st.integers(-(2**80), 2**80), st.just(1e39), st.just(-1e39),
                           st.text(max_size=5), st.none(), st.booleans(), st.lists(st.floats(), max_size=3))

STEP = {"version": 1, "type": "step", "stance": [1.0, 1.0, 0.0], "stance_side": -1, "command": [0.2, 0.0, 0.0]}


def _decode(frames):
    """decode_request, which may only raise ProtocolError with a known code."""
    try:
        return schema.decode_request(frames, LIMITS)
    except ProtocolError as e:
        assert e.code in ERROR_CODES and e.message
        return e


def _dumps(header):
    return json.dumps(header).encode()  # NaN and inf become the NaN/Infinity tokens a sloppy client could send


@given(st.lists(st.binary(max_size=64), max_size=4))
def test_any_bytes_decode_or_raise_a_protocol_error(frames):
    _decode(frames)


@given(json_value)
def test_any_json_header_decodes_or_raises_a_protocol_error(value):
    _decode([json.dumps(value).encode()])


@given(st.sampled_from(["stance", "command", "swing_from", "stance_side", "version", "map", "id"]), hostile_number)
def test_hostile_step_fields(field, value):
    header = {**STEP, field: value}
    if field in ("stance", "command", "swing_from") and not isinstance(value, list):
        header[field] = [value, 0.0, 0.0]
    out = _decode([_dumps(header)])
    if isinstance(out, ProtocolError):
        return
    # What passes is what a step needs: three finite float64 numbers per pose, a side of +-1.
    h = out.header
    for name in ("stance", "command"):
        assert len(h[name]) == 3 and all(isinstance(v, (int, float)) and math.isfinite(v) for v in h[name])
    assert h["stance_side"] in (1, -1) and h["version"] in schema.SUPPORTED_VERSIONS


@pytest.mark.parametrize("value, code", [(float("nan"), "non_finite"), (float("inf"), "non_finite"),
                                         ("1", "invalid_field"), (None, "invalid_field"), (True, "invalid_field")])
def test_bad_stance_values_get_their_code(value, code):
    out = _decode([_dumps({**STEP, "stance": [value, 1.0, 0.0]})])
    assert isinstance(out, ProtocolError) and out.code == code, out


dtypes = st.sampled_from(["|b1", "|u1", "<f4", "<f8", ">f4", "<i4", "<f2", "float32", "", "|V8", "O"])
shapes = st.lists(st.integers(-3, 50), max_size=4)


@given(st.sampled_from(["free", "height", "colour"]), dtypes, shapes, st.integers(0, 2000),
       st.sampled_from([0.0, 1.0, 2.0, np.nan, np.inf]))
def test_hostile_arrays(name, dtype, shape, nbytes, fill):
    frame = np.full(nbytes, 0, np.uint8)
    if nbytes >= 8:
        frame[:8] = np.frombuffer(np.float64(fill).tobytes(), np.uint8)
    header = {"version": 1, "type": "set_terrain", "resolution": 0.05,
              "arrays": [{"name": name, "dtype": dtype, "shape": shape}]}
    out = _decode([_dumps(header), frame.tobytes()])
    if isinstance(out, ProtocolError):
        return
    a = out.arrays[name]
    assert a.ndim == 2 and a.size >= 1 and a.size <= LIMITS.max_cells and a.dtype.str == dtype
    assert a.nbytes == nbytes and (a.dtype.kind != "f" or np.isfinite(a).all())


@given(st.sampled_from(["<f4", "<f8", "|b1", "|u1"]), st.integers(1, 20), st.integers(1, 20), st.integers(0, 2**32 - 1))
def test_arrays_round_trip_bit_for_bit(dtype, nx, ny, seed):
    rng = np.random.default_rng(seed)
    name = "height" if dtype[1] == "f" else "free"
    a = (rng.normal(0, 1, (nx, ny)) if name == "height" else rng.integers(0, 2, (nx, ny))).astype(dtype)
    out = schema.decode_request(schema.encode({"version": 1, "type": "set_terrain", "resolution": 0.05}, {name: a}),
                                LIMITS)
    assert out.arrays[name].dtype == a.dtype and out.arrays[name].tobytes() == a.tobytes()


def test_a_shape_written_as_whole_floats_is_read_as_integers():
    """JSON Schema's integers include 60.0: the shape [4.0, 3.0] passes the schema, and the array is read as (4, 3)
    (NumPy refused the floats with "'float' object cannot be interpreted as an integer")."""
    a = np.ones((4, 3), bool)
    header = {"version": 1, "type": "set_terrain", "resolution": 0.05,
              "arrays": [{"name": "free", "dtype": "|b1", "shape": [4.0, 3.0]}]}
    out = schema.decode_request([json.dumps(header).encode(), a.tobytes()], LIMITS)
    assert out.arrays["free"].shape == (4, 3) and out.arrays["free"].all()


@pytest.mark.parametrize("field, value", [("stance", [10**400, 1, 0]), ("command", [-(10**309), 0, 0]),
                                          ("origin", [10**400, 0])])
def test_an_integer_beyond_float64_is_non_finite_not_internal(field, value):
    header = {"version": 1, "type": "step", "stance": [1, 1, 0], "stance_side": -1, "command": [0.2, 0, 0],
              field: value}
    with pytest.raises(schema.ProtocolError) as e:
        schema.decode_request([json.dumps(header).encode()], LIMITS)
    assert e.value.code == "non_finite" and "beyond float64" in e.value.message


@given(st.floats(width=32))
def test_reply_floats_round_trip_float32_exactly(x):
    back = np.float32(schema.float_from_json(json.loads(json.dumps(schema.json_float(np.float32(x))))))
    assert back.tobytes() == np.float32(x).tobytes() or (math.isnan(x) and math.isnan(back))


def test_limits_and_versions():
    assert Limits().max_frame_bytes >= 16 * Limits().max_cells
    with pytest.raises(ValueError, match="max_cells"):
        Limits(max_cells=0)
    assert schema.negotiate([1, 2, 3]) == 1
    with pytest.raises(ProtocolError) as e:
        schema.negotiate([2])
    assert e.value.code == "unsupported_version"


# ------------------------------------------------------------------------------------- a Service, in-process


@pytest.fixture(scope="module")
def service():
    s = Service(ij.robots.hrp2(), name="hrp2", limits=LIMITS)
    reply = s.handle(schema.encode({"version": 1, "type": "set_terrain", "resolution": 0.05},
                                   {"free": np.ones((20, 20), bool)}))
    assert schema.decode_reply(reply).header["ok"]
    return s


def _reply_validator():
    defs = schema.json_schema()["$defs"]
    return {name: Draft202012Validator({"$ref": f"#/$defs/{name}", "$defs": defs})
            for name in ("reply", "error_reply", "step_reply", "terrain_reply")}


REPLIES = _reply_validator()


@given(st.lists(st.binary(max_size=48), min_size=1, max_size=3) | json_value.map(lambda v: [json.dumps(v).encode()]))
def test_a_service_answers_every_message_with_a_schema_reply(service, frames):
    reply = schema.decode_reply(service.handle(frames)).header
    REPLIES["reply"].validate(reply)
    if not reply["ok"]:
        REPLIES["error_reply"].validate(reply)
        assert reply["code"] in ERROR_CODES


@given(st.sampled_from(["stance", "command", "swing_from"]), st.floats(-1e3, 1e3, width=32),
       st.sampled_from([1, -1]))
def test_a_service_step_reply_obeys_the_schema(service, field, value, side):
    header = {**STEP, "stance_side": side, field: [value, 0.5, 0.0]}
    reply = schema.decode_reply(service.handle(schema.encode(header))).header
    REPLIES["step_reply"].validate(reply)


# ------------------------------------------------------------------------- the window update's index columns


@pytest.mark.parametrize("has_height", [False, True], ids=["2d", "2.5d"])
@pytest.mark.parametrize("start, width", [(0, 8), (22, 8), (9, 16)])  # both edges and the middle
def test_update_columns_equals_a_whole_new_index(has_height, start, width):
    rng = np.random.default_rng(start)
    robot = ij.robots.hrp2()
    h = rng.normal(0, 0.02, (30, 24)).astype(np.float32) if has_height else None
    free = rng.random((30, 24)) > 0.05
    old = index_terrain(ij.terrain.from_arrays(h, free, 0.02), robot)
    free[start:start + width] = rng.random((width, 24)) > 0.5
    if has_height:
        h[start:start + width, 3:20] += rng.normal(0, 0.05, (width, 17)).astype(np.float32)
    new = ij.terrain.from_arrays(h, free, 0.02)
    got, want = update_columns(old, new, robot, start, width), index_terrain(new, robot)
    for name in ("obstacles_before", "height_max", "height_padded", "height_sums", "height_block_first"):
        np.testing.assert_array_equal(np.asarray(getattr(got, name)), np.asarray(getattr(want, name)), err_msg=name)


# ------------------------------------------------------------------------- the files the installed package ships


def _shipped(rel: PurePosixPath, package_data: dict) -> bool:
    """Whether setuptools' ``package-data`` ships the file at ``rel`` (a path inside ``ijoy_jax/``): a pattern of
    the package folder that holds it, or of one above, matches its path from there segment by segment (glob
    patterns, ``*`` within a segment, as setuptools reads them)."""
    for depth in range(len(rel.parts)):
        package, tail = ".".join(("ijoy_jax", *rel.parts[:depth])), rel.parts[depth:]
        for pattern in [*package_data.get(package, []), *package_data.get("*", [])]:
            segments = pattern.split("/")
            if len(segments) == len(tail) and all(map(fnmatch.fnmatchcase, tail, segments)):
                return True
    return False


def test_the_package_is_typed_and_a_wheel_ships_every_file_it_reads():
    """``py.typed`` (PEP 561: type checkers read the annotations) and every other file that is not Python
    source (``protocol.schema.json``, the live view's pages) are in the installed package and declared in
    pyproject.toml's package-data, so a wheel or sdist install has them too (an editable one reads the
    source folder, which has them whether declared or not)."""
    root = resources.files("ijoy_jax")
    assert root.joinpath("py.typed").is_file()
    folder = Path(str(root))
    files = [
        PurePosixPath(p.relative_to(folder).as_posix())
        for p in folder.rglob("*")
        if p.is_file()
        and p.suffix not in (".py", ".pyc")
        and "__pycache__" not in p.parts
        and not any(part.startswith(".") for part in p.relative_to(folder).parts)
    ]
    assert {"py.typed", "server/protocol.schema.json"} <= {str(f) for f in files}
    with open(Path(__file__).resolve().parents[1] / "pyproject.toml", "rb") as f:
        package_data = tomllib.load(f)["tool"]["setuptools"]["package-data"]
    assert [str(f) for f in files if not _shipped(f, package_data)] == []
    assert not _shipped(PurePosixPath("live/other/notes.txt"), package_data)  # the check can fail

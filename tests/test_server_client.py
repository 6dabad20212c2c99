"""The footstep server's Python client, before anything is sent (fast: no server, no compile).

A value the server would refuse that the client can tell by itself (NaN or infinity, which JSON cannot carry;
a field that is not a number; a stance side other than +-1; a fractional cell offset) raises
:class:`ijoy_jax.server.ServerError` with the code the server answers for that value and a one-line message
naming the field; everything else is sent, for the server to judge. The clients here are made with
``hello=False`` (no connection is awaited) for a port where nothing listens, so a request that is sent times out
after a millisecond: a ``TimeoutError`` means "sent", and the server's decoder says what it would have answered.
"""

import json
import math
import socket

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax.server import Client, ServerError, schema
from ijoy_jax.server.schema import ProtocolError

SENT = "sent"
STANCE, COMMAND, SWING = [1.0, 1.1, 0.0], [0.25, 0.0, 0.0], [1.0, 0.9, 0.0]
FREE = np.ones((4, 4), bool)
FREE_SPEC = {"name": "free", "dtype": "|b1", "shape": [4, 4]}


@pytest.fixture(scope="module")
def port():
    """A TCP port where nothing listens: bound, never listening, so that no other process can take it while
    the tests run (a connection there is refused, and ZeroMQ keeps the requests queued)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        yield s.getsockname()[1]


def _client(port: int) -> Client:
    return Client("127.0.0.1", port, hello=False, timeout=1e-3)


def _outcome(call) -> str:
    """The code of the ServerError the client raised before sending (one line, no reply header), or SENT."""
    try:
        call()
    except ServerError as e:
        assert e.header == {} and "\n" not in str(e) and len(str(e)) < 200, str(e)
        return e.code
    except TimeoutError:
        return SENT
    raise AssertionError("a reply from a port where nothing listens")


def _server_code(header: dict, frames: tuple = ()) -> str:
    """What the server's decoder answers for ``header`` written as JSON (NaN and infinity as the tokens a sloppy
    client would send): an error code, or "ok"."""
    try:
        schema.decode_request([json.dumps({"version": 1, **header}).encode(), *frames])
    except ProtocolError as e:
        return e.code
    return "ok"


class _Grid:
    """A terrain-like object (what ``Client.set_terrain`` reads) whose origin and resolution may be anything."""

    def __init__(self, resolution=0.05, origin=(0.0, 0.0)):
        self.resolution, self.origin = resolution, origin

    def to_numpy(self) -> dict:
        return {"free": FREE, "height": None, "origin": self.origin, "resolution": self.resolution, "has_height": False}


def _at(values: list, i: int, value) -> list:
    return [value if j == i else v for j, v in enumerate(values)]


# field -> (how the client sends a value there, the header the server would get for it, its array frames)
FIELDS = {
    **{
        f"stance[{i}]": (
            lambda c, v, i=i: c.step(_at(STANCE, i, v), -1, COMMAND),
            lambda v, i=i: {"type": "step", "stance": _at(STANCE, i, v), "stance_side": -1, "command": COMMAND},
            (),
        )
        for i in range(3)
    },
    **{
        f"command[{i}]": (
            lambda c, v, i=i: c.step(STANCE, -1, _at(COMMAND, i, v)),
            lambda v, i=i: {"type": "step", "stance": STANCE, "stance_side": -1, "command": _at(COMMAND, i, v)},
            (),
        )
        for i in range(3)
    },
    **{
        f"swing_from[{i}]": (
            lambda c, v, i=i: c.step(STANCE, -1, COMMAND, _at(SWING, i, v)),
            lambda v, i=i: {
                "type": "step",
                "stance": STANCE,
                "stance_side": -1,
                "command": COMMAND,
                "swing_from": _at(SWING, i, v),
            },
            (),
        )
        for i in range(3)
    },
    "stance_side": (
        lambda c, v: c.step(STANCE, v, COMMAND),
        lambda v: {"type": "step", "stance": STANCE, "stance_side": v, "command": COMMAND},
        (),
    ),
    "leaves['w']": (lambda c, v: c.set_robot({"w": v}), lambda v: {"type": "set_robot", "leaves": {"w": v}}, ()),
    "resolution": (
        lambda c, v: c.set_terrain(_Grid(resolution=v)),
        lambda v: {"type": "set_terrain", "resolution": v, "origin": [0.0, 0.0], "arrays": [FREE_SPEC]},
        (FREE.tobytes(),),
    ),
    **{
        f"origin[{i}]": (
            lambda c, v, i=i: c.set_terrain(_Grid(origin=_at([0.0, 0.0], i, v))),
            lambda v, i=i: {
                "type": "set_terrain",
                "resolution": 0.05,
                "origin": _at([0.0, 0.0], i, v),
                "arrays": [FREE_SPEC],
            },
            (FREE.tobytes(),),
        )
        for i in range(2)
    },
    **{
        f"offset[{i}]": (
            lambda c, v, i=i: c.update_terrain(_at([0, 0], i, v), free=FREE),
            lambda v, i=i: {"type": "update_terrain", "offset": _at([0, 0], i, v), "arrays": [FREE_SPEC]},
            (FREE.tobytes(),),
        )
        for i in range(2)
    },
}

hostile = st.one_of(
    st.floats(),
    st.sampled_from([math.nan, math.inf, -math.inf, 1e39, 2.5, 1.0, -1.0, 0.0]),
    st.integers(-(2**80), 2**80),
    st.just(10**400),
    st.text(max_size=4),
    st.none(),
    st.booleans(),
    st.lists(st.floats(), max_size=2),
)


@pytest.mark.parametrize("field", list(FIELDS))
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf], ids=["nan", "inf", "-inf"])
def test_nan_or_infinity_in_any_field_is_the_servers_non_finite_error_naming_the_field(port, field, value):
    send, header, frames = FIELDS[field]
    with _client(port) as client, pytest.raises(ServerError) as e:
        send(client, value)
    assert e.value.code == "non_finite" == _server_code(header(value), frames)
    assert e.value.message.startswith(f"{field} = {value!r} is not finite"), e.value.message


@settings(max_examples=300)  # 16 fields x 8 kinds of value; about a second
@given(st.sampled_from(list(FIELDS)), hostile)
def test_what_the_client_refuses_the_server_refuses_with_the_same_code(port, field, value):
    send, header, frames = FIELDS[field]
    with _client(port) as client:
        got = _outcome(lambda: send(client, value))  # ServerError or sent: never a ValueError, TypeError, ...
    if got != SENT:
        assert got == _server_code(header(value), frames), (field, value, got)


def test_a_raw_request_names_its_non_finite_field(port):
    with _client(port) as client, pytest.raises(ServerError) as e:
        client.request({"type": "set_robot", "leaves": {"w": 1.0, "margin": math.nan}})
    assert e.value.code == "non_finite" and e.value.message.startswith("leaves['margin'] = nan is not finite")


@pytest.mark.parametrize(
    "offset, message",
    [([1.5, 0], "offset[0] = 1.5 is not a whole number of cells"), ([0, "2"], "offset[1] = '2' is not a number")],
)
def test_an_offset_is_refused_not_truncated(port, offset, message):
    with _client(port) as client, pytest.raises(ServerError) as e:
        client.update_terrain(offset, free=FREE)
    assert e.value.code == "invalid_field" and e.value.message == message


@pytest.fixture
def sent(monkeypatch) -> list:
    """The frames of every message the clients encode (they are sent, and time out)."""
    out, encode = [], schema.encode

    def recording(header, arrays=None):
        out.append(encode(header, arrays))
        return out[-1]

    monkeypatch.setattr(schema, "encode", recording)
    return out


@pytest.mark.parametrize(
    "send, field, want",
    [
        (
            lambda c: c.step(np.float32([1.1, 2.2, 0.3]), -1, COMMAND),
            "stance",
            [float(np.float32(v)) for v in (1.1, 2.2, 0.3)],
        ),
        (lambda c: c.step(jnp.array([1.0, 1.1, 0.0]), np.int64(1), COMMAND), "stance_side", 1),
        (lambda c: c.step(STANCE, jnp.int32(-1), np.array([[0.25], [0.0], [0.0]])), "command", COMMAND),
        (
            lambda c: c.set_robot({"w": np.float32(2.5)}, margin=jnp.float32(0.05)),
            "leaves",
            {"w": 2.5, "margin": float(np.float32(0.05))},
        ),
        (lambda c: c.update_terrain(np.array([2.0, 3.0]), free=FREE), "offset", [2, 3]),
        (lambda c: c.set_terrain(ij.terrain.from_arrays(None, FREE, 0.05, origin=(0.5, -1.0))), "origin", [0.5, -1.0]),
    ],
    ids=["float32 stance", "numpy and JAX sides", "a (3, 1) command", "0-d leaves", "whole float offsets", "a Terrain"],
)
def test_good_values_of_every_kind_are_sent_as_the_server_reads_them(port, sent, send, field, want):
    with _client(port) as client:
        assert _outcome(lambda: send(client)) == SENT
    request = schema.decode_request(sent[-1])
    assert request.header[field] == want and type(request.header[field]) is type(want)

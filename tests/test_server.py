"""The footstep server as a user runs it: one real ``ijoy serve`` subprocess on 127.0.0.1 (a free port; the
session's, tests/conftest.py's footstep_server, shared with tests/test_live.py), real ZeroMQ and TCP sockets.

Replies equal in-process :func:`ijoy_jax.select_step` bit for bit (2D and 2.5D, both sides, with and without
swing_from, after window updates, after set_robot); every kind of bad input gets an error reply with its code
and the server answers afterwards; a client that vanishes mid-request, raw TCP garbage and a client that
never reads leave it serving; a bounded load test from several clients at once loses no reply. Maps are small
(tests/_server_util.py: 40 x 32 cells at 5 cm, the shape every server and live test uses, so each program
compiles once for all of them) except where a property needs size. The command line's start-up errors run
in-process (``cli.main``: the same code and output); its signals and connection log in real processes.
"""

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import jax
import numpy as np
import pytest
import zmq
from _server_util import MAX_CELLS, MAX_MAPS, RES, SHAPE  # tests/ is on sys.path (pytest rootdir import)
from jsonschema import Draft202012Validator

import ijoy_jax as ij
from ijoy_jax.apps import cli
from ijoy_jax.server import Client, ServerError, schema

REQUEST_TIMEOUT_S = 120.0  # a reply; generous for a loaded 2-core CI machine (a new map shape compiles)
ROBOT = ij.robots.hrp2(margin=0.02)
TOTAL_RTOL = 4 * float(np.finfo(np.float32).eps)  # FootCost of one pose vs. of it in a batch of 496: XLA vectorises
# the plane-fit sums differently (1 ulp seen); the reply's terms equal ij.foot_cost_terms of the pose bit for bit


@pytest.fixture(scope="module")
def server(footstep_server):
    """The session's ijoy serve process (it asserts at the end of the session that the server never died)."""
    return footstep_server


@pytest.fixture
def client(server):
    with Client(server.host, server.port, timeout=REQUEST_TIMEOUT_S) as c:
        yield c


def _validator(name):
    s = schema.json_schema()
    return Draft202012Validator({"$ref": f"#/$defs/{name}", "$defs": s["$defs"]})


def _terrain(has_height, seed=0, shape=SHAPE):
    rng = np.random.default_rng(seed)
    free = rng.random(shape) > 0.03
    free[25:28, :] = False  # a wall across at x = 1.25 m
    h = None
    if has_height:
        x = np.arange(shape[0])[:, None] * RES
        h = (0.02 * np.sin(3.0 * x) + 0.003 * rng.standard_normal(shape)).astype(np.float32)
    return ij.terrain.from_arrays(h, free, RES)


def _queries(n, seed):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        stance = np.float32([rng.uniform(0.5, 1.5), rng.uniform(0.5, 1.1), rng.uniform(-0.5, 0.5)])
        command = np.float32([rng.uniform(-0.3, 0.3), rng.uniform(-0.2, 0.2), rng.uniform(-0.5, 0.5)])
        side = 1 if i % 2 else -1
        swing = None if i % 4 < 2 else stance + np.float32([-0.1, -0.19 * side, 0.05])
        out.append((stance, side, command, swing))
    return out


_TARGETS = {}


def _targets(robot):
    """make_targets(robot), what select_step builds when given none (an eager sort: ~0.5 s a call here), once."""
    key = float(robot.rotation_weight)
    if key not in _TARGETS:
        _TARGETS[key] = ij.make_targets(robot)
    return _TARGETS[key]


def assert_reply_equals_select_step(reply, terrain, robot, stance, side, command, swing):
    c = ij.select_step(terrain, robot, stance, side, command, swing_from=swing, targets=_targets(robot))
    for name in ("pose", "foothold", "target"):
        np.testing.assert_array_equal(getattr(reply, name), np.asarray(getattr(c, name)), err_msg=name)
        assert getattr(reply, name).dtype == np.float32
    assert reply.valid == bool(c.valid) and reply.index == int(c.index)
    for name in ("cost", "foot_cost"):  # bit for bit, +inf included
        assert np.asarray(getattr(reply, name)).tobytes() == np.asarray(getattr(c, name)).tobytes(), name
    assert (reply.command_ok, reply.unsupported, reply.evaluated) == (bool(c.command_ok), bool(c.unsupported),
                                                                      int(c.evaluated))
    p0_index = int(np.argmin(np.abs(np.asarray(robot.actions) - np.asarray(robot.p0)).sum(-1)))
    action = int(c.index) if bool(c.valid) else p0_index
    terms = ij.foot_cost_terms(terrain, robot, stance, side, np.asarray(c.pose)[None], swing_from=swing,
                               action_index=np.array([action], np.int32))
    assert set(reply.terms) == set(ij.FootCostTerms._fields)
    assert reply.terms["action_index"] == action and isinstance(reply.terms["action_index"], int)
    for name in set(ij.FootCostTerms._fields) - {"action_index"}:
        expect = np.asarray(getattr(terms, name))[0]
        assert expect.dtype == np.float32 and reply.terms[name].tobytes() == expect.tobytes(), name
    if reply.valid:  # one candidate's FootCost against the 496-action evaluation's: float32 rounding apart
        np.testing.assert_allclose(reply.terms["total"], reply.foot_cost, rtol=TOTAL_RTOL)


# ------------------------------------------------------------------------------------------------- the basics


def test_a_step_before_any_map_is_an_error(client):
    with pytest.raises(ServerError) as e:
        client.step([1.0, 1.0, 0.0], -1, [0.2, 0.0, 0.0])  # no test leaves "default" set (test_live drops it)
    assert e.value.code == "no_terrain" and "set_terrain first" in e.value.message


def test_hello_and_info_report_the_protocol_robot_and_limits(client):
    assert client.server_hello["version"] == schema.PROTOCOL_VERSION
    info = client.info()
    assert info["supported"] == [1] and info["robot"]["name"] == "hrp2" and info["robot"]["num_actions"] == 496
    assert info["robot"]["leaves"]["margin"] == float(np.float32(0.02))
    assert info["limits"]["max_cells"] == MAX_CELLS and info["limits"]["max_maps"] == MAX_MAPS
    np.testing.assert_array_equal(info["actions"], np.asarray(ROBOT.actions))
    np.testing.assert_array_equal(info["p0"], np.asarray(ROBOT.p0))
    assert info["terms"] == list(ij.FootCostTerms._fields)


@pytest.mark.parametrize("has_height", [False, pytest.param(True, marks=pytest.mark.slow)], ids=["2d", "2.5d"])
def test_replies_equal_select_step_bit_for_bit(client, has_height):
    terrain = _terrain(has_height, seed=int(has_height))
    name = f"equal_{int(has_height)}"
    r = client.set_terrain(terrain, map_name=name)
    assert r["shape"] == list(SHAPE) and r["has_height"] is has_height
    step_reply = _validator("step_reply")
    queries = _queries(8, seed=3 + int(has_height))
    # and two that no step can serve: a stance in the wall, a stance off the map
    queries += [(np.float32([1.3, 0.8, 0.0]), 1, np.float32([0.2, 0, 0]), None),
                (np.float32([5.0, 5.0, 0.0]), -1, np.float32([0.0, 0, 0]), np.float32([5.0, 5.2, 0.0]))]
    valid = []
    for stance, side, command, swing in queries:
        reply = client.step(stance, side, command, swing, map_name=name)
        assert reply.map_name == name and reply.revision == r["revision"] and reply.compute_s > 0
        assert_reply_equals_select_step(reply, terrain, ROBOT, stance, side, command, swing)
        valid.append(reply.valid)
    assert any(valid) and not all(valid)  # both paths were compared
    raw = client.request({"type": "step", "map": name, "stance": [5.0, 5.0, 0.0], "stance_side": 1,
                          "command": [0.2, 0.0, 0.0]}).header
    step_reply.validate(raw)  # the reply obeys the shipped JSON Schema, "Infinity" included
    assert raw["cost"] == "Infinity" and raw["index"] == -1


@pytest.mark.slow
def test_window_updates_equal_a_whole_new_map(client):
    terrain = _terrain(True, seed=7)
    name = "window"
    client.set_terrain(terrain, map_name=name)
    h, free = np.array(terrain.height), np.array(terrain.free)
    rng = np.random.default_rng(8)
    for ix, iy, wx, wy in [(0, 0, 5, 6), (33, 20, 7, 12), (12, 3, 3, 25)]:  # both edges and the middle
        hw = rng.normal(0, 0.01, (wx, wy)).astype(np.float32)
        fw = rng.random((wx, wy)) > 0.2
        r = client.update_terrain([ix, iy], free=fw, height=hw, map_name=name)
        _validator("terrain_reply").validate(r)
        h[ix:ix + wx, iy:iy + wy], free[ix:ix + wx, iy:iy + wy] = hw, fw
        c0, c1 = r["rebuilt_columns"]
        assert c0 <= ix and ix + wx <= c1 and c1 - c0 < SHAPE[0]  # a band of columns, not the whole map
        updated = ij.terrain.from_arrays(h, free, RES)
        for stance, side, command, swing in _queries(3, seed=ix):
            reply = client.step(stance, side, command, swing, map_name=name)
            assert reply.revision == r["revision"]
            assert_reply_equals_select_step(reply, updated, ROBOT, stance, side, command, swing)
    with pytest.raises(ServerError) as e:
        client.update_terrain([38, 0], free=np.ones((3, 3), bool), map_name=name)
    assert e.value.code == "invalid_value" and "leaves the map" in e.value.message
    client.set_terrain(_terrain(False), map_name="window2d")
    with pytest.raises(ServerError) as e:
        client.update_terrain([0, 0], height=np.zeros((2, 2), np.float32), map_name="window2d")
    assert e.value.code == "invalid_field" and "2D" in e.value.message
    client.drop_terrain("window2d")
    client.drop_terrain(name)


def test_set_robot_changes_traced_leaves_without_recompiling(client):
    terrain = _terrain(True, seed=2)
    client.set_terrain(terrain, map_name="robot")
    stance, side, command, swing = _queries(1, seed=11)[0]
    client.step(stance, side, command, swing, map_name="robot")
    before = client.info()["stats"]["compiles"]
    try:
        leaves = client.set_robot({"metrics.bump_limit": 0.03}, w=2.5, margin=0.05, rotation_weight=50.0)
        assert leaves["w"] == 2.5 and leaves["margin"] == float(np.float32(0.05))
        robot = ij.robots.set_leaves(ROBOT, {"w": np.float32(2.5), "margin": np.float32(0.05),
                                             "rotation_weight": np.float32(50.0),
                                             "metrics.bump_limit": np.float32(0.03)})
        for stance, side, command, swing in _queries(4, seed=12):
            reply = client.step(stance, side, command, swing, map_name="robot")
            assert_reply_equals_select_step(reply, terrain, robot, stance, side, command, swing)
        assert client.info()["stats"]["compiles"] == before
        for bad, code in [({"w": -1.0}, "invalid_value"), ({"margin": 0.5}, "invalid_value"),
                          ({"no_such_leaf": 1.0}, "invalid_field"), ({"w": 1e39}, "non_finite")]:
            with pytest.raises(ServerError) as e:
                client.set_robot(bad)
            assert e.value.code == code, (bad, e.value)
        assert client.info()["robot"]["leaves"]["w"] == 2.5  # a refused change changes nothing
    finally:
        client.set_robot(w=1.0, margin=0.02, rotation_weight=100.0, **{"metrics.bump_limit": 0.02})
        client.drop_terrain("robot")


# ---------------------------------------------------------------------------------------------- bad input


def _raw(server, frames, req=False, timeout_ms=60000):
    """Send frames on a fresh DEALER (or REQ) socket; the reply header."""
    ctx = zmq.Context.instance()
    s = ctx.socket(zmq.REQ if req else zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.connect(f"tcp://{server.host}:{server.port}")
    try:
        s.send_multipart(frames)
        assert s.poll(timeout_ms), "no reply"
        out = s.recv_multipart()
        if out and out[0] == b"":
            out = out[1:]
        return json.loads(out[0])
    finally:
        s.close()


def _hdr(**fields):
    return json.dumps({"version": 1, **fields}).encode()


_F = np.ones((4, 4), bool).tobytes()
_H = np.zeros((4, 4), np.float32)
_STEP = {"type": "step", "stance": [1.0, 1.0, 0.0], "stance_side": -1, "command": [0.2, 0.0, 0.0]}
_SPEC = {"name": "free", "dtype": "|b1", "shape": [4, 4]}
_TERRAIN = {"type": "set_terrain", "map": "bad", "resolution": 0.05}
_BIG = int(np.sqrt(MAX_CELLS)) + 1

BAD = {
    "empty message": ([b""], "malformed"),
    "not JSON": ([b"step please"], "malformed"),
    "not UTF-8": ([b"\xff\xfe\x00"], "malformed"),
    "a JSON list": ([b"[1, 2]"], "malformed"),
    "header too large": ([_hdr(type="info", pad="x" * 70000)], "malformed"),
    "frames missing": ([_hdr(**_TERRAIN, arrays=[_SPEC])], "malformed"),
    "frames extra": ([_hdr(type="info"), b"1234"], "malformed"),
    "no version": ([json.dumps({"type": "info"}).encode()], "invalid_field"),
    "version 99": ([_hdr(type="info", version=99)], "unsupported_version"),
    "hello, no common version": ([_hdr(type="hello", versions=[7, 8])], "unsupported_version"),
    "unknown type": ([_hdr(type="teleport")], "unknown_type"),
    "missing field": ([_hdr(type="step", stance=[1, 1, 0], command=[0, 0, 0])], "invalid_field"),
    "unknown field": ([_hdr(**_STEP, speed=3)], "invalid_field"),
    "stance of 2": ([_hdr(**{**_STEP, "stance": [1.0, 1.0]})], "invalid_field"),
    "stance of strings": ([_hdr(**{**_STEP, "stance": ["a", "b", "c"]})], "invalid_field"),
    "side 0": ([_hdr(**{**_STEP, "stance_side": 0})], "invalid_field"),
    "NaN stance": ([b'{"version":1,"type":"step","stance":[NaN,1,0],"stance_side":1,"command":[0,0,0]}'],
                   "non_finite"),
    "Infinity command": ([b'{"version":1,"type":"step","stance":[1,1,0],"stance_side":1,"command":[Infinity,0,0]}'],
                         "non_finite"),
    "1e999 command": ([b'{"version":1,"type":"step","stance":[1,1,0],"stance_side":1,"command":[1e999,0,0]}'],
                      "non_finite"),
    "stance beyond float32": ([_hdr(**{**_STEP, "stance": [1e39, 1.0, 0.0]})], "non_finite"),
    "big-endian height": ([_hdr(**_TERRAIN, arrays=[{"name": "height", "dtype": ">f4", "shape": [4, 4]}]),
                           _H.astype(">f4").tobytes()], "bad_dtype"),
    "int height": ([_hdr(**_TERRAIN, arrays=[{"name": "height", "dtype": "<i8", "shape": [4, 4]}]),
                    np.zeros((4, 4), "<i8").tobytes()], "bad_dtype"),
    "3D free": ([_hdr(**_TERRAIN, arrays=[{**_SPEC, "shape": [4, 4, 1]}]), _F], "bad_shape"),
    "bytes short of the shape": ([_hdr(**_TERRAIN, arrays=[_SPEC]), _F[:-1]], "bad_shape"),
    "free and height of two shapes": ([_hdr(**_TERRAIN, arrays=[_SPEC, {"name": "height", "dtype": "<f4",
                                                                        "shape": [4, 2]}]),
                                       _F, _H[:, :2].tobytes()], "bad_shape"),
    "NaN height": ([_hdr(**_TERRAIN, arrays=[{"name": "height", "dtype": "<f4", "shape": [4, 4]}]),
                    np.where(np.eye(4, dtype=bool), np.nan, 0).astype("<f4").tobytes()], "non_finite"),
    "free of 2s": ([_hdr(**_TERRAIN, arrays=[{**_SPEC, "dtype": "|u1"}]), np.full((4, 4), 2, np.uint8).tobytes()],
                   "invalid_value"),
    "an unknown array": ([_hdr(**_TERRAIN, arrays=[{**_SPEC, "name": "colour"}]), _F], "invalid_field"),
    "map above max_cells": ([_hdr(**_TERRAIN, arrays=[{**_SPEC, "shape": [_BIG, _BIG]}]),
                             np.ones((_BIG, _BIG), bool).tobytes()], "too_large"),
    "resolution 0": ([_hdr(**{**_TERRAIN, "resolution": 0}, arrays=[_SPEC]), _F], "invalid_field"),
    "resolution 1 um": ([_hdr(**{**_TERRAIN, "resolution": 1e-6}, arrays=[_SPEC]), _F], "too_large"),
    "resolution 1e-320": ([_hdr(**{**_TERRAIN, "resolution": 1e-320}, arrays=[_SPEC]), _F], "too_large"),
    "a 400-digit resolution": ([_hdr(**{**_TERRAIN, "resolution": 10**400}, arrays=[_SPEC]), _F], "non_finite"),
    "a 400-digit stance": ([_hdr(**{**_STEP, "stance": [10**400, 1.0, 0.0]})], "non_finite"),
    "origin far away": ([_hdr(**_TERRAIN, origin=[1e5, 0], arrays=[_SPEC]), _F], "invalid_value"),
    "step on an unknown map": ([_hdr(**_STEP, map="nowhere")], "no_terrain"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_gets_an_error_reply_and_the_server_keeps_serving(server, case):
    frames, code = BAD[case]
    reply = _raw(server, frames)
    _validator("error_reply").validate(reply)
    assert reply["ok"] is False and reply["code"] == code, reply
    assert len(reply["message"]) > 10
    if code == "unsupported_version":
        assert reply["supported"] == [1]
    assert _raw(server, [_hdr(type="info", id=5)])["id"] == 5  # still serving


def test_error_replies_echo_the_request_id(server):
    reply = _raw(server, [_hdr(**{**_STEP, "stance_side": 3}, id="req-17")])
    assert reply["id"] == "req-17" and reply["request_type"] is None and reply["code"] == "invalid_field"
    reply = _raw(server, [_hdr(**_STEP, map="nowhere", id=9)])
    assert reply["id"] == 9 and reply["request_type"] == "step"


def test_too_many_maps(client):
    names = [f"m{i}" for i in range(MAX_MAPS + 1)]
    held = set(client.info()["maps"])
    small = ij.terrain.flat((20, 20), RES)
    try:
        for name in names:
            if len(held) >= MAX_MAPS:
                with pytest.raises(ServerError) as e:
                    client.set_terrain(small, map_name=name)
                assert e.value.code == "too_many_maps"
                break
            client.set_terrain(small, map_name=name)
            held.add(name)
        else:
            pytest.fail("max_maps was never reached")
        client.set_terrain(small, map_name=sorted(held)[0])  # replacing a held map is fine
    finally:
        for name in names:
            if name in held:
                client.drop_terrain(name)


def test_a_req_socket_client_is_answered(server):
    reply = _raw(server, [_hdr(type="hello", versions=[1], id=3)], req=True)
    assert reply["ok"] and reply["version"] == 1 and reply["id"] == 3


# ------------------------------------------------------------------------------------ vanishing, garbage, load


def _still_serving(server):
    with Client(server.host, server.port, timeout=REQUEST_TIMEOUT_S) as c:
        assert c.info()["ok"]


def test_a_client_that_closes_before_reading_leaves_the_server_serving(server):
    ctx = zmq.Context.instance()
    h = np.zeros(SHAPE, np.float32)
    for _ in range(3):
        s = ctx.socket(zmq.DEALER)
        s.setsockopt(zmq.LINGER, 2000)  # the request is delivered, then the socket is gone
        s.connect(f"tcp://{server.host}:{server.port}")
        s.send_multipart(schema.encode({"version": 1, "type": "set_terrain", "map": "gone", "resolution": RES},
                                       {"free": np.ones(SHAPE, bool), "height": h}))
        s.send_multipart(schema.encode({"version": 1, **_STEP, "map": "gone"}))
        s.close()
    _still_serving(server)


def test_a_killed_client_process_leaves_the_server_serving(server):
    """The client sends a map and a step, and is SIGKILLed while the server computes."""
    code = ("import os, signal, time, zmq, numpy as np\n"
            "from ijoy_jax.server import schema\n"
            f"s = zmq.Context().socket(zmq.DEALER); s.connect('tcp://{server.host}:{server.port}')\n"
            f"s.send_multipart(schema.encode({{'version': 1, 'type': 'set_terrain', 'map': 'killed', "
            f"'resolution': {RES}}}, {{'free': np.ones({SHAPE}, bool), 'height': np.zeros({SHAPE}, np.float32)}}))\n"
            "s.send_multipart(schema.encode({'version': 1, 'type': 'step', 'map': 'killed', 'stance': [1, 1, 0], "
            "'stance_side': 1, 'command': [0.2, 0, 0]}))\n"
            "time.sleep(0.05); os.kill(os.getpid(), signal.SIGKILL)\n")
    proc = subprocess.run([sys.executable, "-c", code], timeout=120)
    assert proc.returncode == -signal.SIGKILL
    _still_serving(server)
    with Client(server.host, server.port, timeout=REQUEST_TIMEOUT_S) as c:
        for name in ("killed", "gone"):
            if name in c.info()["maps"]:
                c.drop_terrain(name)


def test_a_frame_above_the_frame_limit_drops_that_connection_only(server, client):
    """ZeroMQ closes a connection whose frame exceeds max_frame_bytes (no reply: documented); others go on."""
    limit = client.info()["limits"]["max_frame_bytes"]
    s = zmq.Context.instance().socket(zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.connect(f"tcp://{server.host}:{server.port}")
    try:
        s.send_multipart([_hdr(**_TERRAIN, arrays=[{**_SPEC, "shape": [1, limit + 1]}]), bytes(limit + 1)])
        assert s.poll(1500) == 0  # no reply to that connection
    finally:
        s.close()
    _still_serving(server)


def test_raw_tcp_garbage_leaves_the_server_serving(server):
    payloads = [b"GET / HTTP/1.1\r\nHost: x\r\n\r\n", bytes(range(256)) * 4,
                b"\xff" + b"\x00" * 8 + b"\x7f\x03",  # the start of a ZMTP greeting, then nothing
                b"\xff" + b"\x00" * 8 + b"\x7f\x03\x00NULL" + b"\x00" * 16 + b"\x00\x00\x00\x00"]
    for payload in payloads:
        with socket.create_connection((server.host, server.port), timeout=10) as s:
            s.sendall(payload)
    with socket.create_connection((server.host, server.port), timeout=10):
        pass  # connect and close
    _still_serving(server)


def test_load_from_several_clients_loses_no_reply(server, client):
    """6 clients x 20 step requests at once (and one client that never reads its replies), loopback, bounded:
    every request is answered with its own decision."""
    terrain = _terrain(True, seed=21)
    client.set_terrain(terrain, map_name="load")
    queries = _queries(20, seed=22)
    expected = [ij.select_step(terrain, ROBOT, s, side, c, swing_from=w, targets=_targets(ROBOT))
                for s, side, c, w in queries]
    expected = [(int(e.index), np.asarray(e.foothold)) for e in jax.device_get(expected)]
    clients, per_client, deadline = 6, len(queries), time.monotonic() + 90.0
    results, errors = {}, []

    def worker(k):
        try:
            with Client(server.host, server.port, timeout=REQUEST_TIMEOUT_S) as c:
                order = np.random.default_rng(k).permutation(per_client)
                for i in order:
                    if time.monotonic() > deadline:
                        raise TimeoutError("load test over its time bound")
                    s, side, cmd, w = queries[i]
                    r = c.step(s, side, cmd, w, map_name="load")
                    results[(k, int(i))] = (r.index, r.foothold)
        except Exception as e:  # noqa: BLE001  reported below
            errors.append(repr(e))

    mute = zmq.Context.instance().socket(zmq.DEALER)  # sends requests and never reads the replies
    mute.setsockopt(zmq.LINGER, 0)
    mute.connect(f"tcp://{server.host}:{server.port}")
    for _ in range(100):
        mute.send_multipart(schema.encode({"version": 1, "type": "info"}))
    threads = [threading.Thread(target=worker, args=(k,)) for k in range(clients)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120.0)
    mute.close()
    assert not errors, errors
    assert len(results) == clients * per_client
    for (_, i), (index, foothold) in results.items():
        assert index == expected[i][0]
        np.testing.assert_array_equal(foothold, expected[i][1])
    client.drop_terrain("load")
    _still_serving(server)


# ------------------------------------------------------------------------------------------------- the CLI


def _serve(*args, **kw):
    return subprocess.Popen([sys.executable, "-m", "ijoy_jax.apps.cli", "serve", "--warm-up", "none", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def _serve_in_process(capsys, *args):
    """``ijoy serve --warm-up none ARGS`` through the command line's own entry point, in this process: its exit
    status and stderr (start-up errors end it before anything is served)."""
    capsys.readouterr()
    rc = cli.main(["serve", "--warm-up", "none", *args])
    return rc, capsys.readouterr().err


def test_cli_refuses_a_port_in_use_and_a_bad_host_in_one_line(server, capsys):
    rc, err = _serve_in_process(capsys, "--port", str(server.port))
    assert rc == 2 and err.strip().splitlines() == [
        f"ijoy: error: cannot listen on 127.0.0.1:{server.port} (127.0.0.1): Address already in use"], err
    rc, err = _serve_in_process(capsys, "--host", "no-such-host.invalid", "--port", "0")
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert err.startswith("ijoy: error: cannot listen on 'no-such-host.invalid': the host does not resolve"), err
    rc, err = _serve_in_process(capsys, "--port", "0", "--set", "w=abc")
    assert rc == 2 and "--set 'w=abc'" in err and len(err.strip().splitlines()) == 1


def test_a_connection_accepted_before_the_loop_starts_is_logged(caplog):
    """ijoy serve binds, warms up, then serves: a client may connect in between (the SIGINT test below lost one
    such connection's log line under load, when the monitor was attached by the loop). The listener watches its
    socket from before it is bound, so the loop logs and counts a connection it did not see accepted."""
    from ijoy_jax.server import Service
    from ijoy_jax.server import server as net

    listener = net.listen("127.0.0.1", 0, max_frame_bytes=1 << 20)
    client = zmq.Context.instance().socket(zmq.DEALER)
    client.setsockopt(zmq.LINGER, 0)
    stop, out = threading.Event(), {}
    try:
        client.connect(f"tcp://127.0.0.1:{listener.port}")
        client.send_multipart(schema.encode({"version": 1, "type": "info", "id": 1}))
        deadline = time.monotonic() + 30  # until the connection is accepted, before any loop runs
        while time.monotonic() < deadline and not listener.monitor.poll(0):
            time.sleep(0.01)
        assert listener.monitor.poll(0), "the listener never saw the connection"
        with caplog.at_level("INFO", logger="ijoy_jax.server"):
            thread = threading.Thread(target=lambda: out.update(net.run(listener, Service(ROBOT), stop)))
            thread.start()
            assert client.poll(60000), "no reply"
            assert json.loads(client.recv_multipart()[0])["id"] == 1
            stop.set()
            thread.join(30)
    finally:
        stop.set()
        client.close()
        listener.close()
    assert out["connections"] == 1 and out["requests"] == 1
    assert sum("connection from 127.0.0.1:" in r.getMessage() for r in caplog.records) == 1


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_cli_listens_logs_connections_and_stops_gracefully(sig):
    proc = _serve("--port", "0", env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        line = proc.stdout.readline().strip()
        assert line.startswith("listening on 127.0.0.1:"), line
        port = int(line.rsplit(":", 1)[1])
        for _ in range(3):
            with Client("127.0.0.1", port, timeout=REQUEST_TIMEOUT_S) as c:
                for _ in range(5):
                    c.info()
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    lines = err.strip().splitlines()
    assert sum("connection from " in x for x in lines) == 3  # one line per connection, none per request
    assert lines[-1].startswith("ijoy serve: stopped: 18 requests (0 errors), 3 connections"), lines
    assert len(lines) <= 6, lines

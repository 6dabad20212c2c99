"""ijoy drive (ijoy_jax.live): the stick mapping, trace files, the live loop against independent references, a
real footstep server process on localhost, recording and bit-exact replay, a recorded drive as a sweep, the
MuJoCo robot on native MuJoCo and on MJX, the CLI's one-line errors, and force-feedback effects checked against
the kernel's own struct layout.

Every drive walks the small map of the server tests (tests/_server_util.py), so each program compiles once for
the module and the files that share its xdist worker (tests/conftest.py: ONE_WORKER); one in-process recorded
drive (``recorded``) serves every test that needs one. Exactly one test runs the whole stack as processes: an
``ijoy drive`` process deciding on the session's ``ijoy serve`` process.
"""

import contextlib
import dataclasses
import gc
import io
import json
import math
import re
import subprocess
import sys
import textwrap
import time

import jax
import numpy as np
import pytest
from _server_util import RES, SHAPE  # tests/ is on sys.path (pytest rootdir import)
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax import live, robots, select, stick, sweep
from ijoy_jax.apps import cli
from ijoy_jax.live import forcefeedback
from ijoy_jax.server import Client

ROBOT = robots.hrp2()
LO, HI = (np.asarray(v, np.float64) for v in robots.command_range(ROBOT))
TERRAIN = {"kind": "family", "family": "obstacles", "seed": 1, "shape": list(SHAPE), "resolution": RES}
# Float metrics of the sweep engine's vmapped chunk vs a single jitted rollout: the same ops, possibly fused
# differently (m); and a float64 sum of the recorded float32 feet vs the rollout's float32 sum (m, 5 steps).
FLOAT_TOL = 1e-5
TRACE = textwrap.dedent("""\
    # forward, then forward turning left, then sideways right
    t,forward,left,turn
    0.0, 1.0, 0.0, 0.0
    1.7, 0.7, 0.0, 0.8
    3.3, 0.0, -1.0, 0.0
    4.0, 0.0, 0.0, 0.0
""")


# ------------------------------------------------------------------------------------------- the stick mapping

axis = st.floats(-1.0, 1.0, allow_nan=False)
hostile = st.one_of(axis, st.floats(allow_nan=True, allow_infinity=True))


@settings(max_examples=200, deadline=None)
@given(st.tuples(hostile, hostile, hostile), st.floats(0.0, 0.9))
def test_command_stays_in_the_robot_range(axes, dz):
    c = live.axes_to_command(axes, ROBOT, dz)
    assert np.all(np.isfinite(c)) and np.all(c >= LO - 1e-12) and np.all(c <= HI + 1e-12)


@settings(max_examples=200, deadline=None)
@given(axis, axis, st.floats(0.0, 0.9))
def test_dead_zone_and_monotone_and_continuous(a, b, dz):
    for k in range(3):
        va, vb = np.zeros(3), np.zeros(3)
        va[k], vb[k] = a, b
        ca, cb = live.axes_to_command(va, ROBOT, dz)[k], live.axes_to_command(vb, ROBOT, dz)[k]
        if abs(a) <= dz:
            assert ca == 0.0
        if a <= b:
            assert ca <= cb  # monotone in the deflection
        # Lipschitz: no jump at the dead zone's edge (slope at most range / (1 - dz))
        assert abs(ca - cb) <= max(HI[k], -LO[k]) / (1 - dz) * abs(a - b) * (1 + 1e-9) + 1e-12


def test_full_deflection_is_the_range_ends():
    np.testing.assert_allclose(live.axes_to_command([1, 1, 1], ROBOT), HI)
    np.testing.assert_allclose(live.axes_to_command([-1, -1, -1], ROBOT), LO)
    np.testing.assert_allclose(live.axes_to_command([0.55, 0, 0], ROBOT, 0.1), [0.5 * HI[0], 0, 0])  # half-way
    with pytest.raises(ValueError, match="deadzone"):
        live.axes_to_command([0, 0, 0], ROBOT, 1.0)


def test_gamepad_axes_mapping():
    np.testing.assert_array_equal(live.gamepad_axes([0.5, -1.0, 0.0, 0.25]), [1.0, -0.5, -0.25])
    np.testing.assert_array_equal(live.gamepad_axes([0.0, 0.0]), [0.0, -0.0, 0.0])  # a pad with 2 axes: no turn
    np.testing.assert_array_equal(live.gamepad_axes([np.nan, 3.0, 0.0, 0.0]), [-1.0, 0.0, 0.0])


_JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
                     lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner,
                                                                                  max_size=4), max_leaves=12)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(_JSON)
def test_a_page_message_is_an_object_or_ignored(value):
    from ijoy_jax.live.view import page_message

    text = json.dumps(value)
    assert page_message(text) == (value if isinstance(value, dict) else None) or value != value  # NaN != NaN
    assert page_message(text[: len(text) // 2]) in (None, value) or isinstance(value, dict)


def test_the_views_socket_ignores_hostile_messages_and_keeps_the_connection():
    """Valid JSON that is not an object, JSON nested past the parser's recursion limit (in 4000 bytes), a stick
    of the wrong size and a message over MAX_MESSAGE_BYTES: the first three are ignored on the same connection
    (they once raised AttributeError / RecursionError in the handler and dropped it), the last closes only its
    own connection."""
    import asyncio

    import aiohttp

    from ijoy_jax.live.view import MAX_MESSAGE_BYTES, ViewServer

    async def talk(url):
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(url) as ws:
                for text in ("[1, 2, 3]", "42", "null", '"axes"', "[" * 2000 + "]" * 2000, "{", '{"type": 1}',
                             '{"type": "axes"}', '{"type": "axes", "axes": [1, 2]}',
                             '{"type": "axes", "axes": {"a": 1}}', '{"type": "axes", "axes": [0.5, 0, 0], "source": '
                             + "[" * 10 + "]" * 10 + "}"):
                    await ws.send_str(text)
                await ws.send_str(json.dumps({"type": "axes", "axes": [0.25, -0.5, 1.0], "source": "test"}))
                for _ in range(100):
                    if view.axes.source == "test":
                        break
                    await asyncio.sleep(0.02)
                assert not ws.closed
            async with session.ws_connect(url) as ws:
                await ws.send_str('{"type": "axes", "pad": "' + "x" * MAX_MESSAGE_BYTES + '"}')
                msg = await ws.receive(timeout=5)
                while msg.type == aiohttp.WSMsgType.TEXT:  # the state the server pushes, then the close
                    msg = await ws.receive(timeout=5)
                assert msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.CLOSING)

    with ViewServer(port=0) as view:
        asyncio.run(talk(view.url.replace("http://", "ws://").rstrip("/") + "/ws"))
        np.testing.assert_array_equal(view.axes.axes(), [0.25, -0.5, 1.0])
        assert view.axes.source == "test"
        assert view.axes.updates == 2  # the "[[...]]" source was a valid stick message (source as text); no other


@pytest.mark.parametrize("dt", [0.0, -0.01, float("nan"), float("inf"), 1e-300, "0.01", True])
def test_a_control_period_that_would_never_tick_or_never_end_is_refused(dt):
    """control_dt 0 once raised ZeroDivisionError and 1e-300 s ticked without end in real time."""
    from ijoy_jax.live.bodies import MIN_CONTROL_DT, PerfectBody

    start = np.array([[0.3, 0.9, 0.0], [0.3, 0.7, 0.0]])
    with pytest.raises(ValueError, match=f"control_dt must be a finite number of seconds >= {MIN_CONTROL_DT:g}"):
        PerfectBody(ij.robots.hrp2(), start, 1, dt)
    assert PerfectBody(ij.robots.hrp2(), start, 1, np.float32(0.01)).ticks_per_step == 80


def test_no_gamepad_is_a_clear_error():
    with pytest.raises(live.InputError, match="no gamepad found"):
        live.inputs.Gamepad()


def test_terminal_keys_through_a_pty():
    """Keys typed into a real pseudo-terminal: w then a hold their axes, space stops."""
    import os
    import time

    master, slave = os.openpty()
    kb = live.inputs.TerminalKeyboard(fd=slave, hold=5.0)
    try:
        os.write(master, b"wa")
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and not np.array_equal(kb.axes(), [1.0, 1.0, 0.0]):
            time.sleep(0.01)
        np.testing.assert_array_equal(kb.axes(), [1.0, 1.0, 0.0])
        os.write(master, b" ")
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and np.any(kb.axes()):
            time.sleep(0.01)
        np.testing.assert_array_equal(kb.axes(), [0.0, 0.0, 0.0])
    finally:
        kb.close()
        os.close(master)
        os.close(slave)


# ------------------------------------------------------------------------------------------- trace files


def test_trace_is_sampled_and_held(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text(TRACE)
    tr = live.read_trace(p)
    assert tr.duration == 4.0
    np.testing.assert_array_equal(tr.at(-0.1), [0, 0, 0])
    np.testing.assert_array_equal(tr.at(0.0), [1, 0, 0])
    np.testing.assert_array_equal(tr.at(1.69), [1, 0, 0])
    np.testing.assert_array_equal(tr.at(1.7), [0.7, 0, 0.8])


@pytest.mark.parametrize("text, match", [
    ("0,1,0\n", "expected 4 comma-separated"), ("0,1,x,0\n", "not a number"), ("0,1,0,0\n0,1,0,0\n", "increase"),
    ("0,2,0,0\n", r"\[-1, 1\]"), ("# nothing\n", "no samples"), ("0,nan,0,0\n", "finite")])
def test_bad_traces_name_the_line(tmp_path, text, match):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(live.InputError, match=match):
        live.read_trace(p)


# ------------------------------------------------------------------------------------------- the loop


@pytest.fixture(scope="module")
def trace(tmp_path_factory):
    p = tmp_path_factory.mktemp("trace") / "drive.csv"
    p.write_text(TRACE)
    return p


@pytest.fixture(scope="module")
def recorded(trace, tmp_path_factory):
    """A headless scripted drive on TERRAIN in this process (the local selector), recorded: (path, DriveResult).
    Its programs (selector, cue, cost terms) serve every drive of the module, and reach the ijoy drive process of
    the end-to-end test through the persistent compilation cache."""
    out = tmp_path_factory.mktemp("recorded") / "drive.mcap"
    result = live.run(live.DriveSettings(terrain=TERRAIN), live.ScriptInput(trace), realtime=False, record_to=out)
    assert len(result.decisions) == 5 and all(d["valid"] for d in result.decisions)  # the tests' premise
    return out, result


def _rollout_reference(rec):
    """The scanned Algorithm 1 (ij.rollout, the perfect walker) with the recorded commands, one per decision."""
    commands = np.asarray([d["command"] for d in rec.decisions], np.float32)
    traj = ij.rollout(rec.terrain, rec.robot, np.asarray(rec.config["start"], np.float32), commands,
                      num_steps=len(commands))
    return traj


@pytest.mark.slow
def test_scripted_drive_through_a_real_server_replays_identically(trace, recorded, footstep_server, tmp_path):
    """The whole stack headless: `ijoy drive --script --headless --record` (its own process) deciding on a real
    `ijoy serve` process over localhost sockets; the recording replays in-process and through the CLI with
    identical footsteps, equal to the scanned rollout's, to select_step's decisions and to the same drive
    decided in this process."""
    out = tmp_path / "drive.mcap"
    server = footstep_server
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "ijoy_jax.apps.cli", "drive", "--script", str(trace), "--headless", "--record",
             str(out), "--server", f"{server.host}:{server.port}", "--terrain", "obstacles", "--seed", "1",
             "--shape", f"{SHAPE[0]}x{SHAPE[1]}", "--resolution", str(RES), "--ff", "off", "--json"],
            capture_output=True, text=True, timeout=300)
    finally:  # the shared server as the other tests expect it: no "default" map (tests/test_server.py)
        with Client(server.host, server.port) as c:
            if "default" in c.info()["maps"]:
                c.drop_terrain("default")
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    rec = live.read_recording(out)
    n = len(rec.decisions)
    assert n == 5 == summary["decisions"]  # decisions at 0, 0.8, ..., 3.2 s of a 4 s trace
    assert {d["decider"] for d in rec.decisions} == {"server"}
    assert summary["late"] == 0 and 0 < summary["latency_p99_s"] < 0.8
    # every decision equals select_step on the recorded inputs (an independent call in this process)
    targets = ij.make_targets(rec.robot)  # what select_step builds when given none
    for d in rec.decisions:
        c = ij.select_step(rec.terrain, rec.robot, np.asarray(d["stance"], np.float32), int(d["stance_side"]),
                           np.asarray(d["command"], np.float32), swing_from=np.asarray(d["swing_from"], np.float32),
                           targets=targets)
        np.testing.assert_array_equal(np.asarray(c.foothold), np.asarray(d["foothold"], np.float32))
        assert bool(c.valid) == d["valid"] and int(c.index) == d["index"]
    # the live loop is Algorithm 1: the scanned rollout with the same commands takes the same footholds
    traj = _rollout_reference(rec)
    sent = np.asarray([s["sent"] for s in rec.states[1:]], np.float32)
    np.testing.assert_array_equal(sent, np.asarray(traj.footholds))
    np.testing.assert_array_equal(np.asarray(rec.states[-1]["feet"], np.float32), np.asarray(traj.feet))
    # the server decided as this process's selector did: the in-process recorded drive's footsteps, bit for bit
    np.testing.assert_array_equal(sent, recorded[1].footsteps())
    # the commands are the trace's axes through the dead zone and the range, read as each step began
    np.testing.assert_allclose(rec.decisions[2]["axes"], [1.0, 0.0, 0.0])  # at 1.6 s, before the change at 1.7
    np.testing.assert_allclose(rec.decisions[3]["axes"], [0.7, 0.0, 0.8])
    np.testing.assert_allclose(rec.decisions[3]["command"], live.axes_to_command([0.7, 0, 0.8], ROBOT))
    assert rec.decisions[3]["t"] == pytest.approx(2.4)
    # terms of the chosen footholds: named, finite where valid
    assert all(d["terms"]["total"] < np.inf for d in rec.decisions if d["valid"])
    # replay: in-process (the local selector) and through the command line
    result, _, mismatches = live.replay(out)
    assert mismatches == [] and len(result.decisions) == n
    np.testing.assert_array_equal(result.footsteps(), sent)
    assert cli.main(["drive", "--replay", str(out)]) == 0


@pytest.mark.slow
def test_replay_detects_a_changed_recording(recorded, tmp_path):
    """A recording whose footsteps were tampered with does not replay identically (the check can fail)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    out = recorded[0]
    bad = tmp_path / "b.mcap"
    with open(out, "rb") as f, open(bad, "wb") as g:
        reader, writer = make_reader(f), Writer(g)
        writer.start()
        for m in reader.iter_metadata():
            writer.add_metadata(m.name, m.metadata)
        for a in reader.iter_attachments():
            writer.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        ids = {}
        for schema, channel, message in reader.iter_messages():
            if channel.topic not in ids:
                sid = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.topic] = writer.register_channel(channel.topic, channel.message_encoding, sid)
            data = message.data
            if channel.topic == "/ijoy/state":
                msg = json.loads(data)
                if msg["step"] == 2:
                    msg["feet"][0][0] += 1e-6  # one foot, one micrometre
                data = json.dumps(msg).encode()
            writer.add_message(ids[channel.topic], message.log_time, data, message.publish_time)
        writer.finish()
    _, _, mismatches = live.replay(bad)
    assert mismatches == [2]
    assert cli.main(["drive", "--replay", str(bad)]) == 1


@pytest.mark.slow
def test_decisions_overlap_the_step_and_wait_when_late(trace):
    """Real time: a decider slower than a step makes the robot wait (slack < 0, counted), a fast one does not."""
    import time

    terrain, robot, start = live.open_terrain(TERRAIN)

    class Slow(live.LocalDecider):
        def decide(self, *a, **k):
            time.sleep(0.3)
            return super().decide(*a, **k)

    fast_body = live.PerfectBody(robot, start, control_dt=0.05)
    # a 0.25 s step (robot.step_time stays 0.8 for the decisions; only the body's clock is shorter)
    fast_body.ticks_per_step = 5
    res = live.drive(terrain, robot, fast_body, live.ScriptInput(trace), Slow(terrain, robot), realtime=True,
                     num_steps=3)
    assert len(res.latencies) == 3 and np.all(res.latencies >= 0.3)
    assert np.all(res.slacks < 0) and res.summary()["late"] == 3
    body = live.PerfectBody(robot, start, control_dt=0.05)
    frozen, offsets = [], []  # the garbage collector's frozen objects; each tick's wall time less its drive time

    def on_tick(event):
        offsets.append(time.perf_counter() - event["t"])
        frozen.append(gc.get_freeze_count())

    res = live.drive(terrain, robot, body, live.ScriptInput(trace), live.LocalDecider(terrain, robot), realtime=True,
                     num_steps=2, on_tick=on_tick)
    # Python's garbage collector leaves what existed before the clock alone during the drive
    assert min(frozen) > 0 and gc.get_freeze_count() == 0
    # Each decision had the rest of its step (from its dispatch tick on) to be ready in; it is late exactly when
    # it took longer. The fast decider takes milliseconds against 0.8 s, so at least one of the two is on time
    # even if a loaded machine stalls this process once by a whole step (stalls of 0.6 s and 1.3 s were seen).
    available = res.slacks + res.latencies
    step_ends = [s["t"] for s in res.states[:-1]]  # the warm-up's and the first step's (the last dispatches none)
    np.testing.assert_allclose(available, [t - d["t"] for d, t in zip(res.decisions, step_ends, strict=True)],
                               atol=1e-9)
    assert np.all(available > 0.3), available  # dispatched early in the step: the decision overlaps the walking
    assert res.summary()["late"] == np.sum(res.latencies > available) and np.sum(res.slacks > 0) >= 1
    # The warm-up and two steps (48 ticks, every one seen: view_every is the tick), paced to the wall clock: the
    # drive never ends ahead of it, and each tick is behind the schedule t0 + k * dt only by the lag the loop
    # measured and reports (the lag a person would be told of). (A loaded 2-core machine stalled this thread 0.6 s and
    # 1.3 s in full cold runs; the unpaced end of a drive, after its last tick, once took 0.12 s there, so the
    # drive's whole wall time is no measure of its pacing.)
    assert len(offsets) == 3 * 16
    assert res.wall_s >= 3 * 0.8 - 0.02, res.wall_s
    # + 0.05 s (a tick): from the lag's measure to on_tick's clock read, the event's fields are built with the GIL
    # shared with the decision thread
    assert max(offsets) - min(offsets) <= res.tick_lag_max + 0.05, (np.ptp(offsets), res.tick_lag_max)


def test_a_tick_woken_late_counts_as_behind_the_clock(trace, monkeypatch):
    """A loaded machine can wake the loop's thread late from its sleep: that tick is behind the wall clock, and
    the reported lag says so (a lag measured only before the sleep missed it by up to a tick)."""
    import time

    from ijoy_jax.live import loop

    terrain, robot, start = live.open_terrain(TERRAIN)
    real_sleep, calls = time.sleep, []

    def late_once(s):
        calls.append(s)
        real_sleep(s + (0.2 if len(calls) == 5 else 0.0))

    monkeypatch.setattr(loop.time, "sleep", late_once)
    offsets = []
    res = live.drive(terrain, robot, live.PerfectBody(robot, start, control_dt=0.05), live.ScriptInput(trace),
                     live.LocalDecider(terrain, robot), realtime=True, num_steps=1,
                     on_tick=lambda e: offsets.append(time.perf_counter() - e["t"]))
    assert len(calls) >= 5 and res.tick_lag_max >= 0.2, (len(calls), res.tick_lag_max)
    assert max(offsets) - min(offsets) <= res.tick_lag_max + 0.05  # as in the test above


def test_no_valid_step_stands_and_decides_again():
    """Walled in ahead: the robot stands (StopWalking) while the stick pushes forward, and walks again when the
    person turns the stick sideways (Algorithm 1 live; the scanned rollout would stop for good)."""
    free = np.ones(SHAPE, bool)
    free[int(round(1.1 / RES)):, :] = False  # a wall from x = 1.1 m
    terrain = ij.terrain.from_arrays(None, free, RES)
    robot = robots.hrp2(margin=0.02)
    start = robots.start_stance(robot, 1.0, 0.8)
    trace = live.Trace(np.array([0.0, 2.4, 4.0]), np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 0]]))
    res = live.drive(terrain, robot, live.PerfectBody(robot, start), live.ScriptInput(trace),
                     live.LocalDecider(terrain, robot), realtime=False)
    valid = [d["valid"] for d in res.decisions]
    assert True in valid and valid[-1]
    feet = np.asarray(res.states[-1]["feet"])
    assert feet[:, 0].max() < 1.1 - 0.121  # never onto the wall
    assert feet[:, 1].mean() > 0.85  # went left along it


# ------------------------------------------------------------------------------------------- a drive's exported trace

EXPORT_STICK = live.Trace(np.array([0.0, 0.7, 1.5, 2.2]),
                          np.array([[1.0, 0, 0], [0.6, 0, 0.5], [0, -1.0, 0], [0, 0, 0]]))
"""A stick whose axes change between the decisions of a 0.8 s step (read at 0, 0.8, 1.6 s, or 0.4, 1.2, 2.0 s
half way into each step): a decision too many, too few or read from other axes has another command."""
EXPORT_DT = 0.1  # s: the perfect body's tick in these drives (8 a step: cheap; the loop's schedule is the same)


@pytest.fixture(scope="module")
def open_map():
    """The small 2D map without obstacles, its robot, start feet (2, 3), tables and one decider for every drive on
    it (a decider built per drive costs about a second): (terrain, robot, start, prepared, decider)."""
    terrain = ij.terrain.from_arrays(None, np.ones(SHAPE, bool), RES)
    robot = robots.hrp2(margin=0.02)
    prepared = select.prepare(terrain, robot)
    start = np.asarray(robots.start_stance(robot, 0.5, 0.8), np.float32)
    return terrain, robot, start, prepared, live.LocalDecider(terrain, robot, prepared=prepared)


def _drive_on(open_map, source, record_to=None, **options):
    """A headless drive of the perfect body on ``open_map`` (:func:`ijoy_jax.live.drive` ``options``), recorded
    to ``record_to`` as ``ijoy drive --record`` writes it when given."""
    terrain, robot, start, prepared, decider = open_map
    settings = live.DriveSettings(terrain={"kind": "arrays"}, control_dt=EXPORT_DT,
                                  decide_at=options.get("decide_at", 0.0))
    config = {"settings": dataclasses.asdict(settings), "start": start.tolist()}
    with contextlib.ExitStack() as stack:
        recorder = None if record_to is None else stack.enter_context(live.Recorder(record_to, config, terrain, robot))
        return live.drive(terrain, robot, live.PerfectBody(robot, start, control_dt=EXPORT_DT), source, decider,
                          realtime=False, recorder=recorder, prepared=prepared, **options)


@pytest.mark.parametrize("options, edit", [
    ({}, None),
    ({"duration": 1.5}, None),
    ({"num_steps": 2}, None),
    ({"decide_at": 0.5}, None),
    ({}, lambda rec: rec._replace(inputs=[m for m in rec.inputs if m["t"] >= 1.0])),
    ({}, lambda rec: rec._replace(inputs=[])),
], ids=["ended by its script", "by duration", "by num_steps", "decide_at 0.5", "first input late", "no inputs"])
def test_an_exported_trace_drives_the_drives_decisions(open_map, tmp_path, options, edit):
    """A recorded drive's exported trace (``ijoy drive --replay A.mcap --export-trace B.csv``), driven with A's
    settings (``ijoy drive --script B.csv``): the scripted drive makes A's decisions, as many (whatever ended A: its
    script, a duration, a step count) at the same times with the same commands, so it takes A's footsteps; also
    from a recording whose stick was recorded late or not at all (each decision keeps the axes it read)."""
    drove = _drive_on(open_map, live.ScriptInput(EXPORT_STICK), tmp_path / "a.mcap", **options)
    assert len(drove.decisions) == (3 if set(options) <= {"decide_at"} else 2)  # the premise: shorter when told so
    rec = live.read_recording(tmp_path / "a.mcap")
    live.session.export_trace(rec if edit is None else edit(rec), tmp_path / "b.csv")
    again = _drive_on(open_map, live.ScriptInput(tmp_path / "b.csv"), decide_at=options.get("decide_at", 0.0))
    assert len(again.decisions) == len(drove.decisions)
    for key in ("t", "axes", "command"):
        np.testing.assert_array_equal([d[key] for d in again.decisions], [d[key] for d in drove.decisions], key)
    np.testing.assert_array_equal(again.footsteps(), drove.footsteps())


def _loop_recording(stick, *, ticks, dt, dispatch, decisions, interrupted, first_input):
    """The messages :func:`ijoy_jax.live.drive` records for the scripted ``stick`` (a function of the tick number)
    on a body of ``ticks`` ticks of ``dt`` s a step, reading the stick ``dispatch`` ticks into each step:
    ``decisions`` decisions, then the step period without one (or, ``interrupted``, Ctrl-C in it: its end not
    recorded); the stick from tick ``first_input`` on (the drive's loop records it from tick 0)."""
    periods = decisions + 1
    inputs = [{"t": k * dt, "axes": stick(k)} for k in range(first_input, periods * ticks)]
    made = [{"t": (j * ticks + dispatch) * dt, "axes": stick(j * ticks + dispatch)} for j in range(decisions)]
    states = [{"step": j, "t": (j + 1) * ticks * dt} for j in range(periods - bool(interrupted))]
    return live.Recording({}, None, ROBOT, inputs, made, states, None)


_AXES = st.tuples(*[st.sampled_from([-1.0, -0.5, 0.0, 0.05, 0.3, 1.0, 2.5, -40.0])] * 3)  # beyond 1: hand-edited


@settings(max_examples=100, deadline=None, derandomize=True)
@given(dt=st.sampled_from([0.8, 0.4, 0.1, 0.05, 0.01]), decide_at=st.floats(0.0, 0.99), decisions=st.integers(1, 6),
       interrupted=st.booleans(), first_input=st.integers(0, 700),
       changes=st.lists(st.tuples(st.integers(0, 700), _AXES), max_size=8))
def test_an_exported_trace_schedules_the_recorded_commands(tmp_path_factory, dt, decide_at, decisions, interrupted,
                                                           first_input, changes):
    """Any stick (axes beyond [-1, 1] too, as a hand-edited file may hold: the drive reads them clipped), step
    timing, ``decide_at``, length and end of a drive (a last step period without a decision, or Ctrl-C), its
    stick recorded from any tick: the exported trace, scheduled as a scripted drive reads it
    (:func:`ijoy_jax.stick.scripted_commands`, the loop's schedule), gives exactly the recorded decisions'
    commands, as many, bit for bit."""
    ticks = int(round(float(ROBOT.step_time) / dt))
    dispatch = int(np.floor(decide_at * ticks))

    def held(k):
        past = [a for at, a in sorted(changes, key=lambda c: c[0]) if at <= k]
        return list(past[-1]) if past else [0.0, 0.0, 0.0]

    rec = _loop_recording(held, ticks=ticks, dt=dt, dispatch=dispatch, decisions=decisions, interrupted=interrupted,
                          first_input=first_input)
    path = tmp_path_factory.mktemp("export") / "b.csv"
    live.session.export_trace(rec, path)
    got = stick.scripted_commands(live.read_trace(path), ROBOT, decide_at=decide_at, control_dt=dt)
    want = np.asarray([live.axes_to_command(d["axes"], ROBOT) for d in rec.decisions], np.float64)
    np.testing.assert_array_equal(got, want)


def test_a_drive_says_what_its_warm_up_compiles_only_when_asked(open_map, monkeypatch, capsys):
    """``drive(..., progress=True)`` (``ijoy drive``) names its warm-up's compile on stderr with the seconds
    elapsed (the threshold lowered to 0 s here: warm programs compile in no time); the library's default says
    nothing. The decisions are the same either way."""
    from ijoy_jax import progress

    monkeypatch.setattr(progress, "SHOW_AFTER_S", 0.0)
    monkeypatch.setattr(live.PerfectBody, "warm_up", lambda self: time.sleep(0.3), raising=False)  # a compile
    trace = live.Trace(np.array([0.0, 2.0]), np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]))
    quiet = _drive_on(open_map, live.ScriptInput(trace))
    assert capsys.readouterr().err == ""
    told = _drive_on(open_map, live.ScriptInput(trace), progress=True)
    lines = capsys.readouterr().err.splitlines()
    what = "the drive's programs (PerfectBody, the decision, the cue)"
    assert lines[0].startswith(f"ijoy drive: compiling {what}: "), lines
    assert re.fullmatch(rf"ijoy drive: compiled {re.escape(what)} in \d+\.\d s", lines[-1]), lines
    np.testing.assert_array_equal([d["command"] for d in told.decisions], [d["command"] for d in quiet.decisions])


def test_a_recording_without_decisions_exports_no_trace(tmp_path):
    """A drive stopped before its first decision (by Ctrl-C) has no trace: with ``decide_at`` 0 a scripted
    drive reads its first decision at 0 s, before any trace's last time (> 0 s). One line naming the file, and no
    file written."""
    rec = _loop_recording(lambda k: [1.0, 0.0, 0.0], ticks=80, dt=0.01, dispatch=0, decisions=0, interrupted=False,
                          first_input=0)
    out = tmp_path / "b.csv"
    with pytest.raises(ValueError, match="no decision") as e:
        live.session.export_trace(rec, out)
    assert len(str(e.value).splitlines()) == 1 and str(out) in str(e.value) and not out.exists()


def test_a_drive_of_the_g1_steps_the_g1s_robot_records_and_replays(trace, tmp_path):
    """``model="g1"`` (``ijoy drive --model g1``): the selector steps robots.g1 (its footprint, its stance width,
    its action set), the recording says so and replays identically; a sweep cannot walk it, and says why."""
    out = tmp_path / "g1.mcap"
    res = live.run(live.DriveSettings(terrain=TERRAIN, model="g1"), live.ScriptInput(trace), realtime=False,
                   record_to=out)
    g1 = robots.g1()
    rec = live.read_recording(out)
    assert rec.config["settings"]["model"] == "g1" and rec.config["settings"]["body"] == "perfect"
    for a, b in zip(jax.tree_util.tree_leaves(rec.robot), jax.tree_util.tree_leaves(g1), strict=True):
        np.testing.assert_array_equal(a, b)
    start = np.asarray(rec.config["start"])
    assert start[0, 1] - start[1, 1] == pytest.approx(float(g1.p0[1]), abs=1e-6)  # the G1 stands 0.24 m wide
    # one decision per step of the 4 s trace: the G1 steps every 0.5 s (robots.G1_STEP_TIME), HRP-2 every 0.8 s
    assert len(res.decisions) == math.ceil(4.0 / float(g1.step_time)) == 8
    assert all(d["valid"] for d in res.decisions)
    feet = np.asarray(res.states[-1]["feet"])
    assert feet[:, 0].mean() > start[:, 0].mean() + 0.2  # it walked forward
    _, _, mismatches = live.replay(out)
    assert mismatches == []
    with pytest.raises(ValueError, match="the recording's robot is model 'g1': a sweep walks the project's biped"):
        sweep.export_drive(rec, tmp_path / "g1.toml", out)


@pytest.mark.slow
def test_native_robot_drives_and_replays(trace, tmp_path):
    """The MuJoCo biped on native MuJoCo, driven by the scripted stick: it walks without falling, lands where
    it was sent, and its replay is identical (MuJoCo and the compiled controller are deterministic); exported as
    a sweep, it is one for the MJX biped (walker = "mjx"; the file read back, nothing run)."""
    out = tmp_path / "native.mcap"
    flat = {"kind": "family", "family": "flat", "seed": 0, "shape": list(SHAPE), "resolution": RES}
    res = live.run(live.DriveSettings(terrain=flat, body="native"), live.ScriptInput(trace), realtime=False,
                   record_to=out, num_steps=3)
    logs = [s["log"] for s in res.states[1:]]
    assert len(logs) == 3 and not any(bool(g["fallen"]) for g in logs)
    assert max(float(g["placement_error"]) for g in logs) < 0.03
    feet = np.asarray(res.states[-1]["feet"])
    assert feet[:, 0].mean() > np.asarray(res.states[0]["feet"])[:, 0].mean() + 0.2  # it walked forward
    _, _, mismatches = live.replay(out)
    assert mismatches == []
    info = sweep.export_drive(live.read_recording(out), tmp_path / "native.toml", out, terrain="family")
    assert info["walker"] == "mjx" and info["decisions"] == 3 and info["terrain"] == "family"
    cfg = sweep.load_config(tmp_path / "native.toml")
    assert cfg.walker == "mjx" and cfg.family == "flat" and cfg.num_steps == 3


@pytest.mark.slow
def test_mjx_robot_drives_through_the_cli_and_replays(trace, tmp_path, capsys):
    """``ijoy drive --robot mjx`` (the command line, in this process): the MuJoCo biped on MJX, headless and
    scripted, on the 2.5D flat map tests/test_sim_mjx_biped.py walks (its compiled programs); it walks without
    falling, lands where it was sent, says where MJX runs, and its recording replays identically through the
    command line (one robot on MJX is deterministic); exported, it is a walker = "mjx" sweep."""
    out = tmp_path / "mjx.mcap"
    args = ["drive", "--robot", "mjx", "--script", str(trace), "--headless", "--record", str(out), "--terrain", "flat",
            "--height", "--shape", f"{SHAPE[0]}x{SHAPE[1]}", "--resolution", str(RES), "--steps", "3", "--ff", "off",
            "--json"]
    assert cli.main(args) == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out.strip().splitlines()[-1])
    assert "the MJX biped runs on" in captured.err
    assert summary["decisions"] == 3 and summary["steps_taken"] == 3 and summary["late"] == 0
    assert summary["tick_lag_max_s"] == 0.0  # headless: virtual time, nothing paced
    rec = live.read_recording(out)
    assert rec.config["settings"]["body"] == "mjx" and rec.terrain.has_height
    logs = [s["log"] for s in rec.states[1:]]
    assert len(logs) == 3 and not any(bool(g["fallen"]) for g in logs)
    assert max(float(g["placement_error"]) for g in logs) < 0.03
    feet = np.asarray(rec.states[-1]["feet"])
    assert feet[:, 0].mean() > np.asarray(rec.states[0]["feet"])[:, 0].mean() + 0.2  # it walked forward
    assert cli.main(["drive", "--replay", str(out)]) == 0
    assert "footsteps identical" in capsys.readouterr().out
    info = sweep.export_drive(rec, tmp_path / "mjx.toml", out)
    assert info["walker"] == "mjx" and info["decisions"] == 3


@pytest.mark.slow
def test_the_g1_on_mjx_drives_through_the_cli_and_replays(trace, tmp_path, capsys):
    """``ijoy drive --robot mjx --model g1``: the Unitree G1 on MJX, stepped by robots.g1, headless and scripted on
    the 2.5D flat map of the biped's drive above; it walks without falling, lands where it was sent, says where
    MJX runs, and its recording replays identically through the command line."""
    out = tmp_path / "g1.mcap"
    args = ["drive", "--robot", "mjx", "--model", "g1", "--script", str(trace), "--headless", "--record", str(out),
            "--terrain", "flat", "--height", "--shape", f"{SHAPE[0]}x{SHAPE[1]}", "--resolution", str(RES), "--steps",
            "3", "--ff", "off", "--json"]
    assert cli.main(args) == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out.strip().splitlines()[-1])
    assert "the MJX G1 runs on" in captured.err
    assert summary["decisions"] == 3 and summary["steps_taken"] == 3 and summary["late"] == 0
    rec = live.read_recording(out)
    assert rec.config["settings"]["model"] == "g1" and rec.config["settings"]["body"] == "mjx"
    assert float(rec.robot.foot_length) == pytest.approx(0.18) and float(rec.robot.foot_width) == pytest.approx(0.06)
    logs = [s["log"] for s in rec.states[1:]]
    assert len(logs) == 3 and not any(bool(g["fallen"]) for g in logs)
    assert max(float(g["placement_error"]) for g in logs) < 0.03
    feet = np.asarray(rec.states[-1]["feet"])
    assert feet[:, 0].mean() > np.asarray(rec.states[0]["feet"])[:, 0].mean() + 0.2  # it walked forward
    assert cli.main(["drive", "--replay", str(out)]) == 0
    assert "footsteps identical" in capsys.readouterr().out


# ------------------------------------------------------------------------------------------- a drive as a sweep

MARGINS = (0.02, 0.08)  # the drive's margin (scenario 0 is the drive) and another: one chunk of 2 scenarios


def _exported_run(recorded, folder, terrain):
    """``ijoy drive --replay --export-sweep`` (the command line, in this process), a [grid] of MARGINS added, run
    by the sweep engine: (the command's JSON line, config, table)."""
    path, _ = recorded
    out = folder / "sweeps" / "drive.toml"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = cli.main(["drive", "--replay", str(path), "--export-sweep", str(out), "--sweep-terrain", terrain])
    assert code == 0
    out.write_text(out.read_text() + f'\n[grid]\n"robot.margin" = {list(MARGINS)}\n')
    cfg = sweep.load_config(out)
    stats = sweep.run(cfg, folder / "results", chunk_size=len(MARGINS), progress=False)
    assert stats.computed == len(MARGINS)
    return json.loads(printed.getvalue().strip().splitlines()[-1]), cfg, sweep.load(folder / "results")


@pytest.fixture(scope="module")
def exports(recorded, tmp_path_factory):
    """The recorded drive exported to a sweep with each terrain (its recorded map, its family) and run:
    {terrain: (JSON line, config, table)}."""
    return {t: _exported_run(recorded, tmp_path_factory.mktemp(f"export-{t}"), t) for t in sweep.EXPORT_TERRAINS}


def _along_across(result):
    """Independently of the rollout: the feet's midpoint's displacement along and across each decision's commanded
    direction (world frame, the stance foot's yaw), summed over the drive's steps, from the recorded feet (m)."""
    along = across = 0.0
    for d, before, after in zip(result.decisions, result.states[:-1], result.states[1:], strict=True):
        yaw = float(d["stance"][2])
        c = np.asarray(d["command"], np.float64)
        direction = np.array([np.cos(yaw) * c[0] - np.sin(yaw) * c[1], np.sin(yaw) * c[0] + np.cos(yaw) * c[1]])
        if np.hypot(*direction) == 0:
            continue
        unit = direction / np.hypot(*direction)
        move = np.mean(np.asarray(after["feet"])[:, :2], 0) - np.mean(np.asarray(before["feet"])[:, :2], 0)
        along += float(unit @ move)
        across += float(unit[0] * move[1] - unit[1] * move[0])
    return along, across


@pytest.mark.slow
@pytest.mark.parametrize("terrain", sweep.EXPORT_TERRAINS)
def test_a_recorded_drive_exported_to_a_sweep_takes_its_footsteps(exports, recorded, terrain):
    """`ijoy drive --replay --export-sweep`: the sweep's scenario 0 is the drive (its map, robot, start and
    commands), the rollout of it takes the drive's footholds bit for bit, and the engine's table of it is that
    rollout's summary and the drive's own progress recomputed from its recorded feet."""
    info, cfg, table = exports[terrain]
    path, result = recorded
    assert info == {"sweep": info["sweep"], "recording": str(path), "decisions": 5, "terrain": terrain,
                    "walker": "perfect", "invalid_decisions": []}
    assert cfg.command_file.kind == "recording" and cfg.num_steps == 5 and cfg.walker == "perfect"
    assert cfg.first_swing == 1 and cfg.method == "exhaustive"
    assert (cfg.terrain_recording is not None) == (terrain == "recording")
    assert cfg.family == (None if terrain == "recording" else "obstacles") and cfg.shape == SHAPE
    assert "command.vx" not in table.columns and len(table) == len(MARGINS)
    sc = sweep.scenario(cfg, 0)
    np.testing.assert_array_equal(sc.command, np.asarray([d["command"] for d in result.decisions], np.float32))
    traj = ij.rollout(sc.terrain, sc.robot, sc.start, sc.command, cfg.num_steps, first_swing=sc.first_swing)
    np.testing.assert_array_equal(np.asarray(traj.footholds), result.footsteps())
    np.testing.assert_array_equal(np.asarray(traj.feet), np.asarray(result.states[-1]["feet"], np.float32))
    row = table[table["robot.margin"] == MARGINS[0]].iloc[0]
    for k, v in traj.summary().items():
        if np.issubdtype(np.asarray(v).dtype, np.floating):
            assert row[k] == pytest.approx(float(v), abs=FLOAT_TOL), k
        else:
            assert row[k] == v, k
    along, across = _along_across(result)
    assert row["steps_taken"] == sum(s["go"] for s in result.states) == 5 and not row["stopped"]
    assert row["distance_along"] == pytest.approx(along, abs=FLOAT_TOL) and along > 0.5
    assert row["distance_across"] == pytest.approx(across, abs=FLOAT_TOL)
    other = table[table["robot.margin"] == MARGINS[1]].iloc[0]
    assert other["steps_taken"] > 0  # the same commands, another robot


@pytest.mark.slow
def test_the_drives_trace_file_as_a_sweeps_commands_is_the_same_sweep(exports, recorded, trace, tmp_path):
    """The drive's own trace file as the sweep's command file gives the recorded commands bit for bit
    (ijoy_jax.stick.scripted_commands: the loop's schedule, not a drive), so the same table: a scripted stick
    is the drive it scripts."""
    _, _, table = exports["recording"]
    path, result = recorded
    commands = np.asarray([d["command"] for d in result.decisions], np.float64)
    scripted = stick.scripted_commands(live.read_trace(trace), ROBOT)
    assert scripted.dtype == np.float64
    np.testing.assert_array_equal(scripted, commands)
    text = textwrap.dedent(f"""\
        [sweep]
        num_steps = 5
        method = "exhaustive"
        scenarios_per_cell = 1
        [terrain]
        recording = {json.dumps(str(path))}
        [command]
        file = {json.dumps(str(trace))}
        [grid]
        "robot.margin" = {list(MARGINS)}
        """)
    (tmp_path / "trace.toml").write_text(text)
    by_trace = sweep.load_config(tmp_path / "trace.toml")
    assert by_trace.command_file.kind == "trace" and by_trace.num_steps == 5 and by_trace.first_swing == 1
    np.testing.assert_array_equal(by_trace.command_steps, commands.astype(np.float32))
    sweep.run(by_trace, tmp_path / "results", chunk_size=len(MARGINS), progress=False)
    got = sweep.load(tmp_path / "results")
    assert list(got.columns) == list(table.columns)
    for column in table.columns:
        np.testing.assert_array_equal(got[column].to_numpy(), table[column].to_numpy(), err_msg=column)


# ------------------------------------------------------------------------------------------- the command line


@pytest.mark.parametrize("args, match", [
    (["--script", "/nonexistent/trace.csv"], "trace file '/nonexistent/trace.csv' does not exist"),
    (["--script", "TRACE", "--terrain", "mountains"], "unknown terrain family 'mountains'"),
    (["--script", "BAD"], "bad.csv:2: expected 4 comma-separated values"),
    (["--replay", "/nonexistent.mcap"], "recording '/nonexistent.mcap' does not exist"),
    (["--script", "TRACE", "--shape", "12by5"], "--shape must be NXxNY"),
    (["--script", "TRACE", "--server", "localhost"], "server must be HOST:PORT"),
    (["--script", "TRACE", "--server", "127.0.0.1:1"], "no footstep server at 127.0.0.1:1: nothing accepted a "
                                                       "connection within 5 s"),
    (["--script", "TRACE", "--export-sweep", "out.toml"], "--export-sweep needs --replay FILE"),
    (["--replay", "/nonexistent.mcap", "--export-sweep", "out.toml"], "recording '/nonexistent.mcap' does not exist"),
    (["--script", "TRACE", "--model", "G1"], "argument --model: invalid choice: 'G1' (choose from 'biped', 'g1')"),
    (["--script", "TRACE", "--model", "g1", "--scenario", "sweeps/margin_physics.toml:0"],
     "model 'g1' with a sweep scenario: its robot is the sweep's, HRP-2"),
])
def test_bad_input_is_one_line(args, match, trace, tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,forward,left,turn\n0,1,0\n")
    args = [str(trace) if a == "TRACE" else str(bad) if a == "BAD" else a for a in args]
    rc = cli.main(["drive", *args, "--headless", "--ff", "off"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.startswith("ijoy: error: ") and len(err.splitlines()) == 1, err
    assert match in err


# ------------------------------------------------------------------------------------------- force feedback

_C = r"""
#include <linux/input.h>
#include <stdio.h>
#include <string.h>
static void dump(struct ff_effect *e) { fwrite(e, sizeof *e, 1, stdout); }
int main(void) {
  struct ff_effect e;
  printf("%d %d %d %d %d %zu\n", FF_CONSTANT, FF_SPRING, FF_RUMBLE, EV_FF, FF_GAIN, sizeof(struct ff_effect));
  memset(&e, 0, sizeof e); e.type = FF_CONSTANT; e.id = -1; e.direction = DIRECTION;
  e.u.constant.level = LEVEL; dump(&e);
  memset(&e, 0, sizeof e); e.type = FF_SPRING; e.id = 3;
  CONDITIONS dump(&e);
  memset(&e, 0, sizeof e); e.type = FF_RUMBLE; e.id = -1;
  e.u.rumble.strong_magnitude = STRONG; e.u.rumble.weak_magnitude = WEAK; dump(&e);
  return 0;
}
"""


@pytest.mark.slow
def test_effects_are_the_kernels_structures(tmp_path):
    """A cue force and ALDURO's centring spring encoded as evdev ff structures are, byte for byte, the
    struct ff_effect that linux/input.h lays out for the same fields (compiled with the system's C compiler),
    and evdev's codes are the header's."""
    import shutil

    from evdev import ecodes

    from ijoy_jax import haptics

    if shutil.which("cc") is None or not __import__("os").path.exists("/usr/include/linux/input.h"):
        pytest.fail("needs a C compiler and linux/input.h: apt-get install -y gcc linux-libc-dev (.ci/run does)")
    cfg = haptics.default_joystick_config()
    force = np.array([-0.6, 0.3, 0.1])  # the cue pushes back and to the left
    const = forcefeedback.cue_constant(force, cfg)
    # independently: 5 N max force, projection onto x/y: (-3, 1.5) N, |f| = 3.354 N -> level 0x7FFF * 3.354 / 5
    f = np.array([-3.0, 1.5])
    assert const["u"]["constant"]["level"] == int(round(np.hypot(*f) / 5.0 * 0x7FFF))
    theta = (-np.arctan2(f[1], f[0])) % (2 * np.pi)  # the kernel's direction convention (haptics.linux_constant)
    assert const["direction"] == int(round(theta / (2 * np.pi) * 0x10000)) % 0x10000
    spring = haptics.linux_spring(cfg.centring, 5.0, 0.03)
    rum = forcefeedback.rumble(0.5)
    conds = " ".join(
        f"e.u.condition[{i}].right_saturation = {c['right_saturation']}; e.u.condition[{i}].left_saturation = "
        f"{c['left_saturation']}; e.u.condition[{i}].right_coeff = {c['right_coeff']}; e.u.condition[{i}].left_coeff"
        f" = {c['left_coeff']}; e.u.condition[{i}].deadband = {c['deadband']}; e.u.condition[{i}].center = "
        f"{c['center']};" for i, c in enumerate(spring["u"]["condition"]))
    src = tmp_path / "ff.c"
    code = _C
    for name, value in (("DIRECTION", const["direction"]), ("LEVEL", const["u"]["constant"]["level"]),
                        ("CONDITIONS", conds), ("STRONG", rum["u"]["rumble"]["strong_magnitude"]),
                        ("WEAK", rum["u"]["rumble"]["weak_magnitude"])):
        code = code.replace(name, str(value))
    src.write_text(code)
    exe = tmp_path / "ff"
    subprocess.run(["cc", "-o", str(exe), str(src)], check=True)
    raw = subprocess.run([str(exe)], capture_output=True, check=True).stdout
    header, _, body = raw.partition(b"\n")
    codes = [int(v) for v in header.split()]
    assert codes[:5] == [ecodes.FF_CONSTANT, ecodes.FF_SPRING, ecodes.FF_RUMBLE, ecodes.EV_FF, ecodes.FF_GAIN]
    size = codes[5]
    ours = [forcefeedback.effect(const), forcefeedback.effect(spring, effect_id=3), forcefeedback.effect(rum)]
    assert all(len(bytes(e)) == size for e in ours)
    kernel = [body[i * size:(i + 1) * size] for i in range(3)]
    for e, k in zip(ours, kernel, strict=True):
        assert bytes(e) == k
    assert spring["u"]["condition"][0]["right_coeff"] > 0  # a restoring spring on both axes
    assert ours[1].u.ff_condition_effect[1].left_coeff == spring["u"]["condition"][1]["left_coeff"]


def test_no_device_falls_back_with_a_message(tmp_path):
    out = forcefeedback.open_device()
    assert isinstance(out, forcefeedback.NoFeedback) and out.description.startswith("off (")
    out.update(np.array([0.5, 0.0, 0.0]))  # plays nothing, raises nothing
    missing = forcefeedback.open_device(str(tmp_path / "event99"))
    assert isinstance(missing, forcefeedback.NoFeedback) and "cannot open" in missing.description

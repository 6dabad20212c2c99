"""Hostile values at the public boundaries that no compiled program should ever see: each is refused in one
line naming the argument and its bound, before anything is traced, allocated or driven.

- a concrete heading beyond ``geometry.MAX_HEADING``, where float64 no longer says which way it points (the
  boundary's reduction by whole turns would return a step turned anywhere);
- a Python integer beyond float64 (``10**400``) in a pose, a command or a robot's number (an OverflowError);
- a lookahead horizon beyond ``limits.MAX_HORIZON`` (one search level per step in the program: the library
  accepted what the sweep file refused);
- a drive of 0 decisions (it compiled everything, drove nothing and exited 0) or beyond ``MAX_NUM_STEPS``;
- a folder named where a file is expected, said as such rather than "does not exist".

Nothing here compiles a selector program: every refusal happens before one would be traced.
"""

import contextlib
import io
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax import geometry, limits, live
from ijoy_jax.apps import cli
from ijoy_jax.server import Service, schema
from ijoy_jax.sweep import config as sweep_config

RES = 0.02
SHAPE = (40, 40)
ROBOT = ij.robots.hrp2(margin=0.02, density=0.25)  # 19 actions: nothing here reaches the selector
FLAT = ij.terrain.from_arrays(np.zeros(SHAPE, np.float32), np.ones(SHAPE, bool), RES)
STANCE = [0.4, 0.45, 0.0]
FEET = [[0.4, 0.55, 0.0], [0.4, 0.36, 0.0]]

# Finite headings float64 cannot place (and their negatives): just above the bound, 1e17, up to the largest.
FAR_HEADINGS = st.floats(min_value=geometry.MAX_HEADING * (1 + 1e-12), max_value=1.7e308).flatmap(
    lambda x: st.sampled_from([x, -x])
)
# Python ints no float64 holds.
HUGE_INTS = st.integers(min_value=2**1024, max_value=10**600).flatmap(lambda n: st.sampled_from([n, -n]))


def _boundaries(pose, command=(0.1, 0.0, 0.0)):
    """Every public boundary that takes a pose, called with ``pose`` as the stance (a start's feet)."""
    return {
        "select_step": lambda: ij.select_step(FLAT, ROBOT, pose, -1, list(command)),
        "select_step swing_from": lambda: ij.select_step(FLAT, ROBOT, STANCE, -1, list(command), swing_from=pose),
        "foot_cost_terms": lambda: ij.foot_cost_terms(FLAT, ROBOT, pose, -1, [STANCE]),
        "rollout": lambda: ij.rollout(FLAT, ROBOT, [list(pose), FEET[1]], list(command), 2),
        "feasible_commands": lambda: ij.cue.feasible_commands(FLAT, ROBOT, pose, -1, FEET[1]),
    }


@settings(max_examples=25, deadline=None, derandomize=True)
@given(FAR_HEADINGS)
def test_a_heading_float64_cannot_place_is_refused_at_every_boundary(yaw):
    """2 pi 1e7 is reduced by whole turns (tests/test_hostile_queries.py); 1e17 or 1e300 has no direction left
    in float64 (its spacing at 1e17 is 16 rad): the reduction gave 0, a valid step turned the wrong way."""
    for call in _boundaries([0.4, 0.45, yaw]).values():
        with pytest.raises(ValueError, match="MAX_HEADING"):
            call()


def test_headings_up_to_the_bound_reduce_within_float32s_rounding():
    """The bound's reason: up to it the float64 reduction is within 1e-4 rad of the exact direction (checked
    here against the exact residue of the float64 value, with pi to 60 digits)."""
    from fractions import Fraction

    pi = Fraction("3.141592653589793238462643383279502884197169399375105820974944592")
    rng = np.random.default_rng(0)
    yaws = np.concatenate([rng.uniform(geometry.MAX_HEADING / 2, geometry.MAX_HEADING, 200), [geometry.MAX_HEADING]])
    for yaw in np.concatenate([yaws, -yaws]):
        geometry.check_headings("stance", [0.0, 0.0, yaw])  # within: no error
        got = Fraction(float(geometry.reduce_turns(np.array([0.0, 0.0, yaw]))[2]))
        exact = Fraction(float(yaw))
        exact -= 2 * pi * round(exact / (2 * pi))
        assert abs(float((got - exact + pi) % (2 * pi) - pi)) < 1e-4, yaw
    for bad in (math.nan, math.inf, -math.inf):  # left to the finite checks, which name them
        geometry.check_headings("stance", [0.0, 0.0, bad])


@pytest.mark.parametrize("yaw", [1e17, -1e300, 2.0**40])
def test_the_server_refuses_such_a_heading_as_invalid_value(yaw):
    """The server reduces a far heading as select_step does, so it refuses what select_step refuses, before it
    looks for a map (no terrain is needed to be told)."""
    svc = Service(ROBOT)
    for field in ("stance", "swing_from"):
        header = {
            "version": 1,
            "type": "step",
            "stance": [1.0, 0.8, 0.0],
            "stance_side": -1,
            "command": [0.2, 0.0, 0.0],
            field: [1.0, 0.8, yaw],
        }
        reply = schema.decode_reply(svc.handle(schema.encode(header))).header
        assert not reply["ok"] and reply["code"] == "invalid_value", reply
        assert f"{field} heading" in reply["message"] and "MAX_HEADING" in reply["message"], reply


@settings(max_examples=20, deadline=None, derandomize=True)
@given(HUGE_INTS, st.integers(0, 2))
def test_an_integer_beyond_float64_in_a_pose_or_command_is_a_value_error(n, i):
    """``jnp.asarray([10**400, ...])`` raises OverflowError: the boundary names the argument instead."""
    pose = list(STANCE)
    pose[i] = n
    for call in _boundaries(pose).values():
        with pytest.raises(ValueError, match="beyond float64"):
            call()
    command = [0.1, 0.0, 0.0]
    command[i] = n
    with pytest.raises(ValueError, match="command must be finite numbers"):
        ij.select_step(FLAT, ROBOT, STANCE, -1, command)


@settings(max_examples=20, deadline=None, derandomize=True)
@given(HUGE_INTS, st.sampled_from(["margin", "w", "step_time", "foot_length", "rotation_weight", "density", "reach"]))
def test_an_integer_beyond_float64_in_a_robots_number_is_named(n, name):
    with pytest.raises(ValueError, match=name):
        ij.robots.hrp2(**{name: n})


@settings(max_examples=20, deadline=None, derandomize=True)
@given(st.one_of(st.integers(limits.MAX_HORIZON + 1, 10**30), st.just(10**400)))
def test_a_horizon_beyond_the_budget_is_refused_by_the_library_as_by_the_sweep_file(horizon):
    """A horizon of a million traced a million search levels; the sweep file refused it, the library did not."""
    with pytest.raises(ValueError, match="MAX_HORIZON"):
        ij.SelectOptions(method="lookahead", horizon=horizon)
    assert sweep_config._MAX_HORIZON == limits.MAX_HORIZON  # one bound for both


def test_the_largest_horizon_is_accepted():
    assert ij.SelectOptions(method="lookahead", horizon=limits.MAX_HORIZON).horizon == limits.MAX_HORIZON


@pytest.mark.parametrize(
    "num_steps",
    [0, -1, 0.5, math.nan, math.inf, limits.MAX_NUM_STEPS + 1, 10**400, True],
    ids=["0", "-1", "0.5", "nan", "inf", "max+1", "10**400", "True"],
)
def test_a_drive_of_no_decision_or_beyond_the_budget_is_refused_before_anything_is_built(num_steps):
    """``ijoy drive --steps 0`` compiled the drive's programs for 16 s, drove nothing and exited 0, as a NaN
    duration did; the drive's own check comes before the terrain is indexed or a body is built (None here)."""
    with pytest.raises(ValueError, match="num_steps must be a whole number in \\[1, ijoy_jax.limits.MAX_NUM_STEPS"):
        live.drive(FLAT, ROBOT, None, None, None, num_steps=num_steps)


def _cli(*args: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = cli.main(list(args))
        except SystemExit as e:  # argparse's errors
            rc = e.code
    return rc, out.getvalue(), err.getvalue()


@pytest.mark.parametrize("flag, what", [("--replay", "recording"), ("--image", "height map image")])
def test_a_folder_where_a_drive_file_belongs_is_said_to_be_a_folder(tmp_path, flag, what):
    """It said "does not exist" of a folder that does."""
    rc, out, err = _cli("drive", flag, str(tmp_path), "--headless")
    assert rc == 2 and out == "", (out, err)
    assert err.strip().splitlines()[-1] == f"ijoy: error: {what} {str(tmp_path)!r} is a folder, not a file", err


def test_the_views_socket_survives_axes_beyond_float64_and_keeps_the_connection():
    """A page's ``{"type": "axes", "axes": [<400 digits>, 0, 0]}`` raised OverflowError in the socket's handler:
    a traceback in the log and a dead handler (the next, valid, stick message was never read). A real view on
    loopback: the message is ignored, the connection kept, the next message applied."""
    import asyncio

    import aiohttp

    from ijoy_jax.live.view import ViewServer

    hostile = [
        '{"type": "axes", "axes": [1' + "0" * 400 + ", 0, 0]}",
        '{"type": "axes", "axes": [0, -1' + "0" * 330 + ", 0]}",
    ]

    async def talk(port):
        async with aiohttp.ClientSession() as s, s.ws_connect(f"http://127.0.0.1:{port}/ws") as ws:
            for text in hostile:
                await ws.send_str(text)
            await ws.send_str('{"type": "axes", "axes": [0.25, 0, 0]}')
            for _ in range(100):
                await asyncio.sleep(0.02)
                if view.axes.updates:
                    break
            return ws.closed

    with ViewServer("127.0.0.1", 0) as view:
        closed = asyncio.run(talk(view.port))
    assert not closed
    assert view.axes.updates == 1 and view.axes.axes().tolist() == [0.25, 0.0, 0.0]
    with pytest.raises(ValueError, match="beyond float64"):
        live.inputs.SharedAxes().set([10**400, 0, 0])


@pytest.mark.parametrize("duration, decide_at", [(1e-300, 0.0), (1e-10, 0.0), (0.1, 0.5), (0.4, 0.5)])
def test_a_drive_that_ends_before_its_first_decision_is_refused(duration, decide_at):
    """``ijoy drive --duration 1e-300`` (inside (0, 86400] s) compiled the drive's programs, decided nothing and
    exited 0, as ``--duration nan`` once did; so did 0.1 s with ``--decide-at 0.5`` (the first decision 0.4 s
    in). Refused before the terrain is indexed (source and decider are never reached: None here)."""
    body = live.PerfectBody(ROBOT, FEET)
    with pytest.raises(ValueError, match="ends before the first decision"):
        live.drive(FLAT, ROBOT, body, None, None, duration=duration, decide_at=decide_at)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(st.floats(min_value=820.0, max_value=1e300))
def test_a_map_wider_than_float32s_millimetres_is_told_to_shrink_not_to_shift(resolution):
    """``from_arrays(..., resolution=1e300)`` is accepted (a cell may be large); the boundary then said "shift your
    world frame ... rounds coordinates by up to nan m; subtract the map's origin [0.0, 0.0]": advice that cannot
    help a map that is itself too wide. It names the map's size and the way out."""
    t = ij.terrain.from_arrays(np.zeros((10, 10), np.float32), np.ones((10, 10), bool), resolution)
    with pytest.raises(ValueError) as e:
        ij.foot_cost_terms(t, ROBOT, [1.0, 1.0, 0.0], -1, [[1.0, 1.2, 0.0]])
    message = str(e.value)
    assert message.startswith("the map is ") and "use a finer resolution or fewer cells" in message, message
    assert "nan" not in message and "shift" not in message, message


def test_drive_steps_out_of_range_name_the_flag_before_the_terrain_is_read():
    """``ijoy drive --steps 0`` was refused by the drive, after the terrain, its tables and the body were built,
    with the library's name ``num_steps``; the CLI names ``--steps``. The malformed ``--shape`` is read after it:
    the refusal comes first (and the library keeps its own name, tested above)."""
    for steps in ("0", "-1", str(limits.MAX_NUM_STEPS + 1)):
        rc, out, err = _cli("drive", "--headless", "--steps", steps, "--shape", "not-a-shape")
        assert rc == 2 and out == "", (out, err)
        assert err.strip().splitlines()[-1] == (
            f"ijoy: error: --steps must be a whole number in [1, ijoy_jax.limits.MAX_NUM_STEPS = "
            f"{limits.MAX_NUM_STEPS}] (decisions to make), got {steps}"
        ), err


@pytest.mark.parametrize("case", ["--duration", "trace"])
def test_a_cli_drive_that_ends_before_its_first_decision_names_the_flag_or_the_trace(tmp_path, case):
    """The first decision's time needs the body (its ticks), so the drive refused ``--duration 1e-10`` only once
    the body existed, naming ``duration``; the CLI checks as the body is built (before the decider and the
    warm-up's compiles) and names ``--duration``, or the trace whose last time ends before it."""
    trace = tmp_path / "short.csv"
    trace.write_text("t,forward,left,turn\n0,0.5,0,0\n0.1,0.5,0,0\n")
    extra = ("--duration", "1e-10") if case == "--duration" else ("--decide-at", "0.5")
    rc, out, err = _cli("drive", "--headless", "--script", str(trace), "--shape", "40x40", *extra)
    assert rc == 2 and out == "", (out, err)
    named = "--duration 1e-10 s" if case == "--duration" else f"the trace's last time ({trace}) 0.1 s"
    assert err.strip().splitlines()[-1].startswith(f"ijoy: error: {named} ends before the first decision"), err


@pytest.mark.parametrize(
    "start, message",
    [
        ("1,1,1e300", "--start heading 1e+300 rad is beyond geometry.MAX_HEADING = 2**39 rad"),
        ("1e300,1,0", "--start x 1e+300 m is beyond ijoy_jax.footcost.MAX_COORDINATE = 8192 m, where no map reaches"),
        ("1,-1e39,0", "--start y -1e+39 m is beyond ijoy_jax.footcost.MAX_COORDINATE = 8192 m, where no map reaches"),
        ("nan,1,0", "--start must be finite numbers X,Y,THETA, got 'nan,1,0'"),
    ],
)
def test_a_start_the_drive_cannot_place_is_refused_naming_start_and_its_bound(tmp_path, start, message):
    """``--start 1,1,1e300`` said "start must be finite (2, 3) feet" (float32 made the heading inf) once the
    terrain, its tables and the body were built; the CLI applies the library's pose rules to ``--start`` (a
    heading within ``geometry.MAX_HEADING``, a position where a map may lie) before the terrain is read: the
    missing image named after it is never looked at."""
    rc, out, err = _cli("drive", "--headless", "--image", str(tmp_path / "none.png"), "--start", start)
    assert rc == 2 and out == "", (out, err)
    assert err.strip().splitlines()[-1].startswith(f"ijoy: error: {message}"), err


def test_a_far_start_heading_is_reduced_by_whole_turns_as_a_pose_argument_is():
    """float32 rounds ``2 pi 1e7 + 0.5`` rad by up to 0.5 rad: the start would face anywhere."""
    from ijoy_jax.apps import drive_cli

    x, y, theta = drive_cli._start(f"1.5,2,{2 * math.pi * 1e7 + 0.5!r}")
    assert (x, y) == (1.5, 2.0) and abs(theta - 0.5) < 1e-6, theta
    assert drive_cli._start("1,2,3") == (1.0, 2.0, 3.0)  # within MAX_ANGLE: as given


SWEEP_TEXT = '[grid]\n"robot.w" = [0.5, 1.0]\n[sweep]\nscenarios_per_cell = 2\n'


@pytest.mark.parametrize("name", ["a" * 101, "a" * 300, "é" * 51, "\U00020000" * 26])
def test_a_sweep_name_no_folder_can_hold_is_refused_before_any_compute(name):
    """A 300-character ``sweep.name`` passed and failed only at ``mkdir results/<name>`` (255 bytes per name),
    after the sweep had started; so would 64 letters of 4 UTF-8 bytes each. At most 100 UTF-8 bytes."""
    with pytest.raises(sweep_config.SweepConfigError, match=r"sweep\.name: must be at most 100 characters \(UTF-8"):
        sweep_config.parse_config(SWEEP_TEXT + f'name = "{name}"\n')


def test_a_sweep_files_long_stem_is_refused_as_its_name(tmp_path):
    path = tmp_path / ("s" * 120 + ".toml")
    path.write_text(SWEEP_TEXT)
    stem_rule = r"sweep\.name \(the file's stem, when not given\): must be at most 100"
    with pytest.raises(sweep_config.SweepConfigError, match=stem_rule):
        sweep_config.load_config(path)
    assert sweep_config.parse_config(SWEEP_TEXT + f'name = "{"a" * 100}"\n').name == "a" * 100  # the bound itself


TINY_DENSITIES = st.one_of(
    st.floats(min_value=5e-324, max_value=ij.robots.MIN_DENSITY, exclude_max=True), st.just(1e-300)
)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(TINY_DENSITIES)
def test_a_density_below_the_smallest_action_set_is_refused_naming_the_range(density):
    """``hrp2(density=1e-300)`` quietly gave the 10 actions of density 0.1 (every count clamped to its smallest
    odd lattice): refused, naming density and its range, before a lattice is built; the sweep file says the same."""
    match = r"density must be in \[ijoy_jax.robots.MIN_DENSITY, ijoy_jax.limits.MAX_DENSITY\] = \[0.1, 2.0\]"
    for build in (ij.robots.hrp2, ij.robots.g1, ij.robots.hrp2_actions, ij.robots.g1_actions):
        with pytest.raises(ValueError, match=match):
            build(density=density)
    with pytest.raises(sweep_config.SweepConfigError, match=r"robot\.density: must be in \[0\.1, 2\.0\]"):
        sweep_config.parse_config(f"[robot]\ndensity = {density!r}\n")


def test_every_documented_density_still_builds():
    """The range's ends and the densities the tests, sweeps/*.toml and docs use."""
    assert ij.robots.hrp2_actions(ij.robots.MIN_DENSITY).shape == (10, 3) == ij.robots.g1_actions(0.1).shape
    sizes = {0.1: 10, 0.25: 19, 0.4: 52, 0.5: 117, 0.75: 202, 1.0: 496, 1.5: 1279, 2.0: 3307}
    for density, size in sizes.items():
        assert ij.robots.hrp2_actions(density).shape == (size, 3), density

"""The footstep server's bounded cache of compiled programs (ijoy_jax.server.service.ProgramCache).

Every map kind (shape, resolution, 2D or 2.5D) runs programs of its own; a client that sends a new shape for
every map must not grow the server without end. With room for two kinds and three in turn: the cache never
holds more than two, drops the least recently used with its compiled code (JAX's live executables do not
grow), answers a dropped kind again, bit for bit as before, after compiling it again, and compiles nothing
for a kind it holds. ``max_programs`` and ``ijoy serve --max-programs`` refuse what is not a positive integer
in one line. Maps are tiny 2D ones (20-odd cells a side at 5 cm) and the action set small, so each kind
compiles in about a second; one real
``ijoy serve`` process checks that the option reaches the server.
"""

import contextlib
import gc
import io
import weakref

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax.apps import cli
from ijoy_jax.server import Service, schema, serve_subprocess
from ijoy_jax.server.service import DEFAULT_MAX_PROGRAMS, ProgramCache, compile_count, program_key

ROBOT = ij.robots.hrp2(margin=0.02, density=0.25)  # 19 actions: the cache's behaviour is not the selector's size
RES = 0.05  # m
SHAPES = [(20, 20), (24, 20), (20, 24)]  # cells: three kinds (2D: the cheapest to compile), for a cache of two
STEP = {"version": 1, "type": "step", "stance": [0.5, 0.5, 0.0], "stance_side": -1, "command": [0.1, 0.0, 0.0]}
ANSWER = (
    "valid",
    "index",
    "pose",
    "foothold",
    "cost",
    "foot_cost",
    "target",
    "command_ok",
    "unsupported",
    "evaluated",
    "terms",
)  # a step reply's fields that say what was decided (not how long it took)


def _arrays(shape):
    rng = np.random.default_rng(shape[0] * 100 + shape[1])
    free = rng.random(shape) > 0.05
    return {"free": free}


def _ok(frames) -> dict:
    header = schema.decode_reply(frames).header
    assert header["ok"], header
    return header


def _use(service, shape) -> dict:
    """Set a map of ``shape`` (its own name) and decide one step on it: the step reply's answer."""
    name = f"{shape[0]}x{shape[1]}"
    _ok(
        service.handle(
            schema.encode({"version": 1, "type": "set_terrain", "resolution": RES, "map": name}, _arrays(shape))
        )
    )
    reply = _ok(service.handle(schema.encode({**STEP, "map": name})))
    return {k: reply[k] for k in ANSWER}


def _live_served_programs() -> int:
    """Compiled programs of any service's :class:`~ijoy_jax.server.service.Programs` alive in this process
    (after collecting the garbage)."""
    gc.collect()
    return sum(e.hlo_modules()[0].name.startswith("jit_served_") for e in jax.devices()[0].client.live_executables())


def _terrain(shape):
    arrays = _arrays(shape)
    return ij.terrain.from_arrays(None, arrays["free"], RES)


def _kind(shape):
    return program_key(_terrain(shape))


def _positive_int(text: str) -> bool:
    try:
        return int(text) > 0
    except ValueError:
        return False


@pytest.fixture(scope="module")
def churn():
    """A service with room for two kinds, used on A, B, C (A dropped), A again (B dropped), then C (held):
    what the cache held and compiled at each point."""
    seen = {"live_before": _live_served_programs()}
    service = Service(ROBOT, max_programs=2)
    a, b, c = SHAPES
    seen.update(answers={}, sizes=[], compiles={})
    seen["answers"][a] = _use(service, a)
    seen["sizes"].append(len(service.programs))
    dropped = weakref.ref(service.programs.get(_terrain(a)))  # A's programs (already the most recently used)
    seen["answers"][b] = _use(service, b)
    seen["sizes"].append(len(service.programs))
    seen["held_after_two"] = service.programs.keys()
    seen["live_after_two"] = _live_served_programs()
    seen["answers"][c] = _use(service, c)
    seen["sizes"].append(len(service.programs))
    seen["live_after_three"] = _live_served_programs()  # (collects the garbage first)
    seen["a_freed"] = dropped() is None
    c0 = compile_count()
    seen["a_again"] = _use(service, a)
    seen["compiles"]["a_again"] = compile_count() - c0
    seen["sizes"].append(len(service.programs))
    c0 = compile_count()
    seen["c_again"] = _use(service, c)
    seen["compiles"]["c_again"] = compile_count() - c0
    seen["held_at_end"] = service.programs.keys()
    seen["builds"], seen["evictions"] = service.programs.builds, service.programs.evictions
    return seen


def test_the_cache_never_holds_more_kinds_than_max_programs(churn):
    assert churn["sizes"] == [1, 2, 2, 2]
    assert churn["builds"] == 4 and churn["evictions"] == 2  # A, B, C, A again; A then B dropped
    a, b, c = (_kind(s) for s in SHAPES)
    assert churn["held_after_two"] == [a, b]
    assert churn["held_at_end"] == [a, c]  # C used last: the most recently used is last


def test_a_dropped_kind_frees_its_compiled_programs(churn):
    """The dropped entry is garbage, and JAX holds no more compiled programs with three kinds seen than with
    two (a module-level jitted function would hold one set per kind for the life of the process)."""
    assert churn["a_freed"]
    assert churn["live_after_two"] == churn["live_before"] + 4  # two kinds: each its index and its step decision
    assert churn["live_after_three"] == churn["live_after_two"]


def test_a_dropped_kind_is_compiled_again_and_answers_as_before(churn):
    assert churn["compiles"]["a_again"] > 0
    assert churn["a_again"] == churn["answers"][SHAPES[0]]


def test_a_held_kind_is_not_compiled_again(churn):
    assert churn["compiles"]["c_again"] == 0
    assert churn["c_again"] == churn["answers"][SHAPES[2]]


def test_the_default_keeps_every_map_a_default_server_holds():
    assert Service(ROBOT).programs.max_programs == DEFAULT_MAX_PROGRAMS >= 2 * schema.Limits().max_maps


NOT_POSITIVE_INTEGERS = st.one_of(
    st.integers(max_value=0),
    st.floats(allow_nan=True),
    st.booleans(),
    st.none(),
    st.text(max_size=8),
    st.just(2.0),
    st.just(np.float32(3)),
)


@settings(derandomize=True, deadline=None, max_examples=40)
@given(NOT_POSITIVE_INTEGERS)
def test_max_programs_refuses_what_is_not_a_positive_integer(value):
    with pytest.raises(ValueError, match="max_programs must be a positive integer") as e:
        ProgramCache(value)
    assert len(str(e.value).splitlines()) == 1


def test_the_service_refuses_a_bad_max_programs():
    for value in (0, -1, 1.5):
        with pytest.raises(ValueError, match=r"^max_programs must be a positive integer .*got "):
            Service(ROBOT, max_programs=value)


def _cli(*args: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = cli.main(["serve", "--port", "0", *args])
        except SystemExit as e:  # argparse's errors and --help
            rc = e.code
    return rc, out.getvalue(), err.getvalue()


@settings(derandomize=True, deadline=None, max_examples=40)
@given(
    st.one_of(st.integers(max_value=0).map(str), st.floats().map(repr), st.text(max_size=8)).filter(
        lambda t: not _positive_int(t)
    )
)
def test_the_cli_refuses_a_bad_max_programs_in_one_line(text):
    rc, out, err = _cli("--warm-up", "none", f"--max-programs={text}")
    assert rc == 2 and out == "", (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ijoy: error: --max-programs must be a positive integer"), err


def test_the_cli_refuses_more_warm_up_kinds_than_it_keeps():
    rc, out, err = _cli("--max-programs", "3", "--warm-up", "20x20@0.05", "--warm-up", "24x20@0.05")
    assert rc == 2 and out == ""
    assert err.strip().splitlines() == [
        "ijoy: error: --warm-up: 2 map shapes are 4 map kinds (2D and 2.5D), above "
        "--max-programs 3: the first would be dropped before the server listens; "
        "warm up fewer shapes or raise --max-programs"
    ], err


def test_serve_help_says_how_map_shapes_are_meant_to_be_used():
    rc, out, _ = _cli("--help")
    text = " ".join(out.split())
    assert rc == 0 and "--max-programs" in text
    assert "Use a few fixed map shapes per deployment and list them in --warm-up" in text


def test_a_real_server_keeps_max_programs_kinds():
    """ijoy serve --max-programs 1: a second kind drops the first (a log line says so), and a request on the
    kind it holds compiles nothing."""
    with serve_subprocess("--warm-up", "none", "--max-programs", "1") as srv, srv.client(timeout=600) as c:
        for shape in SHAPES[:2]:
            c.set_terrain(_terrain(shape))
            c.step(STEP["stance"], -1, STEP["command"])
        compiles = c.info()["stats"]["compiles"]
        c.set_terrain(_terrain(SHAPES[1]))
        c.step(STEP["stance"], -1, STEP["command"])
        assert c.info()["stats"]["compiles"] == compiles
        output = list(srv.output)
    dropped = [line for line in output if "dropped the compiled programs for" in line]
    assert dropped == [
        "ijoy serve: dropped the compiled programs for 20x20 maps at 0.05 m (2D), the least recently used kind "
        "(max_programs = 1): a request on such a map compiles them again"
    ], output

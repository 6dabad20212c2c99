"""Progress lines while a program compiles (ijoy_jax.progress), and the commands that show them.

A compile is slowed down on purpose (``jax.stages.Lowered.compile`` made to sleep first) or stood in for by a
sleep in the ``with`` body, and the thresholds are lowered, so every check here costs a second or less and no
real program compiles for long. The slow tier runs the MJX walk with ``progress=True``, through the library
and through ``ijoy sim render``.
"""

import io
import json
import re
import signal
import threading
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ijoy_jax import progress
from ijoy_jax.progress import THREAD_NAME, compile_and_call, compiling

SLOW_COMPILE_S = 1.2  # s a slowed compile sleeps before compiling: several lines at EVERY_S
SHOW_AFTER_S = 0.05  # s, the lowered threshold of the tests that expect lines
EVERY_S = 0.3  # s between two lines in those tests


@jax.jit
def _sine(x):
    return jnp.sin(x) * 2.0


def _scaled(x, *, n):
    return jnp.sin(x) * n + jnp.cos(x) ** 2


_scaled_jit = jax.jit(_scaled, static_argnames="n")


class _Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def _progress_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == THREAD_NAME]


@pytest.fixture
def quick_lines(monkeypatch):
    """Lines after SHOW_AFTER_S, then every EVERY_S (the defaults the library and commands use, lowered)."""
    monkeypatch.setattr(progress, "SHOW_AFTER_S", SHOW_AFTER_S)
    monkeypatch.setattr(progress, "LINE_EVERY_S", EVERY_S)
    monkeypatch.setattr(progress, "TTY_EVERY_S", EVERY_S)


@pytest.fixture
def slow_compile(monkeypatch):
    """Every ahead-of-time compile sleeps SLOW_COMPILE_S first (the program compiled is the same)."""
    compile_ = jax.stages.Lowered.compile

    def slowed(self, *args, **kwargs):
        time.sleep(SLOW_COMPILE_S)
        return compile_(self, *args, **kwargs)

    monkeypatch.setattr(jax.stages.Lowered, "compile", slowed)


def test_a_long_compile_says_what_compiles_and_the_seconds_then_that_it_compiled(quick_lines, slow_compile, capsys):
    x = jnp.linspace(-3.0, 3.0, 7)
    y = compile_and_call(_scaled_jit, x, what="a slowed sine", n=3)
    out, err = capsys.readouterr()
    assert out == ""
    lines = err.splitlines()
    *ticks, last = lines
    assert len(ticks) >= 2, err  # the first after SHOW_AFTER_S, then one every EVERY_S
    seconds = [int(re.fullmatch(r"\[ijoy\] compiling a slowed sine: (\d+) s", t).group(1)) for t in ticks]
    assert seconds == sorted(seconds) and seconds[-1] >= 1, err  # the elapsed seconds, counting up
    took = float(re.fullmatch(r"\[ijoy\] compiled a slowed sine in (\d+\.\d) s", last).group(1))
    assert took >= SLOW_COMPILE_S - 0.05
    assert not _progress_threads()
    np.testing.assert_array_equal(y, _scaled_jit(x, n=3))


def test_a_compile_under_the_threshold_writes_nothing(capsys):
    x = jnp.ones(5)
    _sine(x)  # compiled: the ahead-of-time compile below finds it, as it finds one in the persistent cache
    compile_and_call(_sine, x, what="a sine")
    with compiling("a quick program", show_after_s=5.0):
        time.sleep(0.2)
    assert capsys.readouterr() == ("", "")
    assert not _progress_threads()


def test_on_a_terminal_one_line_is_rewritten_in_place_and_the_final_line_stays():
    term = _Terminal()
    with compiling("a program", stream=term, show_after_s=SHOW_AFTER_S, every_s=0.1):
        time.sleep(0.5)
    text = term.getvalue()
    ticks, last = text[: text.rindex("\r") + 1], text[text.rindex("\r") + 1 :]
    assert "\n" not in ticks and ticks.count("\r") >= 2, repr(text)  # rewritten, never scrolled
    assert all(t.strip().startswith("[ijoy] compiling a program: ") for t in ticks.split("\r")[:-1]), repr(text)
    assert re.fullmatch(r"\[ijoy\] compiled a program in \d+\.\d s *\n", last), repr(text)
    term = _Terminal()
    with compiling("a program", stream=term, show_after_s=SHOW_AFTER_S, final=False, prefix="ijoy serve: "):
        time.sleep(0.3)
    text = term.getvalue()
    assert text.startswith("ijoy serve: compiling a program: 0 s") and "compiled" not in text, repr(text)
    assert text.endswith(" " * 78 + "\r"), repr(text)  # cleared, for the caller's own line


def test_the_thread_runs_only_while_compiling_and_never_keeps_the_process_alive():
    with compiling("a program", stream=io.StringIO()):
        (thread,) = _progress_threads()
        assert thread.daemon
    assert not thread.is_alive() and not _progress_threads()


@pytest.mark.parametrize("error", [RuntimeError("the compiler failed"), KeyboardInterrupt()])
def test_an_error_while_compiling_propagates_and_ends_the_lines(error, quick_lines, capsys):
    with pytest.raises(type(error)):
        with compiling("a program"):
            time.sleep(0.2)
            raise error
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == "[ijoy] compiling a program: 0 s", lines
    assert re.fullmatch(rf"\[ijoy\] compiling a program: stopped after 0\.\d s \({type(error).__name__}\)", lines[-1])
    assert not _progress_threads()


def test_an_error_in_the_compile_propagates_from_compile_and_call(monkeypatch, capsys):
    def failing(self, *args, **kwargs):
        raise RuntimeError("XLA ran out of memory")

    monkeypatch.setattr(jax.stages.Lowered, "compile", failing)
    with pytest.raises(RuntimeError, match="XLA ran out of memory"):
        compile_and_call(jax.jit(lambda x: x + 1), jnp.ones(2), what="a program")
    assert capsys.readouterr().err == ""  # quicker than the threshold
    assert not _progress_threads()


@settings(derandomize=True, deadline=None, max_examples=40)
@given(st.lists(st.floats(width=32), min_size=6, max_size=6), st.sampled_from([1, 3]))
def test_the_result_is_the_programs_own_bit_for_bit(values, n):
    x = jnp.asarray(values, jnp.float32)  # NaN, inf, huge and tiny values too
    got, want = compile_and_call(_scaled_jit, x, what="a program", n=n), _scaled_jit(x, n=n)
    assert np.asarray(got).tobytes() == np.asarray(want).tobytes()


class _NoCompile:
    """A jitted function that must not be compiled ahead of time here (it is inside a caller's trace)."""

    def __init__(self, fn):
        self.fn = fn

    def __call__(self, *args, **kwargs):
        return self.fn(*args, **kwargs)

    def lower(self, *args, **kwargs):
        raise AssertionError("compiled ahead of time inside a trace")


def test_inside_a_callers_jit_or_vmap_nothing_compiles_ahead():
    inner = _NoCompile(_scaled_jit)
    x = jnp.linspace(0.0, 1.0, 4)
    in_jit = jax.jit(lambda v: compile_and_call(inner, v, what="a program", n=2))(x)
    in_vmap = jax.vmap(lambda v: compile_and_call(inner, v, what="a program", n=2))(x)
    np.testing.assert_allclose(in_jit, _scaled(x, n=2), rtol=1e-6)
    np.testing.assert_allclose(in_vmap, _scaled(x, n=2), rtol=1e-6)


_BAD_SECONDS = st.one_of(
    st.floats(max_value=-1e-9),
    st.sampled_from([float("nan"), float("inf"), -float("inf"), True, "2", [1.0]]),
)


@settings(derandomize=True, deadline=None, max_examples=40)
@given(_BAD_SECONDS, st.sampled_from(["show_after_s", "every_s"]))
def test_bad_durations_are_refused_naming_the_parameter(value, name):
    with pytest.raises(ValueError, match=rf"^{name} must be a finite"):
        with compiling("a program", **{name: value}):
            pass
    assert not _progress_threads()


def test_lines_need_a_positive_interval_and_may_start_at_once():
    with pytest.raises(ValueError, match=r"^every_s must be a finite positive number of seconds, got 0.0$"):
        with compiling("a program", every_s=0.0):
            pass
    with compiling("a program", show_after_s=0.0, stream=io.StringIO()):
        pass


@pytest.mark.parametrize("what", ["", "   ", None, 3])
def test_what_must_be_said(what):
    with pytest.raises(ValueError, match="^what must be a non-empty string"):
        with compiling(what):
            pass


@settings(derandomize=True, deadline=None, max_examples=40)
@given(st.one_of(st.integers(), st.text(max_size=4), st.none(), st.floats(allow_nan=False)))
def test_the_walkers_progress_option_is_true_or_false(value):
    """Refused in one line naming it, before any other input is read (these are placeholders)."""
    from ijoy_jax.sim import walker

    for rollout in (walker.rollout, walker.rollout_batch):
        with pytest.raises(ValueError, match=r"^progress must be True or False, got "):
            rollout(None, None, None, None, None, num_steps=1, progress=value)


def test_serve_says_what_its_warm_up_compiles(quick_lines, monkeypatch, capsys):
    """``ijoy serve --warm-up``: the lines while the warm-up compiles (a sleep stands in for it), then its own
    line with the programs and seconds (no second final line); nothing is served (the loop returns at once)."""
    from ijoy_jax.apps import cli
    from ijoy_jax.server import Service
    from ijoy_jax.server import server as net

    def warm_up(self, shape, resolution=0.02):
        time.sleep(0.4)
        return {"shape": list(shape), "resolution": resolution, "seconds": 0.4, "programs": 11}

    monkeypatch.setattr(Service, "warm_up", warm_up)
    monkeypatch.setattr(net, "run", lambda *a, **k: {"requests": 0, "connections": 0, "dropped_replies": 0})
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        rc = cli.main(["serve", "--port", "0", "--warm-up", "24x20@0.05"])
    finally:  # ijoy serve installs its own; the test process keeps pytest's
        for s, h in handlers.items():
            signal.signal(s, h)
    out, err = capsys.readouterr()
    assert rc == 0 and out.startswith("listening on 127.0.0.1:"), (out, err)
    lines = err.splitlines()
    what = "the footstep programs for 24x20 maps at 0.05 m (2D and 2.5D)"
    assert lines[0] == f"ijoy serve: compiling {what}: 0 s", lines
    assert lines[lines.index("ijoy serve: warm-up for 24x20 maps at 0.05 m: 11 programs in 0.4 s") - 1].startswith(
        f"ijoy serve: compiling {what}: "
    ), lines
    assert not any("compiled" in line for line in lines), lines


# ------------------------------------------------------------------------------------ the slow tier: MJX


@pytest.mark.slow
def test_the_walkers_progress_runs_the_same_program(monkeypatch):
    """``rollout_batch(..., progress=True)``: bit for bit the README's small walk (tests/_tiny_walk.py), its
    compile named."""
    import _tiny_walk  # tests/ is on sys.path (pytest rootdir import)

    from ijoy_jax.sim import walker

    said = []

    def recorded(what, **kwargs):
        said.append(what)
        return compiling(what, **kwargs)

    monkeypatch.setattr(progress, "compiling", recorded)
    want = _tiny_walk.walk()
    fields, robots, starts, commands, dyn = _tiny_walk.inputs()
    got = walker.rollout_batch(
        _tiny_walk.sim(),
        fields,
        robots,
        starts,
        commands,
        num_steps=_tiny_walk.STEPS,
        frames_per_step=_tiny_walk.FRAMES,
        dynamics=dyn,
        key=0,
        progress=True,
    )
    assert said == ["the MJX walk of 2 robots (3 steps on 40x40 maps)"]
    for a, b in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(want), strict=True):
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes()


@pytest.mark.slow
def test_sim_render_says_what_it_compiles(quick_lines, tmp_path, capsys, monkeypatch):
    """``ijoy sim render``: the lines while its walk compiles, and the final one. The frames are blank (the
    offscreen renderer needs a GL library, and tests/test_sim_rollouts.py tests it): the subject is the compile."""
    from ijoy_jax.apps import cli
    from ijoy_jax.sim import render

    def blank(sim, terrain, qpos, *, width, height, **kwargs):
        return np.zeros((len(qpos), height, width, 3), np.uint8)

    monkeypatch.setattr(render, "render", blank)
    gif = tmp_path / "walk.gif"
    rc = cli.main(["sim", "render", "--steps", "1", "--frames", "2", "--size", "64x48", "--out", str(gif)])
    out, err = capsys.readouterr()
    assert rc == 0 and gif.exists(), err
    what = "the MJX walk (1 step on a 200x100 map)"
    lines = err.splitlines()
    assert lines[0] == f"[ijoy] compiling {what}: 0 s", lines
    assert any(re.fullmatch(rf"\[ijoy\] compiled {re.escape(what)} in \d+\.\d s", line) for line in lines), lines


def test_cue_field_says_what_it_compiles(monkeypatch, tmp_path, capsys):
    """``ijoy cue field`` (its field's compile stood in for by a 0.3 s sleep): the compiling line, then the
    compiled one, around the figure's computation; the JSON line on stdout as before."""
    from ijoy_jax.apps import cli
    from ijoy_jax.cue import plot

    monkeypatch.setattr(progress, "SHOW_AFTER_S", 0.0)
    monkeypatch.setattr(plot, "scenario_figure", lambda *a, **k: time.sleep(0.3))
    out = tmp_path / "field.png"
    assert cli.main(["cue", "field", "--out", str(out)]) == 0
    stdout, err = capsys.readouterr()
    what = "the cue's field over the paper's three scenes"
    lines = err.splitlines()
    assert lines[0].startswith(f"ijoy cue field: compiling {what}: "), lines
    assert re.fullmatch(rf"ijoy cue field: compiled {re.escape(what)} in \d+\.\d s", lines[-1]), lines
    assert json.loads(stdout) == {"png": str(out)}

"""The ``ijoy`` command line: every subcommand turns bad input into one line on stderr and exit status 2.

Each case runs the real command, with an input that the library refuses before any compute. The cases run in
one child process (``CHILD`` below), one after the other, each in a folder of its own and with the
interpreter's exit hook: what ``python -m ijoy_jax.apps.cli ARGS`` does, ``sys.exit(main(ARGS))``, its status,
stdout and stderr captured per case. One process, not one per case: each process spends about 2 s importing
JAX and the package, which is all the time these refusals take. ``test_the_ijoy_command_runs_as_a_program``
runs the command itself in a subprocess.
"""

import argparse
import contextlib
import importlib.metadata
import io
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from unittest import mock

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax
from ijoy_jax.apps import options

ROOT = Path(__file__).parents[1]

CASES = [
    (["demo", "--margin", "-1"], "margin must be >= 0"),
    (["demo", "--steps", "0"], "argument --steps: takes an integer >= 1, got '0'"),
    (["bench", "footcost", "--ref", "ref.npz"], "--ref is read or written by 'ijoy bench check' only"),
    (["bench", "check", "--ref", "no/such/folder/ref.npz"], "no folder for"),
    (["bench", "walk", "--families", "flat,lava"], "unknown terrain families ['lava']"),
    (["bench", "walk", "--plot", "no/such/folder/walk.png"], "no folder for"),
    (["bench", "sim", "--batch", "4"], "--batch: options of 'ijoy bench walk' only"),
    (["bench", "select", "--refine"], "--refine: options of 'ijoy bench walk' only"),
    (["bench", "footcost", "--kernel", "pallas"],
     "--kernel: options of 'ijoy bench select' and 'ijoy bench walk' only"),
    (["bench", "walk", "--parts", "numpy"], "--parts: options of 'ijoy bench select' only, not of 'walk'"),
    (["bench", "select", "--parts", "numpy,lava"], "argument --parts: unknown parts ['lava']; known: decisions, "
                                                   "rollouts, numpy"),
    (["bench", "walk", "--set", "metrics.support_limit"], "--set takes NAME=VALUE, e.g. metrics.support_limit="),
    (["bench", "walk", "--set", "w=abc"], "--set 'w=abc': 'abc' is not a number"),
    (["bench", "walk", "--set", "foot_length=0.3"], "--set 'foot_length=0.3': 'foot_length' is not one of ['w',"),
    (["bench", "walk", "--set", "metrics.support_limit=-1"], "robot.metrics.support_limit: must be >= 0, got -1.0"),
    (["bench", "walk", "--sweeps", "no_such_folder"], "no sweep file no_such_folder/flat_random.toml"),
    (["bench", "walk", "--resolution", "0.03"], "terrain.resolution: resolution 0.03 m must divide"),
    (["bench", "walk", "--seed", "-1"], "sweep.seed: must be >= 0, got -1"),
    (["bench", "walk", "--model", "hrp2"], "argument --model: invalid choice: 'hrp2'"),
    (["bench", "sim", "--model", "g1"], "--model: options of 'ijoy bench walk' only"),
    (["bench", "sim", "--set", "w=2"], "--set: options of 'ijoy bench walk' only"),
    (["bench", "sim", "--calls", "5"], "--calls: options of 'ijoy bench haptics' and 'ijoy bench cue' only"),
    (["bench", "haptics", "--tick-only"], "--tick-only: options of 'ijoy bench cue' only, not of 'haptics'"),
    (["sweep", "run", "no_such_sweep.toml"], "cannot read"),
    (["sweep", "summarize", "no_such_results"], "no result parts"),
    (["sim", "render", "--size", "big"], "argument --size: takes WIDTHxHEIGHT in pixels, e.g. 480x320, got 'big'"),
    (["sim", "render", "--frames", "0"], "argument --frames: takes an integer >= 1, got '0'"),
    (["sim", "render", "--strip", "no/such/folder/strip.png"], "argument --strip: no folder for"),
    (["sim", "render", "--model", "atlas"], "argument --model: invalid choice: 'atlas' (choose from 'biped', 'g1')"),
    (["demo", "--out", "no/such/folder/demo.png"], "argument --out: no folder for 'no/such/folder/demo.png'"),
    (["demo", "--out", "."], "argument --out: '.' is a folder"),
    (["demo", "--steps", "abc"], "argument --steps: takes an integer >= 1, got 'abc'"),
    (["bench", "walk", "--batch", "0"], "argument --batch: takes an integer >= 1, got '0'"),
    (["bench", "lava"], "argument BENCHMARK: invalid choice: 'lava'"),
    (["tune", "forward", "--out", "/dev/null/o"], "argument --out: no folder for '/dev/null/o'"),
    (["cue", "study", "--out", "/dev/null"], "argument --out: '/dev/null' is a file, not a folder"),
    (["drive", "--record", "/dev/null/drive.mcap"], "argument --record: no folder for"),  # its folder is made
    (["drive", "--replay", "no_such_drive.mcap", "--export-trace", "no/such/folder/t.csv"],
     "argument --export-trace: no folder for"),
    (["drive", "--param", "bogus=1"], "--param bogus=1: unknown key of terrain family 'obstacles'; known keys: "
                                      "start_x, start_y, start_radius, count, size_min"),
    (["tune", "forward", "--out", "o", "--set", "bogus=1"], "unknown config field(s) ['bogus']"),
    (["tune", "forward", "--out", "o", "--set", "distance"], "--set takes NAME=VALUE, e.g. distance=0.04"),
    (["tune", "inverse", "--out", "o", "--config", "no_such.toml"], "No such file or directory"),
    (["cue", "study", "--out", "o", "--train", "0"], "--train must be at least 1"),
    (["cue", "study", "--out", "o", "--steps", "0"], "argument --steps: takes an integer >= 1, got '0'"),
    (["tune", "forward", "--out", "o", "--set", "density=0.05"], "--set 'density=0.05': ForwardConfig: density must"),
    (["tune", "forward", "--out", "o", "--steps", "0"], "--steps: ForwardConfig: steps must be >= 1"),
    (["cue", "field", "--out", "no/such/folder/field.png"], "no folder for"),
    (["drive", "--server", "nohost"], "server must be HOST:PORT, got 'nohost'"),
    (["drive", "--margin", "-1"], "margin must be >= 0"),
    (["drive", "--replay", "no_such_drive.mcap"], "recording 'no_such_drive.mcap' does not exist"),
    (["drive", "--duration", "nan"], "--duration must be in (0, 86400] s, got nan"),
    (["drive", "--duration", "-1"], "--duration must be in (0, 86400] s"),
    (["drive", "--duration", "1e30"], "--duration must be in (0, 86400] s"),
    (["drive", "--server", "127.0.0.1:99999"], "server port must be in 1..65535"),
    (["tune", "inverse", "--out", "o", "--config", "."], "[Errno 21] Is a directory: '.'"),  # any OSError
    (["sweep", "run", str(ROOT / "sweeps" / "w_sweep.toml"), "--out", "/dev/null"],
     "argument --out: '/dev/null' is a file, not a folder"),
    (["serve", "--port", "99999", "--warm-up", "none"], "port must be in 0..65535"),
    (["serve", "--warm-up", "big"], "a map shape is NXxNY or NXxNY@RES"),
    (["serve", "--margin", "-0.1", "--warm-up", "none"], "margin must be >= 0"),
    (["serve", "--port", "0", "--warm-up", "20x20@0.001"], "warm-up: too_large: resolution 0.001 m"),
]


def _env():
    return dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))


def run_cli(args, cwd):
    return subprocess.run([sys.executable, "-m", "ijoy_jax.apps.cli", *args], cwd=cwd, env=_env(),
                          capture_output=True, text=True, timeout=300)


CHILD = """
import contextlib, io, json, os, sys, traceback
from ijoy_jax.apps import cli
out = []
for args, cwd in json.loads(sys.argv[1]):
    os.chdir(cwd)
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        try:
            status = cli.main(args)
        except SystemExit as e:  # argparse's errors, and what sys.exit(main()) would do
            status = e.code
        except BaseException:  # what the interpreter prints for an uncaught exception, and its status
            traceback.print_exc()
            status = 1
    out.append({"status": status, "stdout": stdout.getvalue(), "stderr": stderr.getvalue()})
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def refused(tmp_path_factory):
    """Per case of CASES: (exit status, stdout, stderr, folder it ran in), all run by one child process."""
    dirs = [tmp_path_factory.mktemp("case") for _ in CASES]
    jobs = [[args, str(d)] for (args, _), d in zip(CASES, dirs, strict=True)]
    p = subprocess.run([sys.executable, "-c", CHILD, json.dumps(jobs)], cwd=dirs[0], env=_env(),
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    results = json.loads(p.stdout.strip().splitlines()[-1])
    return [(r["status"], r["stdout"], r["stderr"], d) for r, d in zip(results, dirs, strict=True)]


@pytest.mark.parametrize("case", range(len(CASES)), ids=[" ".join(a[:2]) + f" {i}" for i, (a, _) in enumerate(CASES)])
def test_bad_input_is_one_clean_line_and_status_2(case, refused):
    _, message = CASES[case]
    status, stdout, stderr, folder = refused[case]
    assert status == 2, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ijoy: error: ") and message in lines[0], stderr
    assert "Traceback" not in stderr and stdout == ""
    assert list(folder.iterdir()) == []  # refused before writing anything


def test_the_ijoy_command_runs_as_a_program(tmp_path):
    """The real command in a process of its own: the module's entry point, its exit status and its one line."""
    p = run_cli(["demo", "--steps", "0"], tmp_path)
    assert p.returncode == 2 and p.stdout == "" and list(tmp_path.iterdir()) == []
    assert p.stderr.strip().splitlines() == [
        "ijoy: error: argument --steps: takes an integer >= 1, got '0' (see 'ijoy demo --help')"], p.stderr


def test_every_subcommand_has_a_bad_input_case(tmp_path):
    p = run_cli(["--help"], tmp_path)
    listed = re.search(r"\{([a-z,]+)\}", p.stdout).group(1).split(",")
    assert p.returncode == 0 and len(listed) >= 5
    assert set(listed) == {a[0] for a, _ in CASES}


def test_a_trace_that_would_never_end_is_refused_before_the_drive(tmp_path):
    """A trace's last time is the drive's end: 1e30 s ran without end (memory growing), now one line."""
    trace = tmp_path / "forever.csv"
    trace.write_text("t,forward,left,turn\n0,0.5,0,0\n1e30,0.5,0,0\n")
    p = run_cli(["drive", "--script", str(trace), "--headless"], tmp_path)
    assert p.returncode == 2 and p.stdout == "", p.stderr
    assert p.stderr.strip().splitlines() == [
        f"ijoy: error: the trace's last time ({trace}) must be in (0, 86400] s, got 1e+30"], p.stderr


# ------------------------------------------------------------------------ the parser: version, help, option types


def _parser() -> argparse.ArgumentParser:
    """The ``ijoy`` parser as :func:`ijoy_jax.apps.cli.main` builds it, caught before it parses (nothing runs)."""
    from ijoy_jax.apps import cli

    class Caught(Exception):
        pass

    def catch(self, *args, **kwargs):
        raise Caught(self)

    with mock.patch.object(argparse.ArgumentParser, "parse_args", catch), pytest.raises(Caught) as caught:
        cli.main([])
    return caught.value.args[0]


def _commands(parser, path=("ijoy",)):
    """(path, parser) of ``ijoy`` and of every subcommand under it, depth first."""
    yield path, parser
    for action in parser._actions:  # argparse keeps its subcommands nowhere public
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _commands(sub, (*path, name))


def _main(args) -> tuple[int, str, str]:
    """``ijoy ARGS`` in this process: (exit status, stdout, stderr); argparse's --help and --version exit."""
    from ijoy_jax.apps import cli

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = cli.main(args)
        except SystemExit as e:
            status = e.code
    return status, out.getvalue(), err.getvalue()


def test_version_is_the_installed_package_s():
    status, out, err = _main(["--version"])
    assert status == 0 and err == ""
    assert out.startswith(f"ijoy {importlib.metadata.version('ijoy_jax')} (jax "), out
    assert importlib.metadata.version("ijoy_jax") == ijoy_jax.__version__


def test_every_subcommand_has_a_description():
    """``ijoy X --help`` says what X does, beyond the one line of ``ijoy --help``."""
    missing = [" ".join(p) for p, sub in _commands(_parser()) if not sub.description]
    assert missing == []


def test_each_benchmark_has_its_own_help():
    """``ijoy bench NAME --help`` describes NAME and lists only NAME's options (walk's only under walk)."""
    from ijoy_jax.apps import bench_cli

    for name in bench_cli.BENCHMARKS:
        status, out, _ = _main(["bench", name, "--help"])
        assert status == 0 and out.startswith(f"usage: ijoy bench {name} "), out
        assert ("--families" in out) == (name == "walk") and ("--ref REF" in out) == (name == "check"), out
        assert ("--calls" in out) == (name in ("haptics", "cue")) and ("--tick-only" in out) == (name == "cue"), out


def test_bench_select_runs_the_parts_and_kernels_asked_for(tmp_path):
    """``ijoy bench select --parts numpy`` times the NumPy baseline alone (no selector program compiled); the fused
    kernel is timed on a GPU only: on a CPU ``--kernel pallas`` is refused, naming the device, and on a GPU
    accepted; a kernel not XLA's or the fused one is refused by name."""
    import jax

    from ijoy_jax.apps import bench

    out = tmp_path / "select.json"
    status, _, err = _main(["bench", "select", "--quick", "--parts", "numpy", "--json", str(out)])
    assert status == 0, err
    rows = json.loads(out.read_text())
    assert [(r["bench"], r["method"]) for r in rows] == [("select", "numpy-ordered")]
    assert rows[0]["decisions_per_s"] > 0
    status, _, err = _main(["bench", "select", "--quick", "--kernel", "pallas", "--parts", "numpy"])
    if jax.default_backend() == "cpu":
        assert status == 2 and "--kernel pallas: the fused kernel's speed needs a GPU" in err, err
    else:
        assert status == 0 and bench.select_kernels(["pallas"]) == ("pallas",), err
    with pytest.raises(ValueError, match=r"kernel must be xla or pallas, got \['cuda'\]"):
        bench.select_kernels(["cuda"])
    assert bench.select_kernels(["xla"]) == ("xla",)
    assert bench.select_kernels() == (("xla",) if jax.default_backend() == "cpu" else ("xla", "pallas"))


@pytest.mark.slow
def test_bench_select_decisions_and_rollouts_with_xla_only():
    """``--parts decisions,rollouts --kernel xla`` (quick sizes): XLA's decision and rollout rows, no fused
    kernel's and no NumPy row, each with a positive rate."""
    from ijoy_jax.apps import bench

    rows = bench.run("select", quick=True, kernels=["xla"], parts=["decisions", "rollouts"])
    assert {r["kernel"] for r in rows} == {"xla"}
    assert {r["bench"] for r in rows} == {"select", "rollout"}
    assert {r["method"] for r in rows if r["bench"] == "select"} == {"exhaustive", "ordered"}
    # the paper's 2D grid beside the 2.5D map, both methods on each
    assert {(r["terrain"], r["method"]) for r in rows if r["bench"] == "select"} == {
        (t, m) for t in ("2D", "2.5D") for m in ("exhaustive", "ordered")}
    assert all(r.get("decisions_per_s", r.get("steps_per_s", 0)) > 0 for r in rows)
    # the work a decision did, from the timed program's own output: the whole action set, or the ordered
    # search's share of it (whole chunks of 32, at least one)
    n = ijoy_jax.robots.hrp2().num_actions
    work = {(r["method"], r["terrain"], r["max_margin"], r["batch"]): r["actions_per_decision"]
            for r in rows if r["bench"] == "select"}
    assert all(v == n for (method, *_), v in work.items() if method == "exhaustive"), work
    ordered = [v for (method, *_), v in work.items() if method == "ordered"]
    assert all(32 <= v <= n for v in ordered) and min(ordered) < n, work


def test_every_subcommand_is_a_module_of_its_own():
    """``ijoy NAME`` lives in ijoy_jax/apps/NAME_cli.py: ``add_parser(sub)`` registers it, ``main(args)`` runs it."""
    import importlib

    names = [path[1] for path, _ in _commands(_parser()) if len(path) == 2]
    assert len(names) >= 8
    for name in names:
        module = importlib.import_module(f"ijoy_jax.apps.{name}_cli")
        assert callable(module.add_parser) and callable(module.main), name


# A value each option type refuses; an option of a type not listed here fails the test below until it is added.
BAD_VALUE = {"int": "abc", "float": "abc", "positive_int": "0", "positive_ints": "1,x", "image_size": "big",
             "output_file": "no/such/folder/x.out", "output_folder": "/dev/null/x",
             "output_file_in_new_folder": "/dev/null/x/y.toml", "_walk_families": "lava",
             "_walkers": "real", "_parts": "lava"}


def test_every_typed_option_refuses_a_bad_value_in_one_line_naming_it(tmp_path, monkeypatch):
    """Every option with a type, of every subcommand: a bad value is one line naming the option, status 2,
    refused as the command line is parsed."""
    monkeypatch.chdir(tmp_path)
    checked = 0
    for path, sub in _commands(_parser()):
        for action in sub._actions:
            if action.type is None or not action.option_strings:
                continue
            flag = action.option_strings[-1]
            kind = getattr(action.type, "__name__", repr(action.type))
            assert kind in BAD_VALUE, f"{' '.join(path)} {flag}: add a bad value of type {kind} to BAD_VALUE"
            status, out, err = _main([*path[1:], flag, BAD_VALUE[kind]])
            lines = err.strip().splitlines()
            assert status == 2 and out == "" and len(lines) == 1, (path, flag, err)
            assert lines[0].startswith(f"ijoy: error: argument {'/'.join(action.option_strings)}: "), lines
            checked += 1
    assert checked >= 40 and list(tmp_path.iterdir()) == []


def _names():
    """Relative paths of up to 3 parts: the fixture's folder, file and missing names, '.', '..', odd text."""
    part = st.one_of(st.sampled_from(["d", "f", "missing", ".", "..", "", " "]),
                     st.text(st.characters(blacklist_characters="/", blacklist_categories=("Cs",)), max_size=6))
    return st.lists(part, min_size=1, max_size=3).map("/".join).filter(lambda n: not n.startswith("/"))


@contextlib.contextmanager
def _cwd(folder):
    """Run the block in ``folder`` (the process's working folder, restored after)."""
    old = os.getcwd()
    os.chdir(folder)
    try:
        yield
    finally:
        os.chdir(old)


def _sandbox(tmp: str) -> Path:
    """A working folder 3 deep in ``tmp`` (so '..' stays inside it) holding folder d and file f."""
    cwd = Path(tmp, "1", "2", "3")
    (cwd / "d").mkdir(parents=True)
    (cwd / "f").write_text("")
    return cwd


def _write_file(path: Path) -> None:
    path.write_text("x")


def _write_file_making_its_folder(path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("x")


def _make_folder_and_write_in_it(path: Path) -> None:
    path.mkdir(parents=True, exist_ok=True)
    (path / "x").write_text("x")


@pytest.mark.parametrize("check, use", [(options.output_file, _write_file),
                                        (options.output_file_in_new_folder, _write_file_making_its_folder),
                                        (options.output_folder, _make_folder_and_write_in_it)],
                         ids=["output_file", "output_file_in_new_folder", "output_folder"])
@settings(max_examples=150)
@given(_names())
def test_an_accepted_output_can_be_made_and_written(check, use, name):
    """output_file / output_file_in_new_folder / output_folder refuse only with a one-line ArgumentTypeError, and
    what they accept can be written (a file, its folder made first for the second) or made and written in (a
    folder)."""
    with tempfile.TemporaryDirectory() as tmp, _cwd(_sandbox(tmp)):
        try:
            check(name)
        except argparse.ArgumentTypeError as e:
            assert str(e) and "\n" not in str(e)
            return
        use(Path(name))


def test_a_drive_records_and_exports_into_a_folder_it_makes(tmp_path):
    """--record and --export-sweep name files whose writers make their folder (a new ``sweeps/``): accepted as
    parsed, where --export-trace (written into an existing folder only) refuses the same name."""
    new = str(tmp_path / "new" / "sweeps" / "drive.toml")
    drive = dict(_commands(_parser()))[("ijoy", "drive")]
    parsed = drive.parse_args(["--replay", "x.mcap", "--export-sweep", new])
    assert parsed.export_sweep == new
    assert drive.parse_args(["--record", new]).record == new
    with pytest.raises(options.UsageError, match="--export-trace.*does not exist"):
        drive.parse_args(["--replay", "x.mcap", "--export-trace", new])
    assert not (tmp_path / "new").exists()  # parsing makes nothing


@given(st.one_of(st.text(max_size=12), st.from_regex(r"\A-?[0-9]{1,5}[xX]-?[0-9]{1,5}\Z")))
def test_image_size_is_two_sides_in_range_or_a_one_line_refusal(text):
    try:
        width, height = options.image_size(text)
    except argparse.ArgumentTypeError as e:
        assert "\n" not in str(e) and repr(text) in str(e)
        return
    assert 1 <= width <= options.MAX_IMAGE_SIDE and 1 <= height <= options.MAX_IMAGE_SIDE
    assert [int(v) for v in text.lower().split("x")] == [width, height]


@given(st.one_of(st.text(max_size=6), st.integers(-5, 10**6).map(str)))
def test_positive_int_is_at_least_1_or_a_one_line_refusal(text):
    try:
        value = options.positive_int(text)
    except argparse.ArgumentTypeError as e:
        assert "\n" not in str(e) and repr(text) in str(e)
        return
    assert value >= 1 and value == int(text)


def test_the_force_feedback_line_only_when_a_device_was_asked_for_or_found(monkeypatch, capsys):
    """Without --ff, a drive with no force-feedback device says nothing about it; asked for one (--ff auto or a
    path), it says why there is none; a device found is always named."""
    from ijoy_jax.apps import drive_cli
    from ijoy_jax.live import forcefeedback

    drive = dict(_commands(_parser()))[("ijoy", "drive")]
    default = next(a.default for a in drive._actions if "--ff" in a.option_strings)
    monkeypatch.setattr(forcefeedback, "open_device", lambda path=None: forcefeedback.NoFeedback("no device"))
    for spec, said in ((default, False), ("auto", True), ("/dev/input/event9", True)):
        drive_cli.feedback_device(spec)
        err = capsys.readouterr().err
        assert ("force feedback: off (no device)" in err) == said, (spec, err)
    assert drive_cli.feedback_device("off") is None and capsys.readouterr().err == ""
    found = mock.Mock(description="Pad (/dev/input/event3: constant)")
    monkeypatch.setattr(forcefeedback, "open_device", lambda path=None: found)
    assert drive_cli.feedback_device(default) is found
    assert "force feedback: Pad (/dev/input/event3: constant)" in capsys.readouterr().err

"""The ``ijoy`` command line: every subcommand turns bad input into one line on stderr and exit status 2.

Each case runs the real command, with an input that the library refuses before any compute. The cases run in
one child process (``CHILD`` below), one after the other, each in a folder of its own and with the
interpreter's exit hook: what ``python -m ijoy_jax.apps.cli ARGS`` does, ``sys.exit(main(ARGS))``, its status,
stdout and stderr captured per case. One process, not one per case: each process spends about 2 s importing
JAX and the package, which is all the time these refusals take. ``test_the_ijoy_command_runs_as_a_program``
runs the command itself in a subprocess.
"""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]

CASES = [
    (["demo", "--margin", "-1"], "margin must be >= 0"),
    (["demo", "--steps", "0"], "num_steps must be at least 1"),
    (["bench", "footcost", "--ref", "ref.npz"], "--ref is read or written by 'ijoy bench check' only"),
    (["bench", "check", "--ref", "no/such/folder/ref.npz"], "no folder for"),
    (["bench", "walk", "--families", "flat,lava"], "unknown terrain families ['lava']"),
    (["bench", "walk", "--plot", "no/such/folder/walk.png"], "no folder for"),
    (["bench", "sim", "--batch", "4"], "--batch: options of 'ijoy bench walk' only"),
    (["bench", "select", "--refine"], "--refine: options of 'ijoy bench walk' only"),
    (["bench", "footcost", "--kernel", "pallas"], "--kernel: options of 'ijoy bench walk' only"),
    (["bench", "walk", "--set", "metrics.support_limit"], "--set takes NAME=VALUE, e.g. metrics.support_limit="),
    (["bench", "walk", "--set", "w=abc"], "--set 'w=abc': 'abc' is not a number"),
    (["bench", "walk", "--set", "foot_length=0.3"], "--set 'foot_length=0.3': 'foot_length' is not one of ['w',"),
    (["bench", "walk", "--set", "metrics.support_limit=-1"], "robot.metrics.support_limit must be finite and >= 0"),
    (["bench", "sim", "--set", "w=2"], "--set: options of 'ijoy bench walk' only"),
    (["sweep", "run", "no_such_sweep.toml"], "cannot read"),
    (["sweep", "summarize", "no_such_results"], "no result parts"),
    (["sim", "render", "--size", "big"], "invalid literal"),
    (["tune", "forward", "--out", "o", "--set", "bogus=1"], "unknown config field(s) ['bogus']"),
    (["tune", "forward", "--out", "o", "--set", "distance"], "--set takes NAME=VALUE, e.g. distance=0.04"),
    (["tune", "inverse", "--out", "o", "--config", "no_such.toml"], "No such file or directory"),
    (["cue", "study", "--out", "o", "--train", "0"], "--train must be at least 1"),
    (["cue", "field", "--out", "no/such/folder/field.png"], "no folder for"),
    (["drive", "--server", "nohost"], "server must be HOST:PORT, got 'nohost'"),
    (["drive", "--margin", "-1"], "margin must be >= 0"),
    (["drive", "--replay", "no_such_drive.mcap"], "recording 'no_such_drive.mcap' does not exist"),
    (["drive", "--duration", "nan"], "--duration must be in (0, 86400] s, got nan"),
    (["drive", "--duration", "-1"], "--duration must be in (0, 86400] s"),
    (["drive", "--duration", "1e30"], "--duration must be in (0, 86400] s"),
    (["drive", "--server", "127.0.0.1:99999"], "server port must be in 1..65535"),
    (["tune", "inverse", "--out", "o", "--config", "."], "[Errno 21] Is a directory: '.'"),  # any OSError
    (["sweep", "run", str(ROOT / "sweeps" / "w_sweep.toml"), "--out", "/dev/null"], "/dev/null is not a folder"),
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
    assert p.stderr.strip().splitlines() == ["ijoy: error: num_steps must be at least 1, got 0"], p.stderr


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

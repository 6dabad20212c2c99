"""The ``ijoy`` command line: every subcommand turns bad input into one line on stderr and exit status 2.

Each case runs the real command in a subprocess (``python -m ijoy_jax.apps.cli``, what the ``ijoy`` script
calls), with an input that the library refuses before any compute.
"""

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
    (["serve", "--port", "99999", "--warm-up", "none"], "port must be in 0..65535"),
    (["serve", "--warm-up", "big"], "a map shape is NXxNY or NXxNY@RES"),
    (["serve", "--margin", "-0.1", "--warm-up", "none"], "margin must be >= 0"),
    (["serve", "--port", "0", "--warm-up", "20x20@0.001"], "warm-up: too_large: resolution 0.001 m"),
]


def run_cli(args, cwd):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", "ijoy_jax.apps.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("args, message", CASES, ids=[" ".join(a[:2]) + f" {i}" for i, (a, _) in enumerate(CASES)])
def test_bad_input_is_one_clean_line_and_status_2(args, message, tmp_path):
    p = run_cli(args, tmp_path)
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ijoy: error: ") and message in lines[0], p.stderr
    assert "Traceback" not in p.stderr and p.stdout == ""
    assert list(tmp_path.iterdir()) == []  # refused before writing anything


def test_every_subcommand_has_a_bad_input_case(tmp_path):
    p = run_cli(["--help"], tmp_path)
    listed = re.search(r"\{([a-z,]+)\}", p.stdout).group(1).split(",")
    assert p.returncode == 0 and len(listed) >= 5
    assert set(listed) == {a[0] for a, _ in CASES}

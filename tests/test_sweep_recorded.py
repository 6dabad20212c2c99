"""Sweeps whose commands (and terrain) come from files (ijoy_jax.sweep.recorded): the files read as ijoy drive wrote
or reads them, every bad file or key refused before compute in one line (file: key: reason), a recording with a
dead end said so, a changed file never resumed into old results, and `ijoy drive --export-sweep`'s refusals.

The recordings here are written with ijoy_jax.live.Recorder directly (no drive: nothing compiles). A recorded
drive exported and run by the engine, against the drive's own footsteps, is in tests/test_live.py (it needs a
drive), and commands from a file with the MJX biped in tests/test_sweep_physics.py (its one program).
"""

from __future__ import annotations

import dataclasses
import json
import re

import numpy as np
import pytest
from _sweep_util import write  # tests/ is on sys.path (pytest rootdir import)
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax import live, sweep
from ijoy_jax.apps import cli

SHAPE, RES = (20, 16), 0.05  # 1 m x 0.8 m
ROBOT = ij.robots.hrp2(margin=0.02, density=0.25)  # 19 actions: the one run below compiles a small program
COMMANDS = [[0.2, 0.0, 0.0], [0.2, 0.05, 0.1], [0.0, -0.1, 0.0]]
TRACE = "t,forward,left,turn\n0.0, 1.0, 0.0, 0.0\n1.0, 0.0, 0.5, -0.3\n2.0, 0.0, 0.0, 0.0\n"


def _recording(path, commands=COMMANDS, *, valid=None, steps=None, start=(0.3, 0.4), spec=None, first_swing=1):
    """A drive recording as ijoy drive writes it (its metadata, terrain and robot, one decision per command)."""
    free = np.ones(SHAPE, bool)
    free[15:, :] = False  # a wall at x = 0.75 m
    terrain = ij.terrain.from_arrays(None, free, RES)
    feet = np.asarray(ij.robots.start_stance(ROBOT, *start), np.float32)
    settings = live.DriveSettings(terrain=spec or {"kind": "image", "path": "ground.png"}, first_swing=first_swing)
    config = {"settings": dataclasses.asdict(settings), "start": feet.tolist()}
    with live.Recorder(path, config, terrain, ROBOT) as rec:
        for i, c in enumerate(commands):
            rec.write("/ijoy/decision", 0.8 * i, {
                "step": (steps or range(1, len(commands) + 1))[i], "t": 0.8 * i, "axes": [0.0, 0.0, 0.0],
                "command": c, "stance": [0.0, 0.0, 0.0], "stance_side": 1.0, "swing_from": [0.0, 0.0, 0.0],
                "foothold": [0.0] * 6, "valid": True if valid is None else valid[i], "cost": 0.0, "index": 0,
                "terms": {}, "latency_s": 0.01, "deadline_slack_s": 0.7, "decider": "local"})
    return path


@pytest.fixture
def files(tmp_path):
    """Good and bad input files beside the sweep files of a test."""
    _recording(tmp_path / "drive.mcap")
    _recording(tmp_path / "empty.mcap", [])
    _recording(tmp_path / "gaps.mcap", steps=[1, 3, 4])
    _recording(tmp_path / "edge.mcap", start=(0.05, 0.4))  # the feet hang over the map's edge
    (tmp_path / "garbage.mcap").write_bytes(b"\x89MCAP0\r\n this is not one")
    (tmp_path / "short.mcap").write_bytes(b"x")  # shorter than MCAP's magic
    (tmp_path / "torn.mcap").write_bytes((tmp_path / "drive.mcap").read_bytes()[:300])  # a recording cut short
    (tmp_path / "trace.csv").write_text(TRACE)
    (tmp_path / "bad.csv").write_text("t,forward,left,turn\n0,1,0\n")
    (tmp_path / "instant.csv").write_text("0.0, 1.0, 0.0, 0.0\n")  # ends at 0 s: no decision
    return tmp_path


BAD = [
    ('[command]\nfile = "missing.mcap"\n', "command.file", "missing.mcap' does not exist"),
    ('[command]\nfile = "garbage.mcap"\n', "command.file", "is not a readable ijoy drive recording (MCAP)"),
    ('[command]\nfile = "short.mcap"\n', "command.file", "is not a readable ijoy drive recording (MCAP)"),
    ('[terrain]\nrecording = "torn.mcap"\n', "terrain.recording", "is not a readable ijoy drive recording (MCAP)"),
    ('[command]\nfile = "empty.mcap"\n', "command.file", "the recording has no decisions"),
    ('[command]\nfile = "gaps.mcap"\n', "command.file", "not steps 1 to 3 in order"),
    ('[command]\nfile = "bad.csv"\n', "command.file", "bad.csv:2: expected 4 comma-separated values"),
    ('[command]\nfile = "instant.csv"\n', "command.file", "ends (0.0 s) before its first decision"),
    ("[command]\nfile = 3\n", "command.file", "must be a file name (a string)"),
    ('[command]\nfile = "drive.mcap"\nvx = 0.2\n', "command.vx", "give a file or a distribution, not both"),
    ("[command]\ndeadzone = 0.2\n", "command.deadzone", "only with command.file"),
    ('[command]\nfile = "drive.mcap"\ndeadzone = 0.2\n', "command.deadzone", "is for trace files"),
    ('[command]\nfile = "trace.csv"\ndecide_at = 1.0\n', "command.decide_at", "must be in [0, 1)"),
    ('[command]\nfile = "drive.mcap"\nfirst_swing = 0\n', "command.first_swing", "must be 1 (left foot first)"),
    ('[command]\nfile = "drive.mcap"\nturbo = 1\n', "command.turbo", "unknown key"),
    ('[sweep]\nnum_steps = 9\n[command]\nfile = "drive.mcap"\n', "sweep.num_steps", "command.file holds 3 commands"),
    ('[command]\nfile = "trace.csv"\n[grid]\n"robot.step_time" = [0.6, 0.8]\n', "grid.robot.step_time",
     "fix it in [robot]"),
    ('[sweep]\nrandom_samples = 2\n[command]\nfile = "trace.csv"\n[random]\n"robot.step_time" = [0.6, 0.8]\n',
     "random.robot.step_time", "fix it in [robot]"),
    ('[terrain]\nrecording = "drive.mcap"\nfamily = "obstacles"\n', "terrain.family",
     "give a recording or a generated terrain, not both"),
    ('[terrain]\nrecording = "drive.mcap"\n[grid]\n"terrain.count" = [1, 2]\n', "grid.terrain.count",
     "terrain parameters need a generated terrain"),
    ('[terrain]\nrecording = "trace.csv"\n', "terrain.recording", "is not a drive recording"),
    ('[terrain]\nrecording = "missing.mcap"\n', "terrain.recording", "does not exist"),
    ('[sweep]\nwalker = "mjx"\n[terrain]\nrecording = "edge.mcap"\n', "terrain.recording",
     "needs ground at (-0.0"),
]


@pytest.mark.parametrize("text, key, reason", BAD, ids=[f"{b[1]}:{b[2][:24]}" for b in BAD])
def test_bad_files_and_keys_name_file_key_and_reason(files, text, key, reason):
    path = write(files, text, "bad_sweep.toml")
    with pytest.raises(sweep.SweepConfigError) as e:
        sweep.load_config(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: {key}: ") and len(msg.splitlines()) == 1, msg
    assert reason in msg


@settings(max_examples=60, deadline=None)
@given(data=st.binary(max_size=300), suffix=st.sampled_from([".mcap", ".csv"]))
def test_any_bytes_are_read_or_refused_in_one_line(tmp_path_factory, data, suffix):
    """Hostile files: whatever the bytes, reading them as a command file gives commands or one ValueError line."""
    path = tmp_path_factory.mktemp("hostile") / f"f{suffix}"
    path.write_bytes(data)
    try:
        seq = sweep.recorded.read_commands(path, ROBOT)
    except ValueError as e:
        assert len(str(e).splitlines()) == 1 and str(e)
    else:  # a trace that parses: finite float32 commands within the robot's range
        lo, hi = ij.robots.command_range(ROBOT)
        assert seq.kind == "trace" and np.all(seq.commands >= lo - 1e-6) and np.all(seq.commands <= hi + 1e-6)


def test_a_recording_cut_anywhere_is_refused_in_one_line(files):
    data = (files / "drive.mcap").read_bytes()
    for n in np.linspace(0, len(data) - 1, 40).astype(int):
        (files / "cut.mcap").write_bytes(data[:n])
        with pytest.raises(ValueError) as e:
            sweep.recorded.read_commands(files / "cut.mcap")
        assert len(str(e.value).splitlines()) == 1
    assert len(sweep.recorded.read_commands(files / "drive.mcap").commands) == 3  # the whole file reads


def test_the_command_line_says_it_in_one_line(files, capsys):
    path = write(files, '[command]\nfile = "garbage.mcap"\n', "bad_sweep.toml")
    assert cli.main(["sweep", "run", str(path), "--out", str(files / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"ijoy: error: {path}: command.file: ") and len(err.splitlines()) == 1, err
    assert not (files / "out").exists()


def test_a_recording_gives_its_commands_terrain_start_and_first_swing(files):
    _recording(files / "right.mcap", first_swing=-1)
    path = write(files, '[sweep]\nscenarios_per_cell = 1\n[terrain]\nrecording = "drive.mcap"\n[command]\n'
                        'file = "right.mcap"\n[grid]\n"robot.margin" = [0.0, 0.05]\n')
    cfg = sweep.load_config(path)
    assert cfg.num_steps == 3 and cfg.first_swing == -1 and cfg.family is None and cfg.command == {}
    assert (cfg.shape, cfg.resolution, cfg.has_height) == (SHAPE, RES, False)
    np.testing.assert_array_equal(cfg.command_steps, np.asarray(COMMANDS, np.float32))
    assert cfg.inputs == {"command.file": cfg.command_file.sha256, "terrain.recording": cfg.terrain_recording.sha256}
    table = sweep.scenarios(cfg)
    assert len(table) == 2 and not [c for c in table.columns if c.startswith(("command.", "terrain."))]
    sc = sweep.scenario(cfg, 1)
    rec = live.read_recording(files / "drive.mcap")
    np.testing.assert_array_equal(np.asarray(sc.terrain.free), np.asarray(rec.terrain.free))
    np.testing.assert_array_equal(sc.start, np.asarray(rec.config["start"], np.float32))
    np.testing.assert_array_equal(sc.command, np.asarray(COMMANDS, np.float32))
    assert sc.first_swing == -1 and float(sc.robot.margin) == np.float32(0.05)
    # fewer steps than commands: the first ones
    short = sweep.parse_config(path.read_text().replace("[sweep]", "[sweep]\nnum_steps = 2"), str(path))
    np.testing.assert_array_equal(short.command_steps, np.asarray(COMMANDS[:2], np.float32))


def test_a_trace_gives_the_commands_a_drive_of_it_decides_with(files):
    """ijoy_jax.stick.scripted_commands: the stick at 0, 0.8, 1.6 s (the trace ends at 2 s), through the
    dead zone onto the sweep robot's command range; a later decision point reads the stick later."""
    lo, hi = ij.robots.command_range(ROBOT)
    cfg = sweep.parse_config('[robot]\ndensity = 0.25\n[command]\nfile = "trace.csv"\n', str(files / "s.toml"))
    want = [[hi[0], 0.0, 0.0], [hi[0], 0.0, 0.0], [0.0, hi[1] * 4 / 9, lo[2] * 2 / 9]]  # (0.5 - 0.1) / 0.9, ...
    np.testing.assert_allclose(cfg.command_steps, np.asarray(want, np.float32), rtol=1e-6)
    assert cfg.command_file.kind == "trace" and cfg.first_swing == 1 and cfg.command_file.invalid == ()
    late = sweep.parse_config('[robot]\ndensity = 0.25\n[command]\nfile = "trace.csv"\ndecide_at = 0.5\n'
                              "deadzone = 0.6\n", str(files / "s.toml"))  # read at 0.4 and 1.2 s (2.0: the end)
    np.testing.assert_allclose(late.command_steps, np.asarray([[hi[0], 0, 0], [0, 0, 0]], np.float32))  # |0.5| < 0.6
    # The sweep's reach is its robot's: full stick forward is a 0.30 m step per 0.8 s, not 0.20 m
    far = sweep.parse_config('[robot]\ndensity = 0.25\nreach = 0.30\n[command]\nfile = "trace.csv"\n',
                             str(files / "s.toml"))
    _, hi_far = ij.robots.command_range(ij.robots.hrp2(density=0.25, reach=0.30))
    assert hi_far[0] == pytest.approx(hi[0] * 1.5) and hi_far[1] == pytest.approx(hi[1])
    np.testing.assert_allclose(far.command_steps, np.asarray(want, np.float32) * [[1.5, 1, 1]], rtol=1e-6)
    # A reach beyond the default max_sole_distance with a longer one set; a huge one refused before any lattice
    farther = sweep.parse_config('[robot]\nreach = 0.45\nmax_sole_distance = 0.6\n[command]\nfile = "trace.csv"\n',
                                 str(files / "s.toml"))
    assert farther.command_steps[0, 0] == pytest.approx(0.45 / 0.8)
    # a shorter max_sole_distance at the paper's reach refuses far steps in the rollouts, not the trace's robot
    short = sweep.parse_config('[robot]\ndensity = 0.25\nmax_sole_distance = 0.3\n[command]\nfile = "trace.csv"\n',
                               str(files / "s.toml"))
    np.testing.assert_allclose(short.command_steps, cfg.command_steps)
    with pytest.raises(sweep.SweepConfigError, match=r"robot\.reach: 1e\+30 m makes about .* actions"):
        sweep.parse_config('[robot]\nreach = 1e30\n[command]\nfile = "trace.csv"\n', str(files / "s.toml"))


def test_a_dead_end_in_the_recording_is_said(files, tmp_path):
    """The sweep's robot stops at a decision without a valid step (the drive stood and decided again): the file
    and ijoy drive --export-sweep say so."""
    path = _recording(files / "stuck.mcap", valid=[True, False, True])
    seq = sweep.recorded.read_commands(path)
    assert seq.invalid == (2,) and seq.kind == "recording"
    out = tmp_path / "export" / "stuck.toml"
    info = sweep.export_drive(live.read_recording(path), out, path)
    assert info["invalid_decisions"] == [2] and info["terrain"] == "recording" and info["decisions"] == 3
    text = out.read_text()
    assert "(steps [2])" in text and "the footsteps agree up to the first of them" in text
    cfg = sweep.load_config(out)  # the file as written is a valid sweep of the recording
    assert cfg.num_steps == 3 and cfg.inputs["command.file"] == seq.sha256
    assert f'recording = "../{path.name}"' in text and "[robot]" in text and "density = 0.25" in text


FLAT = {"kind": "family", "family": "flat", "seed": 0, "shape": list(SHAPE), "resolution": RES}


@pytest.mark.parametrize("spec, start, match", [
    ({"kind": "image", "path": "ground.png"}, None, "was not drawn from a generator family"),
    (FLAT, [0.3, 0.4, 0.0], "started away from the family's start zone"),
    (FLAT, None, "is not the recorded drive (the terrain's"),  # the recorded map has a wall, the family's not
], ids=["image", "start", "other map"])
def test_export_to_a_family_refuses_what_it_cannot_reproduce(files, tmp_path, capsys, spec, start, match):
    """--sweep-terrain family only for a family's map from its start zone, checked against the recording, in one
    line, writing nothing."""
    path = _recording(files / "d.mcap", spec=spec)
    recording = live.read_recording(path)
    recording.config["settings"]["start"] = start  # as ijoy drive --start records it
    with pytest.raises(ValueError, match=re.escape(match)) as e:
        sweep.export_drive(recording, tmp_path / "x.toml", path, terrain="family")
    assert len(str(e.value).splitlines()) == 1 and not (tmp_path / "x.toml").exists()
    if start is None:  # the command line says the same
        code = cli.main(["drive", "--replay", str(path), "--export-sweep", str(tmp_path / "x.toml"),
                         "--sweep-terrain", "family"])
        err = capsys.readouterr().err.strip()
        assert code == 2 and err.startswith("ijoy: error: ") and match in err and len(err.splitlines()) == 1
        assert not (tmp_path / "x.toml").exists()


def test_a_changed_file_is_another_sweep(files, tmp_path):
    """The sweep's plan records its files' hashes: a rerun after the recording changed refuses the old folder."""
    path = write(files, '[sweep]\nscenarios_per_cell = 1\n[robot]\ndensity = 0.25\n[terrain]\nrecording = '
                        '"drive.mcap"\n[command]\nfile = "drive.mcap"\n')
    stats = sweep.run(path, tmp_path / "out", progress=False)
    assert stats.computed == 1
    df = sweep.load(tmp_path / "out")
    assert df["steps_taken"].iloc[0] > 0
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert manifest["plan"]["inputs"] == sweep.load_config(path).inputs
    _recording(files / "drive.mcap", [[0.1, 0.0, 0.0]] * 3)  # the same name, other commands
    with pytest.raises(ValueError, match="holds results of a different sweep or chunk plan"):
        sweep.run(path, tmp_path / "out", progress=False)
    assert sweep.run(path, tmp_path / "out2", progress=False).computed == 1

"""Sweep folders and sweep sizes: parts record their plan, one run per folder (a lock), sizes checked before
any allocation, a start zone that leaves room for the terrain, and slices of a sweep that a later run extends.

The sweep is tests/_sweep_util.py's tiny one (2D 60 x 50 map at 4 cm, 19 actions, 6 steps), as in
tests/test_sweep.py, with a grid of robot.w alone: one compile of the chunk function for the module.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from _sweep_util import tiny_sweep, write  # tests/ is on sys.path (pytest rootdir import)
from hypothesis import given, settings
from hypothesis import strategies as st

from ijoy_jax import sweep
from ijoy_jax.apps import cli
from ijoy_jax.sweep import config as sweep_config
from ijoy_jax.sweep import expansion as sweep_expansion
from ijoy_jax.sweep import fits as sweep_fits
from ijoy_jax.sweep import results as sweep_results
from ijoy_jax.sweep import seeding
from ijoy_jax.terrain import generators as gen
from ijoy_jax.terrain.family import ParamError

TINY = tiny_sweep(margins=False)
CHUNK = 2  # 6 scenarios -> 3 chunks
# A second run of two real processes gets this long to refuse (it compiles nothing before it does), s.
REFUSE_S = 60


# --------------------------------------------------------------------------- 4. the start zone


def test_start_zone_covering_the_whole_map_is_refused_naming_the_field():
    fam = gen.FAMILIES["obstacles"]
    shape, res = (60, 50), 0.04  # 2.4 m x 2.0 m, start point (0.36, 1.0) m: farthest centre ~2.24 m away
    with pytest.raises(ParamError, match="covers the whole 2.4 x 2 m map") as e:
        fam.validate(fam.params(start_radius=50.0), shape=shape, resolution=res)
    assert e.value.field == "start_radius"
    fam.validate(fam.params(start_radius=2.0), shape=shape, resolution=res)  # leaves the far corners
    fam.validate(fam.params(start_radius=50.0))  # no map given: nothing to compare with


@pytest.mark.parametrize("name", sorted(gen.FAMILIES))
def test_every_family_refuses_a_start_zone_over_the_whole_map(name):
    fam = gen.FAMILIES[name]
    with pytest.raises(ParamError, match="start_radius"):
        fam.validate(fam.params(start_radius=50.0), shape=(48, 40), resolution=0.05)


@pytest.mark.parametrize("text, key", [
    (TINY.replace("count = 6\n", "count = 6\nstart_radius = 50\n"), "terrain.params.start_radius"),
    (TINY + '"terrain.start_radius" = [0.35, 50.0]\n', "grid.terrain.start_radius"),
])
def test_sweep_refuses_a_start_zone_over_the_whole_map(tmp_path, text, key):
    path = write(tmp_path, text)
    with pytest.raises(sweep.SweepConfigError) as e:
        sweep.load_config(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: {key}: "), msg
    assert "covers the whole" in msg


# --------------------------------------------------------------------------- 1. parts record their plan


@pytest.fixture(scope="module")
def tiny_file(tmp_path_factory) -> Path:
    return write(tmp_path_factory.mktemp("cfg"), TINY, "tiny.toml")


@pytest.fixture(scope="module")
def other_file(tmp_path_factory) -> Path:
    """Another sweep with the same plan shape (3 chunks of 2): only the robot.w values differ."""
    return write(tmp_path_factory.mktemp("cfg"), TINY.replace("[0.5, 2.0]", "[1.0, 4.0]"), "tiny.toml")


def test_parts_record_their_plan(tiny_file, tmp_path):
    out = tmp_path / "a"
    sweep.run(tiny_file, out, chunk_size=CHUNK, progress=False)
    man = json.loads((out / "manifest.json").read_text())
    plans = {sweep_results.part_plan(p)["hash"] for p in (out / "parts").glob("part-*.parquet")}
    assert plans == {man["plan_hash"]}
    assert len(man["plan_hash"]) >= 12


def test_another_sweep_into_a_folder_without_manifest_is_refused(tiny_file, other_file, tmp_path):
    out = tmp_path / "mixed"
    sweep.run(tiny_file, out, chunk_size=CHUNK, progress=False)
    (out / "manifest.json").unlink()
    parts_before = sorted((out / "parts").glob("*"))
    with pytest.raises(ValueError) as e:
        sweep.run(other_file, out, chunk_size=CHUNK, progress=False)
    msg = str(e.value)
    assert str(out) in msg and "another plan" in msg
    assert msg.count("plan ") >= 2  # both plans are named
    assert sorted((out / "parts").glob("*")) == parts_before  # nothing written
    assert not (out / "manifest.json").exists()


@pytest.mark.parametrize("name", [".", "..", ".hidden", "a/b"])
def test_a_name_that_is_not_one_plain_path_component_is_refused(tmp_path, name):
    """The name is the default folder results/<name>: "." or ".." wrote into results/.. (the working folder)."""
    path = write(tmp_path, TINY.replace('name = "tiny"', f"name = {name!r}".replace("'", '"')))
    with pytest.raises(sweep.SweepConfigError, match=r"sweep\.name: must be letters") as e:
        sweep.load_config(path)
    assert str(path) in str(e.value)


def test_a_folder_of_other_files_is_never_written_into(tiny_file, tmp_path):
    """--out . in a project (its own sweep.toml, sources) is refused before any write; a new or empty folder,
    or the sweep's own results, are not."""
    project = tmp_path / "project"
    project.mkdir()
    (project / "sweep.toml").write_text("mine")
    (project / "notes.md").write_text("also mine")
    before = sorted(p.name for p in project.iterdir())
    with pytest.raises(ValueError, match="holds files that are not a sweep's results") as e:
        sweep.run(tiny_file, project, chunk_size=CHUNK, progress=False)
    assert str(project) in str(e.value) and "notes.md" in str(e.value)
    assert sorted(p.name for p in project.iterdir()) == before and (project / "sweep.toml").read_text() == "mine"
    empty = tmp_path / "empty"
    empty.mkdir()
    sweep.run(tiny_file, empty, chunk_size=CHUNK, max_scenarios=2, progress=False)
    sweep.run(tiny_file, empty, chunk_size=CHUNK, max_scenarios=2, progress=False)  # its own results: resumed
    afile = tmp_path / "file"
    afile.write_text("x")
    with pytest.raises(ValueError, match="is not a folder"):
        sweep.run(tiny_file, afile, chunk_size=CHUNK, progress=False)


def test_load_refuses_parts_of_another_plan(tiny_file, other_file, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    sweep.run(tiny_file, a, chunk_size=CHUNK, progress=False, max_scenarios=4)
    sweep.run(other_file, b, chunk_size=CHUNK, progress=False)
    # Sweep A's first chunk slipped into sweep B's folder (same chunk ids, same columns).
    os.replace(a / "parts" / "part-00000.parquet", b / "parts" / "part-00000.parquet")
    for partial in (False, True):
        with pytest.raises(ValueError) as e:
            sweep.load(b, partial=partial)
        msg = str(e.value)
        assert str(b) in msg and "part-00000.parquet" in msg and "another plan" in msg, msg
    with pytest.raises(ValueError, match="another plan"):
        sweep.load_aggregates(b)


def test_resume_skips_only_parts_of_the_same_plan(tiny_file, tmp_path):
    out = tmp_path / "r"
    sweep.run(tiny_file, out, chunk_size=CHUNK, progress=False, max_scenarios=4)
    want = sweep.load(out, partial=True)
    stats = sweep.run(tiny_file, out, chunk_size=CHUNK, progress=False, max_scenarios=4)
    assert stats.skipped == 2 and stats.computed == 0
    assert sweep.load(out).equals(want)


# --------------------------------------------------------------------------- 2. one run per folder


_HOLDING_CHILD = """
import os, sys, time
_replace = os.replace
def slow_replace(src, dst):
    _replace(src, dst)
    if str(dst).endswith(".parquet"):
        time.sleep(600)   # hold the folder (and its lock) after the first part; the test kills it
os.replace = slow_replace
from ijoy_jax.apps import cli
sys.exit(cli.main(sys.argv[1:]))
"""


@pytest.mark.slow
def test_a_second_process_on_the_same_out_is_refused(tiny_file, tmp_path):
    """Two real processes on one --out: the second refuses at once with one line naming the holder."""
    out = tmp_path / "shared"
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    first = subprocess.Popen([sys.executable, "-c", _HOLDING_CHILD, "sweep", "run", str(tiny_file), "--out",
                              str(out), "--chunk", str(CHUNK)], env=env, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 180
        while not list((out / "parts").glob("part-*.parquet")) if (out / "parts").exists() else True:
            assert first.poll() is None, "the first run ended before writing a chunk"
            assert time.monotonic() < deadline, "no chunk written in 180 s"
            time.sleep(0.05)
        sessions = len(json.loads((out / "manifest.json").read_text())["sessions"])
        second = subprocess.run([sys.executable, "-m", "ijoy_jax.apps.cli", "sweep", "run", str(tiny_file),
                                 "--out", str(out), "--chunk", str(CHUNK)], env=env, capture_output=True,
                                text=True, timeout=REFUSE_S)
        assert first.poll() is None  # still holding the folder
    finally:
        first.kill()
        first.wait()
    assert second.returncode == 2, second.stderr
    err = second.stderr.strip()
    assert len(err.splitlines()) == 1, err
    assert f"{out} is in use by another run" in err and f"pid {first.pid}" in err, err
    # The refused run wrote nothing: no session, no part of its own.
    assert len(json.loads((out / "manifest.json").read_text())["sessions"]) == sessions
    assert not list((out / "parts").glob("*.tmp")) or all(str(first.pid) in p.name
                                                         for p in (out / "parts").glob("*.tmp"))
    # Once the holder is dead its lock is stale: a rerun takes it over and finishes the sweep.
    stats = sweep.run(tiny_file, out, chunk_size=CHUNK, progress=False)
    assert stats.skipped == 1 and stats.computed == 4
    assert len(sweep.load(out)) == 6
    assert not list((out / "parts").glob("*.tmp"))


def test_a_held_lock_refuses_and_a_dead_holders_lock_is_taken_over(tiny_file, tmp_path):
    import fcntl

    out = tmp_path / "o"
    out.mkdir()
    lock = out / ".lock"
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    lock.write_text(json.dumps({"pid": int(dead.stdout), "host": os.uname().nodename}))  # a dead holder
    with open(lock, "r+") as held:  # another open file: flock conflicts even within this process
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(ValueError, match=f"{out} is in use by another run"):
            sweep.run(tiny_file, out, chunk_size=CHUNK, progress=False, max_scenarios=2)
        assert not (out / "manifest.json").exists()
    # Released (its holder gone): the stale file is taken over.
    sweep.run(tiny_file, out, chunk_size=CHUNK, progress=False, max_scenarios=2)
    assert json.loads(lock.read_text())["pid"] == os.getpid()
    assert len(sweep.load(out)) == 2


def test_members_of_a_multi_process_run_share_the_folder(tiny_file, tmp_path):
    """Process 1 of 2 runs beside a live process 0 (simulated by its locks), but not beside a single run
    nor a second process 1."""
    import fcntl

    out = tmp_path / "m"
    out.mkdir()
    with open(out / ".lock", "a+") as shared, open(out / ".lock-process-00000", "a+") as p0:
        fcntl.flock(shared, fcntl.LOCK_SH | fcntl.LOCK_NB)
        fcntl.flock(p0, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(ValueError, match="in use by another run"):
            sweep.run(tiny_file, out, chunk_size=CHUNK, progress=False)
        with open(out / ".lock-process-00001", "a+") as p1:
            fcntl.flock(p1, fcntl.LOCK_EX | fcntl.LOCK_NB)
            with pytest.raises(ValueError, match="in use by another process with this --process-id"):
                sweep.run(tiny_file, out, chunk_size=CHUNK, progress=False, process_id=1, num_processes=2)
        stats = sweep.run(tiny_file, out, chunk_size=CHUNK, progress=False, process_id=1, num_processes=2)
        assert stats.computed == 2 and stats.skipped == 0


# --------------------------------------------------------------------------- 3. sizes before allocation


@pytest.mark.parametrize("text, key", [
    ("[sweep]\nscenarios_per_cell = 2000000000\n", "sweep.scenarios_per_cell"),
    ('[sweep]\nscenarios_per_cell = 10\n[grid]\n"robot.w" = [1, 2]\n"robot.margin" = [0, 0.01]\n'
     '"robot.step_time" = [0.5, 0.6]\n"robot.rotation_weight" = [1, 2]\n', None),  # small: fine
    ("[sweep]\nseed = 1\n[grid]\n" + "".join(
        f'"robot.{k}" = [{", ".join(str(0.001 * (i + 1)) for i in range(100))}]\n'
        for k in ("w", "margin", "rotation_weight", "step_time", "metrics.slope_weight")), "grid"),
], ids=["2e9-per-cell", "small", "1e10-cells"])
def test_sizes_are_checked_at_validation_before_any_allocation(tmp_path, text, key, monkeypatch):
    # A grid of 1e10 cells or 2e9 scenarios per cell would allocate tens of GiB (or loop) in cells()/scenarios().
    monkeypatch.setattr(sweep_config, "cells", lambda cfg: pytest.fail("cells() ran before the size check"))
    path = write(tmp_path, text)
    if key is None:
        monkeypatch.undo()
        assert sweep.load_config(path).num_scenarios == 160
        return
    t0 = time.perf_counter()
    with pytest.raises(sweep.SweepConfigError) as e:
        sweep.load_config(path)
    assert time.perf_counter() - t0 < 5
    msg = str(e.value)
    assert msg.startswith(f"{path}: {key}: "), msg
    assert "exceed the limit" in msg and "GiB of host memory" in msg and "split the sweep" in msg


def test_tables_beyond_host_memory_are_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(sweep_fits, "_host_memory", lambda: 64 * 2**20)  # a 64 MiB host
    cfg_text = "[sweep]\nscenarios_per_cell = 200000\n"
    with pytest.raises(sweep.SweepConfigError, match=r"sweep.scenarios_per_cell: 2e\+05 scenarios \(1 cells x "
                                                     r"200000 per cell\) need ~.* GiB of host memory"):
        sweep.parse_config(cfg_text)
    monkeypatch.setattr(sweep_fits, "_host_memory", lambda: 64 * 2**30)
    cfg = sweep.parse_config(cfg_text)
    assert sweep_config.table_bytes(cfg) < 0.5 * 64 * 2**30


def test_a_big_plan_reports_its_progress_and_builds_only_what_is_asked(monkeypatch, capsys):
    cfg = sweep.parse_config("[sweep]\nscenarios_per_cell = 40\n[command]\nvx = [0.1, 0.3]\n"
                             '[grid]\n"robot.w" = [1, 2]\n')
    full = sweep.scenarios(cfg)
    monkeypatch.setattr(sweep_expansion, "_PROGRESS_EVERY", 10)
    monkeypatch.setattr(seeding, "_BLOCK", 8)  # progress is reported per vectorised block of replicates
    head = sweep.scenarios(cfg, 13, progress=True)
    err = capsys.readouterr().err
    assert "[ijoy sweep] drawing commands: 13/13 replicates" in err  # blocks end at 8 and 13: 10 crossed at 13
    assert head.equals(full.iloc[:13])
    again = sweep.scenarios(cfg, progress=True)
    assert again.equals(full) and capsys.readouterr().err.count("drawing commands") == 4  # at 16, 24, 32, 40
    # Fixed commands need no generator per replicate, and are the draws' values exactly.
    fixed = sweep.parse_config("[sweep]\nscenarios_per_cell = 5\n[command]\nvx = 0.2\nwz = -0.0\n")
    got = sweep.scenarios(fixed, progress=True)
    assert "drawing commands" not in capsys.readouterr().err
    for r in range(5):
        rng = np.random.default_rng([fixed.seed, 2, r])
        want = [rng.uniform(*fixed.command[k]) for k in sweep.COMMAND_KEYS]
        row = got.loc[r, [f"command.{k}" for k in sweep.COMMAND_KEYS]].to_numpy()
        assert np.array_equal(row, want) and np.array_equal(np.signbit(row), np.signbit(want))


# --------------------------------------------------------------------------- 5. slices of a sweep, extended later

FOUR = TINY.replace("scenarios_per_cell = 3", "scenarios_per_cell = 4")  # 2 cells x 4 replicates
SLICE_CHUNK = CHUNK  # chunks [0, 1] [2, 3] (cell 0), [4, 5] [6, 7] (cell 1): one slice's call spans cells and chunks


@pytest.fixture(scope="module")
def four(tmp_path_factory) -> tuple[Path, pd.DataFrame]:
    """FOUR's sweep file and the table of its whole run (what a folder extended slice by slice must end as)."""
    root = tmp_path_factory.mktemp("four")
    path = write(root, FOUR, "four.toml")
    sweep.run(path, root / "whole", chunk_size=SLICE_CHUNK, progress=False)
    return path, sweep.load(root / "whole")


def _asked(whole: pd.DataFrame, kind: str, n: int) -> set[int]:
    """The scenario ids a slice asks for, from the whole table: the first n replicates of every cell, or ids < n."""
    keep = whole["replicate"] < n if kind == "scenarios_per_cell" else whole["scenario"] < n
    return set(whole.loc[keep, "scenario"].tolist())


def test_two_per_cell_then_the_whole_sweep_equal_a_whole_run(four, tmp_path):
    """The brief's case: a slice of 2 per cell, then the whole sweep into the same folder: the second run
    computes only the 4 scenarios missing and the folder loads exactly as the whole run's (chunk ids too)."""
    path, whole = four
    out = tmp_path / "b"
    first = sweep.run(path, out, chunk_size=SLICE_CHUNK, scenarios_per_cell=2, progress=False)
    assert (first.scenarios, first.computed, first.sweep_scenarios) == (4, 4, 8)
    assert first.complete and not first.sweep_complete
    got = sweep.load(out)
    assert got.groupby("cell")["replicate"].apply(list).tolist() == [[0, 1], [0, 1]]  # every cell, evenly
    man = json.loads((out / "manifest.json").read_text())
    assert man["complete"] is False and man["selection"]["scenarios_per_cell"] == 2
    assert man["sessions"][-1]["truncated"] is True
    second = sweep.run(path, out, chunk_size=SLICE_CHUNK, progress=False)
    assert (second.computed, second.scenarios) == (4, 8) and second.sweep_complete
    pd.testing.assert_frame_equal(sweep.load(out), whole, check_exact=True)
    man = json.loads((out / "manifest.json").read_text())
    assert man["complete"] is True and man["sessions"][-1]["truncated"] is False
    assert {sweep_results.part_plan(p)["hash"] for p in (out / "parts").glob("part-*.parquet")} == {man["plan_hash"]}
    pd.testing.assert_frame_equal(pd.read_parquet(out / "aggregates.parquet"), sweep.aggregate(whole, ["robot.w"]))


SLICES = st.lists(st.one_of(st.tuples(st.just("scenarios_per_cell"), st.integers(1, 5)),
                            st.tuples(st.just("max_scenarios"), st.integers(1, 9))), min_size=1, max_size=3)


@given(slices=SLICES)
@settings(max_examples=4)
def test_any_slices_then_the_whole_sweep_compute_each_scenario_once(four, tmp_path_factory, slices):
    """Slices of either kind in any order, then the whole sweep, into one folder: each run computes only what
    the folder lacks, loads as the union so far (rows equal to the whole run's), and the folder ends as the
    whole run's; a slice never counts as another plan."""
    path, whole = four
    out = tmp_path_factory.mktemp("sliced") / "o"
    done: set[int] = set()
    for kind, n in slices:
        asked = _asked(whole, kind, n)
        stats = sweep.run(path, out, chunk_size=SLICE_CHUNK, progress=False, **{kind: n})
        assert stats.computed == len(asked - done) and stats.scenarios == len(asked), (kind, n)
        done |= asked
        want = whole[whole["scenario"].isin(done)].reset_index(drop=True)
        pd.testing.assert_frame_equal(sweep.load(out), want, check_exact=True)
        man = json.loads((out / "manifest.json").read_text())
        assert man["complete"] is stats.sweep_complete is (len(done) == len(whole))
    stats = sweep.run(path, out, chunk_size=SLICE_CHUNK, progress=False)
    assert stats.computed == len(whole) - len(done) and stats.sweep_complete
    pd.testing.assert_frame_equal(sweep.load(out), whole, check_exact=True)


def test_a_slice_is_marked_incomplete_and_summarize_says_so(four, tmp_path, capsys):
    path, _ = four
    out = tmp_path / "cli"
    run = ["sweep", "run", str(path), "--out", str(out), "--chunk", str(SLICE_CHUNK)]
    assert cli.main([*run, "--scenarios-per-cell", "1"]) == 0
    printed = capsys.readouterr()
    row = json.loads(printed.out)
    assert (row["scenarios"], row["sweep_scenarios"], row["complete"], row["sweep_complete"]) == (2, 8, True, False)
    assert "1 of 4 scenarios per cell (2 of 8 scenarios)" in printed.err and "incomplete" in printed.err
    assert cli.main(["sweep", "summarize", str(out), "--png", str(tmp_path / "s.png")]) == 0
    said = capsys.readouterr().out
    assert said.startswith("incomplete sweep: 2 of 8 scenarios, asked for 1 of 4 scenarios per cell"), said
    assert f"`ijoy sweep run {path} --out {out}` computes the rest" in said
    assert cli.main([*run, "--scenarios-per-cell", "3"]) == 0  # a larger slice: only the 4 new scenarios
    assert json.loads(capsys.readouterr().out)["computed"] == 4
    assert cli.main(run) == 0
    row = json.loads(capsys.readouterr().out)
    assert (row["computed"], row["sweep_complete"]) == (2, True)
    assert json.loads((out / "manifest.json").read_text())["complete"] is True


@pytest.mark.parametrize("args, want", [
    (["--scenarios-per-cell", "0"], "--scenarios-per-cell must be a positive int, got 0"),
    (["--max-scenarios", "-2"], "--max-scenarios must be a positive int, got -2"),
    (["--scenarios-per-cell", "2", "--max-scenarios", "4"], "give --scenarios-per-cell or --max-scenarios, not both"),
])
def test_bad_slice_flags_are_refused_in_one_line_naming_the_flag(tiny_file, tmp_path, capsys, args, want):
    out = tmp_path / "o"
    assert cli.main(["sweep", "run", str(tiny_file), "--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and want in err, err
    assert not out.exists()
    with pytest.raises(ValueError, match="not both"):
        sweep.run(tiny_file, out, scenarios_per_cell=1, max_scenarios=2, progress=False)


def test_an_unfinished_slice_names_its_missing_chunk_and_the_rerun(four, tmp_path):
    path, whole = four
    out = tmp_path / "o"
    sweep.run(path, out, chunk_size=SLICE_CHUNK, scenarios_per_cell=2, progress=False)  # chunks 0 and 2
    (out / "parts" / "part-00002.parquet").unlink()  # ids 4 and 5
    with pytest.raises(sweep.IncompleteSweepError) as e:
        sweep.load(out)
    msg = str(e.value)
    assert "asked for 2 of 4 scenarios per cell" in msg and "1 of 2 chunks missing (chunks 2)" in msg, msg
    assert "rerun `ijoy sweep run` with the same --out and --scenarios-per-cell 2" in msg, msg
    assert sweep.load(out, partial=True)["scenario"].tolist() == [0, 1]
    again = sweep.run(path, out, chunk_size=SLICE_CHUNK, scenarios_per_cell=2, progress=False)
    assert (again.computed, again.skipped) == (2, 1)
    pd.testing.assert_frame_equal(sweep.load(out), whole[whole["replicate"] < 2].reset_index(drop=True),
                                  check_exact=True)


def test_processes_share_a_slice_by_chunk(four, tmp_path):
    """Process I of N computes the slice's rows of its own chunks (chunk % N == I): each part has one writer."""
    path, whole = four
    out = tmp_path / "o"
    stats = [sweep.run(path, out, chunk_size=SLICE_CHUNK, scenarios_per_cell=1, process_id=i, num_processes=3,
                       progress=False) for i in range(3)]  # ids 0 (chunk 0: process 0) and 4 (chunk 2: process 2)
    assert [s.computed for s in stats] == [1, 0, 1] and stats[0].chunks == 2 and stats[-1].complete
    pd.testing.assert_frame_equal(sweep.load(out), whole[whole["replicate"] < 1].reset_index(drop=True),
                                  check_exact=True)

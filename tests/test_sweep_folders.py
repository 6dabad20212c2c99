"""Sweep folders and sweep sizes: parts record their plan, one run per folder (a lock), sizes checked before
any allocation, and a start zone that leaves room for the terrain (issue #22).

Sizes are those of tests/test_sweep.py (2D 60 x 50 map at 4 cm, 19 actions, 6 steps): one compile of the
chunk function for the module.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from ijoy_jax import sweep
from ijoy_jax.sweep import results as sweep_results
from ijoy_jax.terrain import generators as gen
from ijoy_jax.terrain.family import ParamError

TINY = """
[sweep]
name = "tiny"
seed = 3
scenarios_per_cell = 3
num_steps = 6

[robot]
density = 0.25

[terrain]
family = "obstacles"
shape = [60, 50]
resolution = 0.04
max_count = 8

[terrain.params]
count = 6

[command]
vx = [0.1, 0.3]

[grid]
"robot.w" = [0.5, 2.0]
"""
CHUNK = 2  # 6 scenarios -> 3 chunks
# A second run of two real processes gets this long to refuse (it compiles nothing before it does), s.
REFUSE_S = 60


def write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


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

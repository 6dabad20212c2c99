"""Sweep folders and sweep sizes: parts record their plan, one run per folder (a lock), sizes checked before
any allocation, and a start zone that leaves room for the terrain (issue #22).

Sizes are those of tests/test_sweep.py (2D 60 x 50 map at 4 cm, 19 actions, 6 steps): one compile of the
chunk function for the module.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from ijoy_jax import sweep
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

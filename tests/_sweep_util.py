"""The tests' tiny sweep, shared by tests/test_sweep.py and tests/test_sweep_folders.py.

One static configuration (2D 60 x 50 map at 4 cm, 19 actions at density 0.25, 6 steps, exhaustive search)
for both, so each module compiles the chunk function once; they differ only in the cells of the grid.
"""

from __future__ import annotations

from pathlib import Path

_HEAD = """
[sweep]
name = "tiny"
seed = 3
scenarios_per_cell = 3
num_steps = 6
method = "exhaustive"

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
vy = [-0.05, 0.05]
wz = 0.0

[grid]
"robot.w" = [0.5, 2.0]
"""


def tiny_sweep(*, margins: bool) -> str:
    """The tiny sweep's TOML text: ``robot.w`` in [0.5, 2.0] crossed, if ``margins``, with ``robot.margin`` in
    [0.0, 0.05] (4 cells, 12 scenarios; else 2 cells, 6 scenarios). It ends in its ``[grid]`` table, so a test
    may append grid keys."""
    return _HEAD + ('"robot.margin" = [0.0, 0.05]\n' if margins else "")


def write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    """Write a sweep file ``name`` with ``text`` into ``tmp_path``; its path."""
    p = tmp_path / name
    p.write_text(text)
    return p

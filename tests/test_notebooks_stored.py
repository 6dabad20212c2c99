"""The notebooks are stored as they ran: every code cell executed once, in order, without an error, and each
figure a cell draws stored with it, so the documentation (which renders them as stored, never running them)
shows what a reader would see. The slow tier runs each one end to end (nbmake): the stored notebook runs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


def _code_cells(path: Path) -> list[dict]:
    return [c for c in json.loads(path.read_text())["cells"] if c["cell_type"] == "code"]


def _draws(cell: dict) -> bool:
    """Whether a cell makes a matplotlib figure (which the inline backend shows under it)."""
    src = "".join(cell["source"])
    return any(k in src for k in ("plt.show()", "plt.subplots(", "plt.figure("))


def test_there_are_notebooks():
    assert len(NOTEBOOKS) >= 6


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_each_notebook_is_stored_as_it_ran(path):
    cells = [c for c in _code_cells(path) if "".join(c["source"]).strip()]
    counts = [c.get("execution_count") for c in cells]
    assert counts == list(range(1, len(cells) + 1)), f"{path.name}: run it top to bottom and store it ({counts})"
    errors = [o for c in cells for o in c.get("outputs", []) if o.get("output_type") == "error"]
    assert not errors, f"{path.name}: a stored error: {errors[0].get('ename')}: {errors[0].get('evalue')}"
    for c in cells:
        if _draws(c):
            images = [o for o in c.get("outputs", []) if "image/png" in o.get("data", {})]
            assert images, f"{path.name}: a cell that draws stores no figure: {''.join(c['source'])[:80]!r}"
    assert any("image/png" in o.get("data", {}) for c in cells for o in c.get("outputs", [])), (
        f"{path.name}: no figure stored")

"""The README's Python examples run as written: every ```python block, in order, in one namespace (as a reader
pastes them one after the other; a later block may use names an earlier one defined), in a scratch folder.

The simulation example compiles the MJX biped once (a few minutes on a CPU): it is kept small for that.
"""

import re
from pathlib import Path

import numpy as np
import pytest

README = Path(__file__).parents[1] / "README.md"
BLOCK = re.compile(r"^```python\n(.*?)^```$", re.S | re.M)


def python_blocks(text: str) -> list[str]:
    return BLOCK.findall(text)


def test_block_extraction():
    text = "a\n```python\nx = 1\n```\n```sh\nls\n```\n```python\ny = x + 1\n```\n"
    assert python_blocks(text) == ["x = 1\n", "y = x + 1\n"]


@pytest.mark.slow
def test_readme_examples_run(tmp_path, monkeypatch):
    blocks = python_blocks(README.read_text())
    assert len(blocks) >= 4  # use, batching, haptics, simulation
    monkeypatch.chdir(tmp_path)
    ns: dict = {"__name__": "readme"}
    for i, code in enumerate(blocks):
        exec(compile(code, f"README.md python block {i + 1}", "exec"), ns)  # noqa: S102
    # The examples did what their comments say.
    assert bool(ns["choice"].valid) and int(ns["traj"].summary()["steps_taken"]) > 0
    assert ns["y"].shape == ns["signal"].shape and ns["A"].shape == (12, 3) and ns["f"].shape == (3,)
    assert np.all(np.asarray(ns["b"]) >= 0)
    assert (tmp_path / "walk.gif").stat().st_size > 0 and len(ns["frames"]) > 0
    assert ns["batch"].footsteps.shape[:2] == (2, 3)
    # The footstep server's reply is the first example's in-process choice.
    assert ns["reply"].index == int(ns["choice"].index) and ns["reply"].valid
    np.testing.assert_array_equal(ns["reply"].foothold, np.asarray(ns["choice"].foothold))
    # The live drive: three decisions of the scripted stick (at 0, 0.8 and 1.6 s of its 2.4 s), each a step taken.
    assert ns["result"].footsteps().shape == (3, 6) and ns["result"].summary()["steps_taken"] == 3

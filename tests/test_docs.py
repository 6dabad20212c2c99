"""The documentation: the Sphinx build passes with warnings as errors, and no public name is left out.

A docstring that does not parse, a broken cross-reference between pages or a public name missing from
the API reference (``docs/_ext/ijoy_api.py`` checks each module's ``__all__``, or its public functions,
classes and constants) fails the build, so it fails this test.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "docs" / "_ext"))

import ijoy_api  # noqa: E402

pytestmark = pytest.mark.slow  # the Sphinx build runs in a subprocess (about a minute)

BUILD_TIMEOUT_S = 600  # about 45 s on the 2-core CI machine; the margin is for a loaded machine


@pytest.fixture(scope="module")
def html(tmp_path_factory):
    out = tmp_path_factory.mktemp("docs")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-E", "-q", "-b", "html",
           "-d", str(out / "doctrees"), "docs", str(out / "html")]
    proc = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=BUILD_TIMEOUT_S)
    assert proc.returncode == 0, f"sphinx-build failed:\n{proc.stdout[-5000:]}\n{proc.stderr[-10000:]}"
    return out / "html"


def test_build_passes_with_warnings_as_errors(html):
    assert (html / "index.html").exists()


@pytest.mark.parametrize("page, expected", [
    ("api/footcost.html", 'id="ijoy_jax.footcost.foot_cost"'),
    ("api/select.html", 'id="ijoy_jax.select.select_step"'),
    ("api/haptics.html", 'id="ijoy_jax.haptics.repulsive_force"'),
    ("api/ijoy_jax.html", 'href="select.html#ijoy_jax.select.select_step"'),
    ("api/cli.html", "small sizes, for a smoke test"),  # ijoy bench --help
    ("api/server.html", 'id="ijoy_jax.server.Client"'),
    ("api/live.html", 'id="ijoy_jax.live.drive"'),  # the function; its module is ijoy_jax.live.loop
    ("api/stick.html", 'id="ijoy_jax.stick.scripted_commands"'),
    ("api/sweep.html", 'id="ijoy_jax.sweep.recorded.read_commands"'),
    ("api/sim.html", 'id="ijoy_jax.sim.mjx_biped.MjxBiped"'),  # ijoy drive --robot mjx's body
    ("api/sim.html", 'id="ijoy_jax.sim.walk_step.tick"'),  # the walker's step in public parts (walker re-exports)
    ("api/robots.html", "forward/backward step of HRP-2"),  # a constant's docstring, from the module assigning it
    ("drive.html", "A recorded drive as a sweep"),
    ("sweeps.html", "plan.inputs"),  # the section on a person's commands (sweeps/README.md)
    ("server.html", "unsupported_version"),
    ("benchmarks.html", "Headline figures"),
    ("benchmarks_history.html", "lab notebook"),
    ("readme.html", "Set up"),
    ("notebooks/quickstart.html", "quickstart"),
])
def test_pages_have_their_content(html, page, expected):
    assert expected in (html / page).read_text(encoding="utf-8")


def test_public_api_is_fully_documented(html):
    # objects.inv is what the build documented; compare it by object identity with what the code exports.
    from sphinx.util.inventory import InventoryFile

    with open(html / "objects.inv", "rb") as f:
        inv = InventoryFile.load(f, "", lambda base, uri: uri)
    names = [name for kind, entries in inv.items() if kind.startswith("py:") and kind != "py:module"
             for name in entries]
    documented = {n: ijoy_api._resolve(n) for n in names}
    assert ijoy_api.missing({n: o for n, o in documented.items() if o is not None}) == []


def test_missing_reports_a_public_name_left_out():
    modules = ["ijoy_jax", "ijoy_jax.select", "ijoy_jax.robots"]
    complete = {f"{m}.{n}": obj for m in modules for n, obj in ijoy_api.public_names(m).items()}
    assert ijoy_api.missing(complete, modules) == []
    without = {k: v for k, v in complete.items() if not k.endswith(".select_step")}
    assert ijoy_api.missing(without, modules) == ["ijoy_jax.select_step", "ijoy_jax.select.select_step"]
    # A constant is matched by name as well as identity (LEFT = 1 is not any other documented 1).
    without_left = {k: v for k, v in complete.items() if not k.endswith(".LEFT")}
    assert ijoy_api.missing(without_left, modules) == ["ijoy_jax.LEFT", "ijoy_jax.robots.LEFT"]


def test_each_public_object_has_one_home_at_its_shortest_public_path():
    home = ijoy_api.homes(ijoy_api.public_modules())
    assert home[("ijoy_jax", "foot_cost")] == ("ijoy_jax.footcost", "foot_cost")
    assert home[("ijoy_jax.footcost.xla", "foot_cost")] == ("ijoy_jax.footcost", "foot_cost")
    assert home[("ijoy_jax", "Terrain")] == ("ijoy_jax.terrain", "Terrain")
    assert home[("ijoy_jax", "LEFT")] == ("ijoy_jax.robots", "LEFT")
    assert "ijoy_jax.apps.cli" not in ijoy_api.public_modules()


def test_cli_help_covers_every_subcommand():
    paths = [p for p, _ in ijoy_api._walk(ijoy_api.cli_parser(), "ijoy")]
    for expected in ["ijoy", "ijoy bench", "ijoy sweep run", "ijoy sweep summarize", "ijoy sim render", "ijoy tune"]:
        assert expected in paths

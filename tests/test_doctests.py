"""Every example in the package's docstrings runs and shows what it says: the API reference's examples are
checked as the README's commands are (tests/test_docs.py), so an example that drifts from the code fails here.

One test per module (the examples of one module share its imports and state, as in a reader's session); in the
slow tier, as some examples compile programs (about 2 minutes on two cores for the whole package).
"""

from __future__ import annotations

import doctest
import importlib
import io
import pkgutil

import pytest

import ijoy_jax

MODULES = sorted(m.name for m in pkgutil.walk_packages(ijoy_jax.__path__, "ijoy_jax."))


def _examples(name: str) -> list[doctest.DocTest]:
    module = importlib.import_module(name)
    return [t for t in doctest.DocTestFinder().find(module, name) if t.examples]


def test_the_package_has_examples_to_check():
    """The walk over the package finds its modules (a broken walk would check nothing and pass)."""
    assert {"ijoy_jax.select", "ijoy_jax.sim.model", "ijoy_jax.footcost.xla", "ijoy_jax.robots.commands"} <= set(
        MODULES
    )
    assert sum(len(t.examples) for t in _examples("ijoy_jax.footcost.xla")) > 0


@pytest.mark.slow
@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)  # as pytest's doctests: "0.05..." is a float32 0.05
    out = io.StringIO()
    for test in _examples(name):
        runner.run(test, out=out.write)
    assert runner.failures == 0, out.getvalue()

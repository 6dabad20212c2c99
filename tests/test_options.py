"""ijoy_jax.apps.options: the ``--set NAME=VALUE`` syntax that ``ijoy bench walk`` and ``ijoy tune`` share."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ijoy_jax.apps.options import assignments, number_assignments


def test_assignments_split_at_the_first_equals_and_strip_names():
    got = assignments([" metrics.support_limit =0.003", "names=[\"w\", \"margin\"]", "w=1", "w=2", "x=a=b"], "w=1")
    assert got == {"metrics.support_limit": "0.003", "names": "[\"w\", \"margin\"]", "w": "2", "x": "a=b"}
    assert assignments(None, "w=1") == {} and assignments([], "w=1") == {}


@pytest.mark.parametrize("item", ["w", "=1", "  =1", ""])
def test_an_item_without_a_name_or_equals_is_refused_with_the_example(item):
    with pytest.raises(ValueError, match=r"--set takes NAME=VALUE, e\.g\. w=1; got"):
        assignments([item], "w=1")


@given(st.lists(st.tuples(st.text("abc._", min_size=1).filter(str.strip), st.text()), max_size=5))
def test_every_well_formed_item_round_trips(pairs):
    items = [f"{name}={value}" for name, value in pairs]
    want = {name.strip(): value for name, value in pairs}  # a later item wins
    assert assignments(items, "w=1") == want


def test_number_assignments_name_the_item_an_unknown_name_and_a_non_number():
    names = ("w", "metrics.support_limit")
    assert number_assignments(["w=2", "metrics.support_limit=3e-3"], names, "w=1") == {
        "w": 2.0, "metrics.support_limit": 0.003}
    with pytest.raises(ValueError, match=r"--set 'margin=0\.1': 'margin' is not one of \['w', 'metrics"):
        number_assignments(["margin=0.1"], names, "w=1")
    with pytest.raises(ValueError, match=r"--set 'w=abc': 'abc' is not a number"):
        number_assignments(["w=abc"], names, "w=1")
    with pytest.raises(ValueError, match=r"--set takes NAME=VALUE, e\.g\. w=1; got 'w'"):
        number_assignments(["w"], names, "w=1")

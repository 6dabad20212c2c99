"""The terrain-family registry: each family's validation of parameter values and its extra metrics."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ijoy_jax import sweep
from ijoy_jax.sweep import config as sweep_config
from ijoy_jax.terrain import generators as gen
from ijoy_jax.terrain.family import ParamError
from ijoy_jax.terrain.objects import bar_crossings

SHAPE, RES = (48, 40), 0.05  # 2.4 m x 2.0 m; default start point (0.36, 1.0) m
FOOT = (0.242, 0.13)  # HRP-2's foot length and width, m

FIELDS = [(name, field) for name, fam in gen.FAMILIES.items() for field in fam.rules]


def _bad_values(rule, max_count):
    """(value, words of the reason) pairs that the rule must refuse."""
    bad = [("x", "must be a number"), (True, "must be a number"), (None, "must be a number")]
    if rule.integer:
        bad += [(2.5, "must be an integer"), (float("nan"), "must be an integer")]
    else:
        bad += [(float("nan"), "must be a number")]
        if not rule.allow_inf:
            bad += [(math.inf, "must be finite"), (-math.inf, "must be finite")]
    if math.isfinite(rule.lo):
        bad += [(type(rule.lo)(rule.lo - 1), "must be >=")]
    if math.isfinite(rule.hi):
        bad += [(rule.hi + 0.5, "must be <=")]
    if rule.count and max_count is not None:
        bad += [(max_count + 1, "exceeds max_count")]
    return bad


@pytest.mark.parametrize("name, field", FIELDS, ids=[f"{n}.{f}" for n, f in FIELDS])
def test_every_field_refuses_bad_values_naming_the_field(name, field):
    fam = gen.FAMILIES[name]
    rule = fam.rules[field]
    default = getattr(fam.params(), field)
    assert fam.check(field, default, max_count=fam.max_count) == default  # defaults pass
    for value, reason in _bad_values(rule, fam.max_count):
        with pytest.raises(ParamError) as e:
            fam.check(field, value, max_count=fam.max_count)
        assert e.value.field == field and e.value.cls == fam.params.__name__
        assert str(e.value).startswith(f"{fam.params.__name__}.{field}: "), e.value
        assert reason in e.value.reason, (value, e.value)


def test_every_family_has_a_rule_of_each_kind_it_needs():
    for name, fam in gen.FAMILIES.items():
        fam.validate(fam.params(), max_count=fam.max_count)  # defaults are valid
        assert fam.rules["start_radius"].lo == 0.0
        counts = [f for f, r in fam.rules.items() if r.count]
        # A family with static slots has exactly one count they bound; one without has none.
        assert len(counts) == (fam.max_count is not None), name
        assert fam.count_field == (counts[0] if counts else None)
        for f, r in fam.rules.items():
            assert r.at_most is None or r.at_most in fam.rules, (name, f)
    assert [n for n, fam in gen.FAMILIES.items() for r in fam.rules.values() if r.allow_inf] == ["rough"]
    # Everything the sweep refused by name before the registry is still refused (sizes, ranges, start radius).
    for fam in gen.FAMILIES.values():
        for f, r in fam.rules.items():
            was = (f.endswith(("_min", "_max")) and not f.startswith("yaw")) or f in (
                "size", "spacing", "width", "run", "length", "start_radius")
            assert r.lo >= 0 or not was, (fam.name, f)
    with pytest.raises(ParamError, match="unknown field"):
        gen.FAMILIES["flat"].check("height", 1.0)


@pytest.mark.parametrize("name", list(gen.FAMILIES))
def test_ordered_ranges_are_checked(name):
    fam = gen.FAMILIES[name]
    pairs = [(f, r.at_most) for f, r in fam.rules.items() if r.at_most]
    for lo, hi in pairs:
        p = fam.params().replace(**{lo: 0.5, hi: 0.25})
        with pytest.raises(ParamError, match=f"impossible range: {lo} \\(0.5\\) > {hi} \\(0.25\\)") as e:
            fam.validate(p)
        assert e.value.field == lo
        fam.validate(fam.params().replace(**{lo: 0.25, hi: 0.25}))  # equal ends are a fixed value


def test_generators_still_only_refuse_non_finite_values():
    """Generators clip; ranges are a config's business (a negative jitter still generates)."""
    gen.stairs(0, gen.StairParams(run_jitter=-0.01), shape=(8, 8))
    gen.rough(0, gen.RoughParams(obstacle_above=math.inf), shape=(8, 8))
    with pytest.raises(ValueError, match="BarParams.width must be finite"):
        gen.bars(0, gen.BarParams(width=math.inf), shape=(8, 8))


def test_sweep_config_asks_the_family():
    """A sweep file's terrain values get the family's rule and reason, with the file and key."""
    bad = '[terrain]\nfamily = "bars"\n[terrain.params]\nposition_jitter = -0.05\n'
    with pytest.raises(sweep.SweepConfigError, match=r"terrain.params.position_jitter: must be >= 0, got -0.05"):
        sweep.parse_config(bad)
    bad = '[terrain]\nfamily = "stairs"\n[sweep]\nrandom_samples = 2\n[random]\n"terrain.num_steps" = [1, 3]\n'
    with pytest.raises(sweep.SweepConfigError, match="counts are integers"):
        sweep.parse_config(bad)
    ok = sweep.parse_config('[terrain]\nfamily = "rough"\n[terrain.params]\nobstacle_above = inf\n')
    assert ok.terrain_params["obstacle_above"] == math.inf
    assert not hasattr(sweep_config, "_COUNT_FIELDS")  # no name heuristics left in the sweep


# --------------------------------------------------------------------------- extra metrics


@pytest.mark.parametrize("name", list(gen.FAMILIES))
def test_metrics_come_from_the_registry_with_their_columns(name):
    fam = gen.FAMILIES[name]
    feet = jnp.array([[0.5, 1.1, 0.0], [0.5, 0.9, 0.0]], jnp.float32)
    out = jax.eval_shape(
        lambda k: fam.metrics(k, fam.params(), feet, *FOOT, shape=SHAPE, resolution=RES), jax.random.key(0)
    )
    assert tuple(out) == fam.metric_names and all(v.shape == () for v in out.values())
    assert (name == "bars") == bool(fam.metric_names)


def test_bar_metrics_are_bar_crossings_of_the_posed_bars_inside_jit():
    fam = gen.FAMILIES["bars"]
    p = gen.BarParams(count=2, first=0.6, spacing=0.8)  # bars near x = 0.96 and 1.76 m

    @jax.jit
    def metrics(key, x):
        feet = jnp.stack([jnp.stack([x, 1.1, 0.0]), jnp.stack([x, 0.9, 0.0])])
        return fam.metrics(key, p, feet, *FOOT, shape=SHAPE, resolution=RES)

    key = jax.random.key(4)
    boxes = gen.objects("bars", key, p, shape=SHAPE, resolution=RES).boxes
    for x, crossed in [(0.36, 0), (1.4, 1), (2.3, 2)]:
        got = metrics(key, jnp.float32(x))
        feet = np.array([[x, 1.1, 0.0], [x, 0.9, 0.0]], np.float32)
        want = bar_crossings(boxes, feet, *FOOT)
        assert {k: int(v) for k, v in got.items()} == {k: int(v) for k, v in want.items()}
        assert int(got["bars_crossed"]) == crossed and bool(got["crossed"]) == (crossed == 2)


def test_sweep_columns_are_the_registrys():
    union = [m for fam in gen.FAMILIES.values() for m in fam.metric_names]
    assert sweep.EXTRA_METRICS == gen.METRIC_NAMES == tuple(dict.fromkeys(union)) == ("bars_crossed", "crossed")

"""Tests of ijoy_jax.limits: every size a caller gives is checked against one memory budget before anything is
allocated, with the same bounds in the library, the CLI, the sweep file and the server."""

from __future__ import annotations

import re
import struct
import zlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ijoy_jax as ij
from ijoy_jax import limits
from ijoy_jax.server.schema import Limits
from ijoy_jax.sweep import config as sweep_config
from ijoy_jax.tune import forward


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.integers(-3, 5000), st.integers(-3, 5000))
def test_a_map_shape_is_two_positive_ints_within_the_cell_budget(nx, ny):
    ok = nx >= 1 and ny >= 1 and nx * ny <= limits.MAX_MAP_CELLS
    if ok:
        assert limits.check_map_shape((nx, ny)) == (nx, ny)
        assert limits.check_map_shape((np.int64(nx), float(ny))) == (nx, ny)  # integral floats and NumPy ints
    else:
        with pytest.raises(ValueError, match="MAX_MAP_CELLS" if min(nx, ny) >= 1 else "positive"):
            limits.check_map_shape((nx, ny), "shape")


@pytest.mark.parametrize("shape", [(2.5, 3), ("a", 3), (3,), None, (True, 4), (1e300, 1)])
def test_a_map_shape_that_is_not_two_integers_is_named(shape):
    with pytest.raises(ValueError, match="two integers|MAX_MAP_CELLS"):
        limits.check_map_shape(shape, "shape")


def test_the_bounds_are_one_set_shared_by_the_sweep_file_and_the_server():
    assert sweep_config.MAX_MAP_CELLS is limits.MAX_MAP_CELLS and sweep_config.MAX_NUM_STEPS is limits.MAX_NUM_STEPS
    assert sweep_config.MAX_DENSITY is limits.MAX_DENSITY and sweep_config.MAX_ACTIONS is limits.MAX_ACTIONS
    assert Limits().max_cells <= limits.MAX_MAP_CELLS and Limits().max_window_cells <= limits.MAX_WINDOW_CELLS
    Limits(max_cells=limits.MAX_MAP_CELLS, max_window_cells=limits.MAX_WINDOW_CELLS)  # the bounds themselves
    with pytest.raises(ValueError, match="MAX_MAP_CELLS"):
        Limits(max_cells=limits.MAX_MAP_CELLS + 1)
    with pytest.raises(ValueError, match="MAX_WINDOW_CELLS"):
        Limits(max_window_cells=limits.MAX_WINDOW_CELLS + 1)
    # the action-set bound is HRP-2's lattice at the density bound, so both describe one table
    assert ij.robots.hrp2_actions(limits.MAX_DENSITY).shape == (limits.MAX_ACTIONS, 3)


def test_maps_too_large_are_refused_before_they_are_built():
    huge = (100_000, 100_000)
    with pytest.raises(ValueError, match="MAX_MAP_CELLS"):
        ij.terrain.flat(huge)
    with pytest.raises(ValueError, match="MAX_MAP_CELLS"):
        ij.terrain.generators.generate("rough", jax.random.key(0), shape=huge)
    over = np.ones((2049, 2048), bool)  # 4 MB here; ~250 MB of FootCost tables after
    with pytest.raises(ValueError, match="terrain grid 2049 x 2048 .*MAX_MAP_CELLS"):
        ij.terrain.from_arrays(None, over, 0.02)
    with pytest.raises(ValueError, match="MAX_MAP_CELLS"):
        ij.terrain.from_image(over.astype(np.uint8), 0.02)
    with pytest.raises(ValueError, match="MAX_MAP_CELLS"):
        forward.ForwardConfig(shape=huge)  # checked as it is built
    assert ij.terrain.flat((2048, 2048)).shape == (2048, 2048)  # the bound itself


def _png_header_only(path, width: int, height: int) -> None:
    """A PNG whose header claims ``width x height`` 8-bit grey pixels, with one tiny (wrong-sized) data chunk:
    what a decoder reads before allocating (a decompression bomb costs its size only once decoded)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 16))
                     + chunk(b"IEND", b""))


@pytest.mark.parametrize("size", [(3000, 3000), (30_000, 30_000)])  # above our bound; above Pillow's bomb limit
def test_an_image_too_large_is_refused_from_its_header(tmp_path, size):
    path = tmp_path / "big.png"
    _png_header_only(path, *size)
    with pytest.raises(ValueError, match="MAX_MAP_CELLS") as e:
        ij.terrain.from_image(path, 0.02)
    assert str(path) in str(e.value)


def test_action_sets_beyond_the_budget_are_refused_before_the_lattice_is_built():
    with pytest.raises(ValueError, match="MAX_DENSITY"):
        ij.robots.hrp2(density=limits.MAX_DENSITY * 1.01)
    with pytest.raises(ValueError, match="MAX_DENSITY"):
        ij.robots.hrp2(density=50)  # once 354 s of building and a 40 GiB table
    with pytest.raises(ValueError, match="4867 actions are above ijoy_jax.limits.MAX_ACTIONS"):
        ij.robots.hrp2(density=limits.MAX_DENSITY, reach=0.3)  # a longer reach: more actions at a density
    with pytest.raises(ValueError, match="MAX_ACTIONS"):
        ij.robots.make_robot(np.zeros((limits.MAX_ACTIONS + 1, 3)), foot_length=0.25, foot_width=0.14, margin=0.02,
                             step_time=0.8)


def test_rollouts_longer_than_the_budget_are_refused_before_compiling():
    terrain = ij.terrain.flat((40, 40))
    robot = ij.robots.hrp2()
    start = ij.robots.start_stance(robot, 0.4, 0.4)
    for n in (10**12, limits.MAX_NUM_STEPS + 1):
        with pytest.raises(ValueError, match="MAX_NUM_STEPS"):
            ij.rollout(terrain, robot, start, [0.1, 0.0, 0.0], num_steps=n)
    for n in (0, -1, 2.0, True):
        with pytest.raises(ValueError, match="num_steps must be a positive int"):
            ij.rollout(terrain, robot, start, [0.1, 0.0, 0.0], num_steps=n)
    assert limits.check_num_steps(np.int32(7)) == 7


def test_a_map_too_fine_for_the_robots_windows_is_refused_naming_the_coarsest_fix():
    robot = ij.robots.hrp2()
    fine = ij.terrain.flat((400, 400), resolution=0.001)
    with pytest.raises(ValueError, match="footprint window is 553 cells across, above .*MAX_WINDOW_CELLS"):
        ij.select_step(fine, robot, [0.2, 0.2, 0.0], -1, [0.1, 0.0, 0.0])
    # at the finest resolution the message names, the footprint window fits
    finest = 2 * robot.max_radius / (limits.MAX_WINDOW_CELLS - 1)
    assert limits.check_window(robot.max_radius, finest * 1.001, "footprint") <= limits.MAX_WINDOW_CELLS
    for res in (0.0, 1e-320, -1.0):
        with pytest.raises(ValueError, match="MAX_WINDOW_CELLS"):
            limits.check_window(0.1, res, "footprint")


def test_an_action_index_outside_the_set_is_refused_where_concrete_and_flagged_where_traced():
    terrain = ij.terrain.flat((60, 60))
    robot = ij.robots.hrp2()
    stance = np.array([0.6, 0.6, 0.0])
    steps = np.array([[0.7, 0.8, 0.0], [0.7, 0.8, 0.0]])
    for bad in ([10**6, 0], [-5, 0], [robot.num_actions, 0]):
        with pytest.raises(ValueError, match=r"action_index must be in \[0, 496\)"):
            ij.foot_cost_terms(terrain, robot, stance, -1, steps, action_index=np.array(bad))
    with pytest.raises(TypeError, match="integers"):
        ij.foot_cost_terms(terrain, robot, stance, -1, steps, action_index=np.array([0.5, 1.0]))
    with pytest.raises(ValueError, match="shape"):
        ij.foot_cost_terms(terrain, robot, stance, -1, steps, action_index=np.zeros(3, int))
    traced = jax.jit(lambda a: ij.foot_cost_terms(terrain, robot, stance, -1, steps, action_index=a))
    out = traced(jnp.array([10**6, 3]))
    assert np.isinf(out.unsupported[0]) and np.isinf(out.total[0])
    ref = ij.foot_cost_terms(terrain, robot, stance, -1, steps, action_index=np.array([3, 3]))
    assert float(out.total[1]) == float(ref.total[1]) and float(out.unsupported[1]) == 0.0
    out = traced(jnp.array([-5, 3]))
    assert np.isinf(out.total[0]) and float(out.total[1]) == float(ref.total[1])


@pytest.mark.parametrize("args, match", [
    (["--warm-up", "100000x100000"], r"--warm-up 100000x100000: shape \[100000, 100000\] .*max_cells = 1048576"),
    (["--warm-up", "2000x2000@0.02"], r"--warm-up 2000x2000: .*raise --max-cells"),
    (["--max-cells", str(2**23)], "Limits.max_cells must be <= ijoy_jax.limits.MAX_MAP_CELLS"),
    (["--density", "1e9"], "density must be <= ijoy_jax.limits.MAX_DENSITY"),
])
def test_the_server_refuses_sizes_beyond_its_limits_before_building_anything(args, match, capsys):
    """Once OOM-killed at 16 GB (a warm-up of 1e10 cells) or a raw ArrayMemoryError (density 1e9): one line,
    before the robot, the listener or a map exists."""
    from ijoy_jax.apps import cli

    rc = cli.main(["serve", "--port", "0", *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len([e for e in err if e.startswith("ijoy: error: ")]) == 1, err
    assert any(re.search(match, e) for e in err), err

"""Walking benchmark per terrain family (issue #20): ``ijoy bench walk``, the perfect robot next to the MJX biped.

On one GPU (H100 or H200), the whole default run (11 families x 2 command kinds x 1024 robots x 30 steps,
one MJX compile; 0.28 G physics steps, several minutes)::

    ijoy bench walk --batch 1024 --steps 30 --json out/walk.json --plot out/walk.png

(``python -m ijoy_jax.apps.cli bench walk ...`` where the ``ijoy`` script is not installed; ``--families``
takes a comma-separated subset, e.g. to split the run in two). A smoke test on a CPU (4 robots, 6 steps,
two to three minutes on two cores, a minute of it the one MJX compile)::

    ijoy bench walk --quick --json /tmp/walk.json --plot /tmp/walk.png

Every robot walks HRP-2's joystick loop (margin 2 cm, 496 actions, ``method="ordered"``) on its own
5 m x 2 m map of 2 cm cells (250 x 100), drawn from its family's parameter range (:data:`FAMILIES`),
standing at ``x = 0.5 m`` on the centre line (``y = 1 m``) facing +x, for ``steps`` steps, once with
a new random command every step inside the action set's range (:func:`ijoy_jax.robots.random_commands`)
and once with a held forward command (:data:`FORWARD` m/s). Each (family, commands) pair runs the
paper's perfect robot (:func:`ijoy_jax.control.rollout`, vmapped) and the simulated biped
(:func:`ijoy_jax.sim.walker.rollout_batch`) on the same maps with the same commands, and gives one row
per walker (:func:`aggregate`): falls, stops, progress along +x, obstacle contacts, placement and
sole-tilt errors, and the timings (compile time from JAX's own compile events, run time, physics steps/s).

One compile for everything. Every family is a 2.5D map (``has_height=True``; 2D clutter is stored as the
2.5D map the physics makes of it) of one grid shape and resolution, every command schedule is
(B, steps, 3), the robots share one action set, and one :class:`ijoy_jax.sim.walker.Sim` serves every
family, so :func:`ijoy_jax.sim.walker.rollout_batch` compiles once and every later family only changes
traced heights and free masks; each row says how many new programs its call compiled
(:func:`ijoy_jax.sim.walker.compiled_programs`) and the last record gives the total. A family whose robot
has another action set (the stairs, with ``robots.hrp2(reach=0.30)``) compiles once more.
The Sim's height field spans :data:`HEIGHT_RANGE` (the stairs and 10 deg slopes rise or fall up to
0.9 m over the map).

Outputs: JSON records (:func:`run`), the Markdown table of BENCHMARKS.md (:func:`markdown_table`) and a
bar plot of falls, stops and progress per family, perfect and simulated side by side (:func:`plot`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
import os
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from types import MappingProxyType
from typing import Any

import ijoy_jax.sim  # noqa: F401  before mujoco: headless EGL, and mjx imported without the warp lines

# isort: split
import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import control, robots, select
from ijoy_jax import terrain as terrain_mod
from ijoy_jax.extras import require
from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.prng import as_key
from ijoy_jax.sim import model
from ijoy_jax.sim import walker as W
from ijoy_jax.terrain import Terrain, generators, scene

SIZE = (5.0, 2.0)
"""Map extent (m) along x (the walking direction) and y."""
RESOLUTION = 0.02
"""Default cell size (m): 250 x 100 cells."""
START = (0.5, 1.0)
"""Where every robot stands (m): the midpoint of its feet, facing +x."""
START_RADIUS = 0.35
"""Start zone radius (m, the generators' default): it holds HRP-2's double stance and is flat (or the plane)."""
HEIGHT_RANGE = (model.BipedParams.z_lo, model.BipedParams.z_hi)
"""z_lo, z_hi (m) of the Sim's height field (the biped's defaults): every family's heights lie inside (tested)."""
FORWARD = 0.25
"""Held forward command (m/s): the paper's action set's fastest, 0.2 m steps of 0.8 s; on open ground the robot
reaches the far edge of the 5 m map after about 21 steps and marks time there."""
COMMANDS = ("random", "forward")
SLOPE_DEG = (2.0, 10.0)
"""Slope angles (deg), uniform per map."""
ROUGH_RMS = (0.01, 0.03)
"""Rough ground RMS height (m), uniform per map."""
ROUGH_CORRELATION = (0.10, 0.20)
"""Rough ground correlation length (m), uniform per map."""
STAIR_RISE = (0.05, 0.15)
"""Stair riser heights (m), uniform per map (negative for stairs_down)."""
STAIR_RUNS = (0.30, 0.40)
"""Stair tread depths (m), one of these per map (equally likely). A 24.2 cm foot with its 2 cm margins needs
0.282 m, and without turning the feet stay on the action set's 5 cm lattice of x, so a tread holds a foothold
only at some phases of that lattice: with risers at :data:`STAIR_FIRST` + k x tread, a tread of 0.30 m takes
one 0.30 m step and one of 0.40 m two (0.30 + 0.10); the perfect robot climbs both to the top, while on
treads of 0.35 m it marks time before the second riser (measured; tests/test_experiments.py section 7 has
the geometry)."""
STAIR_COUNT = 6
"""Risers per stair (6 x 15 cm = 0.9 m at most, inside :data:`HEIGHT_RANGE`)."""
STAIR_FIRST = 0.6
"""Distance (m) from the start point to the first riser."""
STAIR_REACH = 0.30
"""``robots.hrp2(reach=...)`` for the stairs (m)."""
STAIR_FORWARD = 0.375
"""Held forward command on the stairs (m/s): :data:`STAIR_REACH` per 0.8 s step, the longest step, which is
the one that crosses a riser (at :data:`FORWARD`, 0.2 m steps, the robot marks time before the first one)."""
PLATFORM_HEIGHT_MIN = 0.02
"""Lowest platform (m); the highest is the robot's ``max_step_height`` (0.10 m for HRP-2)."""
IMAGE_PIXELS = (512, 512)
"""Size of the generated ground image (pixels = cells: 10.24 m square at 2 cm)."""
IMAGE_RMS = 0.015
"""RMS height (m) of the generated ground image (at 2 cm, with the 1 cm roughness limit under a foot, the
selector finds a way on hardly any window: 0.15-0.4 m of progress in 30 steps, measured)."""
IMAGE_WAVELENGTHS = (2.0, 50.0)
"""Shortest and longest wavelength (pixels) of the generated ground image's spectrum (4 cm to 1 m at 2 cm)."""
IMAGE_EXPONENT = 1.8
"""The generated ground's amplitude spectrum falls as ``f ** -IMAGE_EXPONENT``: a fractional Brownian surface of
Hurst exponent 0.8 (fractal dimension 2.2), within the range reported for natural ground."""
IMAGE_SCALE = 1e-4
"""Metres per grey level of the generated 16-bit ground image (0.1 mm; 0 m is grey level 32768)."""


# --------------------------------------------------------------------------------------------- the families


@dataclasses.dataclass(frozen=True, eq=False)
class WalkFamily:
    """One terrain family of the benchmark.

    Fields::

      name: the family's name.
      make: ``make(key, batch, *, shape, resolution) -> Terrain`` with a leading batch axis: ``batch`` maps
        of ``shape`` (nx, ny) cells of ``resolution`` m (origin (0, 0)), each drawn from the family's range.
      ranges: the parameter ranges, in words (for the table).
      reach: None for ``robots.hrp2()``; else the ``reach`` (m) of ``robots.hrp2(reach=...)``.
      forward: the held forward command (m/s) of the family's "forward" rows; None: the run's ``forward``.
    """

    name: str
    make: Callable[..., Terrain]
    ranges: str
    reach: float | None = None
    forward: float | None = None

    def robot(self) -> robots.Robot:
        """The family's robot: ``robots.hrp2()``, or ``robots.hrp2(reach=...)`` for a family with its own reach."""
        return robots.hrp2() if self.reach is None else robots.hrp2(reach=self.reach)

    def maps(self, key, batch: int, *, shape, resolution: float) -> Terrain:
        """:attr:`make` as one jitted program per family, batch and grid (a new key reuses it): the same maps
        (to float32 rounding) as ``make`` op by op, which compiles each of its hundreds of small ops."""
        return _jitted(self.make)(key, batch, shape=tuple(int(n) for n in shape), resolution=float(resolution))


@functools.cache
def _jitted(make: Callable[..., Terrain]) -> Callable[..., Terrain]:
    return jax.jit(make, static_argnums=1, static_argnames=("shape", "resolution"))


def grid_shape(resolution: float = RESOLUTION) -> tuple[int, int]:
    """(nx, ny) cells of the 5 m x 2 m map at ``resolution`` m (which must divide both extents)."""
    res = float(resolution)
    if not (math.isfinite(res) and res > 0):
        raise ValueError(f"resolution must be a positive number of metres, got {resolution!r}")
    cells = tuple(int(round(s / res)) for s in SIZE)
    if any(abs(c * res - s) > 1e-9 for c, s in zip(cells, SIZE, strict=True)) or min(cells) < 2:
        raise ValueError(f"resolution {res} m must divide the {SIZE[0]} m x {SIZE[1]} m map into whole cells")
    return cells


def start_zone(shape, resolution: float) -> dict[str, float]:
    """The generators' start-zone fields (fractions of the map, radius in m) that put the start at :data:`START`."""
    return dict(start_x=START[0] / (shape[0] * resolution), start_y=START[1] / (shape[1] * resolution),
                start_radius=START_RADIUS)


def start_stances(robot: robots.Robot, batch: int) -> jax.Array:
    """(batch, 2, 3) start feet (left, right): side by side at :data:`START`, facing +x, ``p0`` apart."""
    return jnp.broadcast_to(robots.start_stance(robot, *START), (batch, 2, 3))


def _uniform(key, batch, lo, hi) -> jax.Array:
    return jax.random.uniform(key, (batch,), jnp.float32, lo, hi)


def _keys(key, batch: int):
    return jax.random.split(as_key(key), batch)


def flat(key, batch: int, *, shape, resolution: float) -> Terrain:
    """Level ground at height 0 (2.5D)."""
    params = generators.FlatParams(**start_zone(shape, resolution))
    return generators.batch("flat", _keys(key, batch), params, shape=shape, resolution=resolution, has_height=True)


CLUTTER = dict(count=17, size_min=0.04, size_max=0.12)
"""2D clutter: `sweeps/margin_physics.toml`'s obstacles at its density (14 on 8 m^2, here 17 on 10 m^2)."""


def clutter2d(key, batch: int, *, shape, resolution: float) -> Terrain:
    """2D obstacles (the margin sweep's clutter), stored as the 2.5D map the physics makes of them.

    A 2D map's obstacle cells stand ``BipedParams.obstacle_height`` (0.1 m) tall in the simulation
    (:func:`ijoy_jax.sim.model.physical_heights`); here they carry that height and stay obstacles
    (``free`` False), so the map shares the other families' 2.5D compile. The selector chooses the steps it
    chooses on the 2D map (tested): a foothold's grown footprint must be free either way, so its height
    terms are 0, and 0.1 m obstacles do not exceed the swing corridor's 0.1 m clearance.
    """
    params = generators.ObstacleParams(**CLUTTER, **start_zone(shape, resolution))
    maps = generators.batch("obstacles", _keys(key, batch), params, shape=shape, resolution=resolution,
                            has_height=False, max_count=CLUTTER["count"])
    height = jax.vmap(lambda t: model.physical_heights(t, model.BipedParams().obstacle_height))(maps)
    return Terrain(height=height, free=maps.free, origin=maps.origin, resolution=maps.resolution, has_height=True)


def _slope(direction: Callable[[jax.Array, int], jax.Array]):
    def make(key, batch: int, *, shape, resolution: float) -> Terrain:
        k_angle, k_dir = jax.random.split(as_key(key))
        angle = jnp.deg2rad(_uniform(k_angle, batch, *SLOPE_DEG))
        params = generators.SlopeParams(angle=angle, direction=direction(k_dir, batch),
                                        **start_zone(shape, resolution))
        return generators.batch("slope", _keys(key, batch), params, shape=shape, resolution=resolution,
                                has_height=True)

    return make


def _cross_direction(key, batch):
    return jnp.where(jax.random.bernoulli(key, 0.5, (batch,)), 0.5, -0.5).astype(jnp.float32) * jnp.pi


uphill = _slope(lambda key, batch: jnp.zeros((batch,), jnp.float32))
uphill.__doc__ = "A plane rising along +x at an angle uniform in :data:`SLOPE_DEG`, 0 at the start."
downhill = _slope(lambda key, batch: jnp.full((batch,), jnp.pi, jnp.float32))
downhill.__doc__ = "A plane falling along +x at an angle uniform in :data:`SLOPE_DEG`, 0 at the start."
cross = _slope(_cross_direction)
cross.__doc__ = "A plane rising to the robot's left or right (+-y, half each) at an angle in :data:`SLOPE_DEG`."


def rough_params(key, batch: int, *, shape, resolution: float) -> generators.RoughParams:
    """The (batch,) RMS heights and correlation lengths :func:`rough` draws from ``key`` (and its start zone)."""
    k_amp, k_len = jax.random.split(jax.random.fold_in(as_key(key), 0))
    return generators.RoughParams(amplitude=_uniform(k_amp, batch, *ROUGH_RMS),
                                  correlation_length=_uniform(k_len, batch, *ROUGH_CORRELATION),
                                  **start_zone(shape, resolution))


def rough(key, batch: int, *, shape, resolution: float) -> Terrain:
    """Gaussian rough ground, RMS uniform in :data:`ROUGH_RMS`, correlation length in :data:`ROUGH_CORRELATION`.

    The start zone is a flat pad at 0 that ramps into the field over one correlation length
    (:func:`ijoy_jax.terrain.generators.rough`); the parameters are :func:`rough_params`.
    """
    params = rough_params(key, batch, shape=shape, resolution=resolution)
    return generators.batch("rough", _keys(jax.random.fold_in(as_key(key), 1), batch), params, shape=shape,
                            resolution=resolution, has_height=True)


STONES = dict(size=0.36, spacing=0.40, jitter=0.0, top_jitter=0.01, gap_height=-0.5)
"""Stepping stones (m): 36 cm square stones at 40 cm pitch (4 cm gaps, 0.5 m deep), tops jittered by +-1 cm, centres
not jittered. Their rows along +x alternate between two phases half a pitch (20 cm) apart: see :func:`stones`."""


PAD_FRONT = 0.16
"""How far (m) the stones' start pad reaches ahead of :data:`START` (the standing feet's grown footprints end
0.141 m ahead)."""


def stone_row(y, pitch) -> jax.Array:
    """Row index of a lateral position ``y`` (m): rows of :func:`stones` are ``pitch`` wide, row 0 just left of
    the start's centre line (``START[1] <= y < START[1] + pitch``)."""
    return jnp.floor((y - START[1]) / pitch).astype(jnp.int32)


def stones(key, batch: int, *, shape, resolution: float) -> Terrain:
    """Stepping stones that HRP-2's 496-action lattice can step along (a brick pattern of square stones).

    Why this layout. An action puts the swing foot at most 0.2 m ahead of the stance foot, and a
    foothold's footprint grown by its margin (0.282 m long) must lie on one stone (on the cells lying
    wholly on it). On the square lattice of :func:`ijoy_jax.terrain.generators.stepping_stones` the
    two feet stand on stones of one column, so reaching the next stone of a row needs a step of
    gap + 0.282 m ahead of the other foot: never reachable. Here every row is that generator's lattice
    (:data:`STONES`), but alternate rows come from two generator calls whose lattices are half a pitch
    apart along x, so the left and right feet's rows are staggered by 20 cm: each step goes from a
    stone of one row to the next stone of the other row. A walk then advances half a pitch per step,
    so the pitch is at most twice the longest step (0.4 m), and the stones must hold a grown footprint
    with some play: 36 cm stones (2.9 cm of play either way), 4 cm gaps. Rows are 40 cm apart, so the
    feet stand 0.23-0.33 m apart. Row 0's first stone is centred 0.2 m ahead of the start, where the
    first 0.2 m step lands; the start zone is a pad at the stones' top, cut off just ahead of the
    standing feet (:data:`PAD_FRONT`). Measured with the perfect robot, the held forward command at
    the fastest (0.25 m/s: 0.2 m steps) crosses every map; slower commands are met with 0.1-0.15 m
    steps that fall short of the next stone, and the robot marks time before the first gap.
    """
    p = STONES["spacing"]
    zone = start_zone(shape, resolution)
    width_x, width_y = shape[0] * resolution, shape[1] * resolution
    first = START[0] + 0.2  # centre of row 0's first stone ahead of the start (the first left step lands there)
    row_y = (START[1] + 0.5 * p) / width_y  # row 0's centre line, as a fraction of the map
    k_a, k_b = jax.random.split(as_key(key))

    def lattice(k, x0):
        params = generators.SteppingStoneParams(
            **{n: v for n, v in STONES.items()}, start_x=x0 / width_x, start_y=row_y, start_radius=0.0)
        return generators.batch("stepping_stones", _keys(k, batch), params, shape=shape, resolution=resolution,
                                has_height=True)

    a, b = lattice(k_a, first), lattice(k_b, first + 0.5 * p)
    centres = terrain_mod.flat(shape, resolution, has_height=True).cell_centres()
    even = stone_row(centres[..., 1], p) % 2 == 0
    # The start zone, cut off just ahead of the standing feet (their grown footprints end 0.141 m ahead), so
    # the first stones are where the stagger puts them and no foothold straddles the pad and a stone.
    pad = (jnp.sum((centres - jnp.asarray(START)) ** 2, axis=-1) <= zone["start_radius"] ** 2) & (
        centres[..., 0] < START[0] + PAD_FRONT)
    height = jnp.where(pad, jnp.float32(0.0), jnp.where(even, a.height, b.height))
    return a.replace(height=height, free=a.free & b.free)


def platforms(key, batch: int, *, shape, resolution: float, max_height: float | None = None) -> Terrain:
    """Single-lane raised platforms: two boxes in a row along +x beside the centre line, under one foot's lane.

    Per map: a lane (left or right of the centre line, half each); two platforms 0.8-1.2 m long and
    0.4-0.5 m wide whose inner edge runs 1 cm beside the centre line, the first starting 0.9-1.3 m
    from the map's origin (0.4-0.8 m ahead of the start), the second 0.3-0.6 m after it; each top
    uniform in [:data:`PLATFORM_HEIGHT_MIN`, ``max_height``] (default: HRP-2's ``max_step_height``,
    0.1 m), so one foot walks on it and the other beside it. Boxes are surfaces drawn with
    :func:`ijoy_jax.terrain.scene.rasterize`.
    """
    if max_height is None:
        with jax.ensure_compile_time_eval():  # the preset's leaves are constants, also under jit
            max_height = float(np.max(np.asarray(robots.hrp2().max_step_height)))
    top = float(max_height)
    ground = flat(key, batch, shape=shape, resolution=resolution)
    u = jax.random.uniform(as_key(key), (batch, 8), jnp.float32)
    side = jnp.where(u[:, 0] < 0.5, 1.0, -1.0)
    length = 0.8 + 0.4 * u[:, 1:3]  # (B, 2)
    width = 0.4 + 0.1 * u[:, 3:5]
    x0 = 0.9 + 0.4 * u[:, 5]
    x1 = x0 + length[:, 0] + 0.3 + 0.3 * u[:, 6]
    height = PLATFORM_HEIGHT_MIN + (top - PLATFORM_HEIGHT_MIN) * jax.random.uniform(
        jax.random.fold_in(as_key(key), 1), (batch, 2), jnp.float32)
    cx = jnp.stack([x0 + 0.5 * length[:, 0], x1 + 0.5 * length[:, 1]], axis=1)
    cy = START[1] + side[:, None] * (0.01 + 0.5 * width)
    boxes = jnp.stack([cx, cy, jnp.zeros_like(cx), length, width, height], axis=-1)  # (B, 2, 6)
    return jax.vmap(lambda t, b: scene.rasterize(t, boxes=b))(ground, boxes)


def _stairs(sign: float):
    def make(key, batch: int, *, shape, resolution: float) -> Terrain:
        k_rise, k_run, k_map = jax.random.split(as_key(key), 3)
        run = jax.random.choice(k_run, jnp.asarray(STAIR_RUNS, jnp.float32), (batch,))
        params = generators.StairParams(rise=sign * _uniform(k_rise, batch, *STAIR_RISE), run=run,
                                        num_steps=STAIR_COUNT, first=STAIR_FIRST, **start_zone(shape, resolution))
        return generators.batch("stairs", _keys(k_map, batch), params, shape=shape, resolution=resolution,
                                has_height=True, max_count=STAIR_COUNT)

    return make


stairs_up = _stairs(1.0)
stairs_up.__doc__ = "Stairs rising along +x: 6 risers of :data:`STAIR_RISE`, treads of :data:`STAIR_RUNS`."
stairs_down = _stairs(-1.0)
stairs_down.__doc__ = "Stairs falling along +x: 6 risers of :data:`STAIR_RISE`, treads of :data:`STAIR_RUNS`."


def ground_image(seed: int = 0, pixels=IMAGE_PIXELS) -> np.ndarray:
    """(rows, cols) uint16 image of natural rough ground: fractal noise.

    White noise (NumPy, seeded) filtered to an amplitude spectrum ``f ** -IMAGE_EXPONENT`` between the wavelengths
    :data:`IMAGE_WAVELENGTHS` (pixels), scaled to :data:`IMAGE_RMS` m RMS and stored at
    :data:`IMAGE_SCALE` m per grey level around grey level 32768. Deterministic given ``seed``.
    """
    rows, cols = (int(p) for p in pixels)
    rng = np.random.default_rng(seed)
    fy = np.fft.fftfreq(rows)[:, None]
    fx = np.fft.rfftfreq(cols)[None, :]
    f = np.hypot(fx, fy)
    lo, hi = 1.0 / IMAGE_WAVELENGTHS[1], 1.0 / IMAGE_WAVELENGTHS[0]
    amp = np.where((f >= lo) & (f <= hi), np.maximum(f, lo) ** -IMAGE_EXPONENT, 0.0)
    field = np.fft.irfft2(np.fft.rfft2(rng.standard_normal((rows, cols))) * amp, s=(rows, cols))
    field *= IMAGE_RMS / field.std()
    return np.clip(np.round(field / IMAGE_SCALE) + 32768, 0, 65535).astype(np.uint16)


def write_ground_png(path, seed: int = 0, pixels=IMAGE_PIXELS) -> str:
    """Write :func:`ground_image` as a 16-bit greyscale PNG; returns the path."""
    from PIL import Image

    Image.fromarray(ground_image(seed, pixels)).save(path)
    return os.fspath(path)


def load_ground(path=None, *, resolution: float = RESOLUTION, height_scale: float = IMAGE_SCALE) -> Terrain:
    """The ground image as one Terrain (:func:`ijoy_jax.terrain.from_image`, a pixel per cell).

    ``path`` None: the generated image (:func:`write_ground_png`, seed 0) through a temporary file.
    """
    if path is not None:
        return terrain_mod.from_image(path, resolution, height_scale=height_scale)
    with tempfile.TemporaryDirectory() as tmp:
        return terrain_mod.from_image(write_ground_png(os.path.join(tmp, "ground.png")), resolution,
                                      height_scale=height_scale)


def window_offsets(key, batch: int, image_shape, shape) -> jax.Array:
    """(batch, 2) int32 cell offsets (ix, iy) of each robot's window in the image, uniform over the image."""
    span = np.asarray([image_shape[0] - shape[0] + 1, image_shape[1] - shape[1] + 1], np.int32)  # static
    if int(span.min()) < 1:
        raise ValueError(f"ground image {tuple(image_shape)} cells is smaller than the map {tuple(shape)}")
    return jax.random.randint(as_key(key), (batch, 2), 0, span, jnp.int32)


def image(key, batch: int, *, shape, resolution: float, ground: Terrain | None = None) -> Terrain:
    """Windows of a height image of natural rough ground (:func:`load_ground`), one per robot.

    Each robot gets the window of ``shape`` cells at :func:`window_offsets` (from ``key``), shifted so the
    start point is at height 0 and flattened within :data:`START_RADIUS` of it, ramping into the image
    over the next 0.2 m (a start pad, as :func:`ijoy_jax.terrain.generators.rough` makes).
    """
    ground = load_ground(resolution=resolution) if ground is None else ground
    offsets = window_offsets(key, batch, ground.shape, shape)
    centres = terrain_mod.flat(shape, resolution, has_height=True).cell_centres()
    dist = jnp.sqrt(jnp.sum((centres - jnp.asarray(START)) ** 2, axis=-1))
    taper = jnp.clip((dist - START_RADIUS) / 0.2, 0.0, 1.0)
    i0 = jnp.asarray([int(START[0] / resolution), int(START[1] / resolution)])

    def one(off):
        h = jax.lax.dynamic_slice(ground.height, (off[0], off[1]), shape)
        return taper * (h - h[i0[0], i0[1]])

    height = jax.vmap(one)(offsets)
    return Terrain(height=height, free=jnp.ones(height.shape, bool), origin=jnp.zeros((batch, 2), jnp.float32),
                   resolution=float(resolution), has_height=True)


FAMILIES: Mapping[str, WalkFamily] = MappingProxyType({f.name: f for f in (
    WalkFamily("flat", flat, "level ground"),
    WalkFamily("clutter2d", clutter2d, "17 obstacles 4-12 cm, 0.1 m tall (2D)"),
    WalkFamily("uphill", uphill, "2-10 deg up along +x"),
    WalkFamily("downhill", downhill, "2-10 deg down along +x"),
    WalkFamily("cross", cross, "2-10 deg across (+-y)"),
    WalkFamily("rough", rough, "RMS 1-3 cm, correlation 10-20 cm"),
    WalkFamily("stones", stones, "36 cm stones, 4 cm gaps, rows staggered by 20 cm"),
    WalkFamily("platforms", platforms, "one lane, 2-10 cm high"),
    WalkFamily("stairs_up", stairs_up, "6 risers 5-15 cm, treads 30 or 40 cm", reach=STAIR_REACH,
               forward=STAIR_FORWARD),
    WalkFamily("stairs_down", stairs_down, "6 risers 5-15 cm down, treads 30 or 40 cm",
               reach=STAIR_REACH, forward=STAIR_FORWARD),
    WalkFamily("image", image, "fractal ground image (PNG), 1.5 cm RMS"),
)})
"""The benchmark's terrain families by name, in table order; read-only."""


# --------------------------------------------------------------------------------------------- the benchmark

WALKERS = ("perfect", "mjx")
"""The perfect robot (:func:`ijoy_jax.control.perfect_walker`) and the MJX biped (:mod:`ijoy_jax.sim.walker`)."""
COMPILE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration",
                  "/jax/core/compile/backend_compile_duration")
"""JAX's own events (:mod:`jax.monitoring`) whose durations add up to a program's compile time: tracing of a
top-level program, lowering to MLIR, and the backend's compile."""


@contextlib.contextmanager
def compile_seconds():
    """Context manager yielding a one-element list that accumulates the seconds JAX spends compiling inside it."""
    total = [0.0]

    def listener(event, duration, **_):
        if event in COMPILE_EVENTS:
            total[0] += float(duration)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield total
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


def forward_commands(batch: int, steps: int, speed: float = FORWARD) -> jax.Array:
    """(batch, steps, 3) the held forward command ``(speed, 0, 0)`` (m/s, m/s, rad/s) for every robot and step."""
    return jnp.broadcast_to(jnp.asarray([speed, 0.0, 0.0], jnp.float32), (batch, steps, 3))


def commands_for(kind: str, key, robot: robots.Robot, batch: int, steps: int, speed: float = FORWARD) -> jax.Array:
    """(batch, steps, 3) commands of a kind: "random" (:func:`ijoy_jax.robots.random_commands`, a new one every
    step inside the action set's range) or "forward" (:func:`forward_commands`)."""
    if kind == "random":
        return robots.random_commands(key, robot, batch, steps)
    if kind == "forward":
        return forward_commands(batch, steps, speed)
    raise ValueError(f"commands must be one of {COMMANDS}, got {kind!r}")


def _percentile(values, q) -> float | None:
    values = np.asarray(values, np.float64).ravel()
    return float(np.percentile(values, q)) if values.size else None


def touchdown_feet(traj: control.Trajectory, start, mask) -> np.ndarray:
    """(B, 2, 3) the feet after the last step of ``mask`` (B, T): the start feet with each masked step's
    foothold (``traj.footsteps``, the measured touch-down of a simulated robot) put down by its swing foot
    (``traj.sides``: +1 left, row 0). With ``mask = traj.taken`` and the perfect robot it is ``traj.feet``."""
    steps, sides, mask = np.asarray(traj.footsteps), np.asarray(traj.sides), np.asarray(mask, bool)
    feet = np.array(np.broadcast_to(np.asarray(start, np.float64), (mask.shape[0], 2, 3)))
    rows = np.arange(mask.shape[0])
    for k in range(mask.shape[1]):
        row = np.where(sides[:, k] > 0, 0, 1)
        feet[rows, row] = np.where(mask[:, k, None], steps[:, k], feet[rows, row])
    return feet


def aggregate(traj: control.Trajectory, start) -> dict[str, Any]:
    """The benchmark's numbers for a batch of rollouts (leading axis B on every leaf of ``traj``).

    A simulated robot's steps count while it stands: a step "made" is one taken that ended with the
    robot standing (``taken`` and not ``log.fallen``); after a fall the loop may go on choosing steps
    that the robot no longer makes. The perfect robot never falls: its steps made are those taken.

    Keys: ``robots``; ``fell`` / ``fell_pct`` (robots that fell; 0 for the perfect robot); ``stops`` /
    ``stops_pct``, robots that stopped walking before the last step without falling (no valid foothold:
    the loop stops, Algorithm 1's StopWalking); ``progress_mean_m`` / ``progress_min_m``, how far the
    midpoint of the feet moved along +x from ``start`` ((B, 2, 3) or (2, 3) start feet) to their
    touch-downs after the last step made (:func:`touchdown_feet`); ``steps_made_mean``;
    ``footholds_on_obstacles`` (steps made onto an obstacle cell, bare footprint); ``unsupported_decisions``.
    With a simulated robot's log (:class:`ijoy_jax.sim.walker.StepLog`), also ``obstacle_contacts``
    (steps begun standing during which a sole or shin touched an obstacle cell) and
    ``robots_with_contact``; over every step made by every robot, ``placement_error_mean_m`` /
    ``_p95_m``, ``yaw_error_p95_rad`` and ``tilt_error_p95_rad`` (the angle between a landed sole's normal
    and its foothold's, ``StepLog.tilt_error``). These are None for the perfect robot (not measured).
    """
    taken = np.asarray(traj.taken, bool)
    b = taken.shape[0]
    log = traj.log
    fallen = np.zeros_like(taken) if log is None else np.asarray(log.fallen, bool)
    made = taken & ~fallen
    upright = np.concatenate([np.ones((b, 1), bool), ~fallen[:, :-1]], axis=1)  # standing as the step began
    fell = fallen.any(axis=1)
    stops = np.asarray(traj.stopped, bool).any(axis=1) & ~fell
    start = np.broadcast_to(np.asarray(start, np.float64), (b, 2, 3))
    progress = touchdown_feet(traj, start, made)[:, :, 0].mean(axis=1) - start[:, :, 0].mean(axis=1)
    out: dict[str, Any] = dict(
        robots=int(b),
        fell=int(fell.sum()),
        fell_pct=100.0 * float(fell.mean()),
        stops=int(stops.sum()),
        stops_pct=100.0 * float(stops.mean()),
        progress_mean_m=float(progress.mean()),
        progress_min_m=float(progress.min()),
        steps_made_mean=float(made.sum(axis=1).mean()),
        footholds_on_obstacles=int((np.asarray(traj.on_obstacle, bool) & made).sum()),
        unsupported_decisions=int(np.asarray(traj.unsupported, bool).sum()),
    )
    if log is None:
        out.update(obstacle_contacts=None, robots_with_contact=None, placement_error_mean_m=None,
                   placement_error_p95_m=None, yaw_error_p95_rad=None, tilt_error_p95_rad=None)
        return out
    contact = np.asarray(log.obstacle_contact, bool) & upright
    err = np.asarray(log.placement_error, np.float64)[made]
    out.update(
        obstacle_contacts=int(contact.sum()),
        robots_with_contact=int(contact.any(axis=1).sum()),
        placement_error_mean_m=float(err.mean()) if err.size else None,
        placement_error_p95_m=_percentile(err, 95),
        yaw_error_p95_rad=_percentile(np.asarray(log.yaw_error, np.float64)[made], 95),
        tilt_error_p95_rad=_percentile(np.asarray(log.tilt_error, np.float64)[made], 95),
    )
    return out


def _to_host(tree):
    return jax.tree_util.tree_map(np.asarray, tree)


def _stack_robot(robot: robots.Robot, batch: int) -> robots.Robot:
    return jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (batch, *np.shape(x))), robot)


def perfect_rollouts(terrains: Terrain, robot: robots.Robot, starts, commands, *, num_steps: int,
                     targets=None, refine: bool = False, kernel: str = "xla") -> control.Trajectory:
    """The perfect robot on B maps: one jitted ``vmap`` of :func:`ijoy_jax.control.rollout` (``method="ordered"``).

    ``terrains``, ``starts`` (B, 2, 3) and ``commands`` (B, num_steps, 3) are batched; the robot and its
    targets (:func:`ijoy_jax.make_targets`, built when None) are shared, and traced: new maps, commands or
    robot values reuse the compiled program. ``refine``: each lattice choice refined to a continuous foothold
    (:mod:`ijoy_jax.refine`; one more program). ``kernel``: FootCost's implementation (``select_step``'s).
    """
    targets = select.make_targets(robot) if targets is None else targets
    return _perfect_jit(terrains, robot, starts, commands, targets, num_steps=int(num_steps), refine=bool(refine),
                        kernel=kernel)


@functools.partial(jax.jit, static_argnames=("num_steps", "refine", "kernel"))
def _perfect_jit(terrains, robot, starts, commands, targets, *, num_steps: int, refine: bool = False,
                 kernel: str = "xla"):
    def one(t, s, c):
        return control.rollout(t, robot, s, c, num_steps, method="ordered", targets=targets, refine=refine,
                               kernel=kernel)

    return jax.vmap(one)(terrains, starts, commands)


def _timed(fn, *args, **kwargs):
    """Run ``fn(*args, **kwargs)`` to completion; return (result on the host, compile seconds, run seconds)."""
    with compile_seconds() as compiled:
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn(*args, **kwargs))
        wall = time.perf_counter() - t0
    return _to_host(out), compiled[0], max(wall - compiled[0], 0.0)


def simulated_rollouts(sim: W.Sim, terrains: Terrain, robot: robots.Robot, starts, commands, *, num_steps: int,
                       chunk: int, targets=None, refine: bool = False, kernel: str = "xla"):
    """The MJX biped on B maps, ``chunk`` rollouts per :func:`ijoy_jax.sim.walker.rollout_batch` call
    (``kernel``: FootCost's implementation in its selector).

    Every call has ``chunk`` rollouts (the last chunk wraps round to the first maps, its extra rollouts
    dropped), so all calls share one compiled program. Returns (trajectory on the host with leading axis B,
    compile seconds, run seconds).
    """
    total = int(np.shape(starts)[0])
    targets = select.make_targets(robot) if targets is None else targets
    stacked = _stack_robot(robot, chunk)
    parts, comp, run_s = [], 0.0, 0.0
    for lo in range(0, total, chunk):
        idx = np.arange(lo, lo + chunk) % total
        part, c, r = _timed(W.rollout_batch, sim, jax.tree_util.tree_map(lambda x, idx=idx: x[idx], terrains),
                            stacked, starts[idx], commands[idx], num_steps=num_steps, method="ordered",
                            targets=targets, refine=refine, kernel=kernel)
        parts.append(jax.tree_util.tree_map(lambda a, n=min(chunk, total - lo): a[:n], part))
        comp, run_s = comp + c, run_s + r
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a), *parts), comp, run_s


def _device_info() -> dict[str, str]:
    import mujoco

    return dict(device=str(jax.devices()[0].device_kind), jax=jax.__version__, mujoco=mujoco.__version__)


def check_options(families: Sequence[str] | None, *, batch: int, steps: int, commands: Sequence[str],
                  resolution: float, chunk: int | None, walkers: Sequence[str], forward: float,
                  kernel: str = "xla") -> list[str]:
    """Validate :func:`run`'s options before any compute; returns the family names in table order."""
    names = list(FAMILIES) if families is None else list(families)
    unknown = [n for n in names if n not in FAMILIES]
    if unknown or not names:
        raise ValueError(f"unknown terrain families {unknown}; known: {', '.join(FAMILIES)}")
    for label, value in (("batch", batch), ("steps", steps), ("chunk", 1 if chunk is None else chunk)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{label} must be a positive int, got {value!r}")
    bad = [c for c in commands if c not in COMMANDS]
    if bad or not commands:
        raise ValueError(f"commands must be some of {COMMANDS}, got {list(commands)}")
    bad = [w for w in walkers if w not in WALKERS]
    if bad or not walkers:
        raise ValueError(f"walkers must be some of {WALKERS}, got {list(walkers)}")
    if not (math.isfinite(forward) and 0 <= forward):
        raise ValueError(f"forward speed must be a finite number of m/s >= 0, got {forward!r}")
    if kernel not in select.KERNELS:
        raise ValueError(f"kernel must be one of {select.KERNELS}, got {kernel!r}")
    grid_shape(resolution)
    return [n for n in FAMILIES if n in names]


def check_robot_leaves(values: Mapping[str, float] | None) -> dict[str, float]:
    """Validate :func:`run`'s ``robot_leaves`` (names in :data:`ijoy_jax.robots.SELECTOR_LEAVES`, values that
    :func:`ijoy_jax.robots.check_robot` accepts on the preset); returns them as a dict of floats."""
    values = {} if values is None else dict(values)
    unknown = [n for n in values if n not in robots.SELECTOR_LEAVES]
    if unknown:
        raise ValueError(f"unknown robot leaves {unknown}; the choice's leaves: {', '.join(robots.SELECTOR_LEAVES)}")
    for name, value in values.items():
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise ValueError(f"robot.{name} must be a number, got {value!r}")
    out = {n: float(v) for n, v in values.items()}
    robots.check_robot(robots.set_leaves(robots.hrp2(), out))  # names the first bad value
    return out


def run(families: Sequence[str] | None = None, *, batch: int = 1024, steps: int = 30,
        commands: Sequence[str] = COMMANDS, resolution: float = RESOLUTION, seed: int = 0, chunk: int | None = None,
        walkers: Sequence[str] = WALKERS, forward: float = FORWARD, refine: bool = False, kernel: str = "xla",
        robot_leaves: Mapping[str, float] | None = None,
        emit: Callable[[dict], None] | None = None) -> list[dict[str, Any]]:
    """Walk ``batch`` robots per family and command kind with each walker; one record per row (and skips).

    Args:
      families: names in :data:`FAMILIES` (None: all), run in the registry's order.
      batch: robots (maps) per family; steps: steps per rollout.
      commands: some of :data:`COMMANDS`; the same maps serve both kinds.
      resolution: cell size (m) of the 5 m x 2 m maps.
      seed: maps and random commands: a family's come from ``fold_in(seed, i)``, i its index in
        :data:`FAMILIES`, so it walks the same maps and commands whichever families run beside it.
      chunk: simulated rollouts per jitted call (equal chunks, one compile): default ``batch`` up to 1024 on an
        accelerator (a rollout holds tens of MB of selector windows; on an H100 1024 ran 1.6x the physics
        steps/s of 512), 32 on a CPU.
      walkers: some of :data:`WALKERS`.
      forward: the held forward command (m/s) of families without their own (:attr:`WalkFamily.forward`).
      refine: both walkers refine each lattice choice to a continuous foothold (:mod:`ijoy_jax.refine`,
        ``refine=True`` of :func:`ijoy_jax.control.rollout` and :func:`ijoy_jax.sim.walker.rollout_batch`).
      kernel: FootCost's implementation in both walkers' selector (:data:`ijoy_jax.select.KERNELS`): "xla", or
        "pallas", the fused kernel (on a GPU it compiles the MJX program several seconds faster, BENCHMARKS.md;
        on a CPU it is interpreted, slowly). Recorded in each row.
      robot_leaves: values of the selector's robot leaves (:data:`ijoy_jax.robots.SELECTOR_LEAVES` by dotted
        name, e.g. ``{"metrics.support_limit": 0.003}``) set on every family's robot: both walkers choose with
        them; traced, so they reuse the compiled programs. Recorded in each row as ``robot_leaves``.
      emit: called with each record as soon as it exists (e.g. to print JSON lines).

    Returns:
      Records (dicts) with ``name`` "walk": ``family``, ``commands``, ``walker``, the numbers of
      :func:`aggregate`, ``compile_s`` and ``run_s`` (compile time from JAX's compile events, run time the
      rest of the wall time), ``physics_steps_per_s`` (simulated: robots x (steps + the standing step) x
      physics steps per step / run time) or ``decisions_per_s`` (perfect), ``new_compiles`` (programs the
      simulated rows' calls added to :func:`ijoy_jax.sim.walker.compiled_programs`), and the setup;
      ``skipped`` (the reason) for a family whose robot cannot be built; and a last record ``name``
      "walk_compiles" with the totals.
    """
    names = check_options(families, batch=batch, steps=steps, commands=commands, resolution=resolution,
                          chunk=chunk, walkers=walkers, forward=forward, kernel=kernel)
    leaves = check_robot_leaves(robot_leaves)
    if not isinstance(refine, (bool, np.bool_)):
        raise ValueError(f"refine must be True or False, got {refine!r}")
    refine = bool(refine)
    shape = grid_shape(resolution)
    if chunk is None:
        chunk = min(batch, 32 if jax.default_backend() == "cpu" else 1024)
    chunk = min(int(chunk), batch)
    emit = (lambda row: None) if emit is None else emit
    rows: list[dict[str, Any]] = []

    def record(row):
        rows.append(row)
        emit(row)

    base = robots.hrp2()
    sim = None
    if "mjx" in walkers:
        sim = W.make_sim(shape, resolution, robot=base)
    info = _device_info()
    programs0, t_all = W.compiled_programs(), time.perf_counter()
    perfect_compile = 0.0
    setup = dict(batch=batch, steps=steps, resolution=resolution, shape=list(shape), chunk=chunk, seed=seed,
                 forward_m_s=forward, refine=refine, kernel=kernel, robot_leaves=leaves, **info)
    key = jax.random.key(seed)
    for name in names:
        fam = FAMILIES[name]
        try:
            robot = robots.set_leaves(fam.robot(), leaves)
        except TypeError as e:
            record(dict(name="walk", family=name, skipped=f"robots.hrp2(reach={fam.reach}) failed: {e}", **setup))
            continue
        robot_name = "hrp2()" if fam.reach is None else f"hrp2(reach={fam.reach})"
        k_map, k_cmd = jax.random.split(jax.random.fold_in(key, list(FAMILIES).index(name)))
        t0 = time.perf_counter()
        maps = jax.block_until_ready(fam.maps(k_map, batch, shape=shape, resolution=resolution))
        maps_s = time.perf_counter() - t0
        lo, hi = float(jnp.min(maps.height)), float(jnp.max(maps.height))
        if sim is not None and (lo < HEIGHT_RANGE[0] or hi > HEIGHT_RANGE[1]):
            raise ValueError(f"family {name}: heights {lo:.3f}..{hi:.3f} m leave the Sim's range {HEIGHT_RANGE}")
        starts = start_stances(robot, batch)
        targets = select.make_targets(robot)
        speed = forward if fam.forward is None else fam.forward
        for kind in commands:
            cmd = jax.block_until_ready(
                commands_for(kind, jax.random.fold_in(k_cmd, COMMANDS.index(kind)), robot, batch, steps, speed))
            common = dict(name="walk", family=name, commands=kind, robot=robot_name, ranges=fam.ranges,
                          maps_s=round(maps_s, 3), **dict(setup, forward_m_s=speed))
            if "perfect" in walkers:
                traj, comp, run_s = _timed(perfect_rollouts, maps, robot, starts, cmd, num_steps=steps,
                                           targets=targets, refine=refine, kernel=kernel)
                perfect_compile += comp
                record(dict(common, walker="perfect", **aggregate(traj, starts), compile_s=round(comp, 3),
                            run_s=round(run_s, 4), decisions_per_s=batch * steps / max(run_s, 1e-9)))
            if sim is not None:
                before = W.compiled_programs()
                traj, comp, run_s = simulated_rollouts(sim, maps, robot, starts, cmd, num_steps=steps, chunk=chunk,
                                                       targets=targets, refine=refine, kernel=kernel)
                physics = batch * (steps + 1) * sim.substeps * sim.cfg.ticks_per_step
                record(dict(common, walker="mjx", **aggregate(traj, starts), compile_s=round(comp, 3),
                            run_s=round(run_s, 4), physics_steps_per_s=physics / max(run_s, 1e-9),
                            new_compiles=W.compiled_programs() - before))
    record(dict(name="walk_compiles", mjx_programs=W.compiled_programs() - programs0,
                mjx_calls=sum(1 for r in rows if r.get("walker") == "mjx") * -(-batch // chunk),
                mjx_compile_s=round(sum(r["compile_s"] for r in rows if r.get("walker") == "mjx"), 3),
                perfect_compile_s=round(perfect_compile, 3), wall_s=round(time.perf_counter() - t_all, 2), **setup))
    return rows


def compiled_perfect_programs() -> int:
    """How many programs :func:`perfect_rollouts` holds compiled in this process (one per robot action-set size,
    batch and ``num_steps``; new maps, commands and robot values reuse them)."""
    return compiled_count(_perfect_jit)


# --------------------------------------------------------------------------------------------- table and plot


def _pairs(rows: Sequence[dict]) -> list[tuple[str, str, dict | None, dict | None, str | None]]:
    """(family, commands, perfect row, simulated row, skip reason) per family and command kind, in run order."""
    out: dict[tuple[str, str], list] = {}
    for r in rows:
        if r.get("name") != "walk":
            continue
        if "skipped" in r:
            out[(r["family"], "")] = [None, None, r["skipped"]]
            continue
        slot = out.setdefault((r["family"], r["commands"]), [None, None, None])
        slot[WALKERS.index(r["walker"])] = r
    return [(f, c, p, s, why) for (f, c), (p, s, why) in out.items()]


def _cell(row: dict | None, key: str, fmt: str, scale: float = 1.0) -> str:
    """A table cell: ``row[key]`` times ``scale`` in ``fmt``, or "-" without a row or a value."""
    value = None if row is None else row[key]
    return "-" if value is None else format(value if scale == 1.0 else scale * value, fmt)


def markdown_table(rows: Sequence[dict]) -> str:
    """The records of :func:`run` as the Markdown table of BENCHMARKS.md: one line per family and command kind,
    the perfect robot and the simulated one side by side ("perfect / simulated"; "-" where a walker did not
    run or a number does not apply).

    Columns (:func:`aggregate`): robots; fell % (simulated); stops % and mean progress along +x (m); mean
    steps made; obstacle contacts (perfect: footholds on obstacle cells; simulated: steps with a sole or shin
    on one); the simulated placement error, mean and p95 (cm); its sole tilt error p95 (deg). A skipped
    family gets one line with the reason.
    """
    head = ("| family | commands | robots | fell % (sim) | stops % (perfect / sim) | progress m (perfect / sim) "
            "| steps made (perfect / sim) | contacts (perfect / sim) | placement mean / p95 cm (sim) "
            "| tilt p95 deg (sim) |")
    lines = [head, "|" + " --- |" * head.count(" | ") + " --- |"]
    for family, kind, p, s, why in _pairs(rows):
        if why is not None:
            lines.append(f"| {family} | - | skipped: {why} |" + " |" * 7)
            continue
        def both(key, fmt, pkey=None, p=p, s=s):
            return f"{_cell(p, pkey or key, fmt)} / {_cell(s, key, fmt)}"

        cells = [family, kind, str((p or s)["robots"]), _cell(s, "fell_pct", ".2f"), both("stops_pct", ".1f"),
                 both("progress_mean_m", ".2f"), both("steps_made_mean", ".1f"),
                 both("obstacle_contacts", "d", pkey="footholds_on_obstacles"),
                 f"{_cell(s, 'placement_error_mean_m', '.2f', 100)} / {_cell(s, 'placement_error_p95_m', '.2f', 100)}",
                 _cell(s, "tilt_error_p95_rad", ".2f", 180 / math.pi)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


PLOT_SIZE = (12.0, 8.0)
"""Figure size of :func:`plot` (inches); saved at :data:`PLOT_DPI`."""
PLOT_DPI = 100


def plot(rows: Sequence[dict], path=None):
    """Bars per family: falls %, stops % and mean progress (m), perfect and simulated side by side.

    One panel per measure; in each, four bars per family: perfect and simulated robot (colour) under
    random and forward commands (hatched: forward). Skipped families are left out. Saved as a PNG of
    :data:`PLOT_SIZE` inches at :data:`PLOT_DPI` when ``path`` is given; returns the figure.
    """
    require("plot", "matplotlib", what="ijoy bench walk --plot")
    import matplotlib

    if path is not None:
        matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    pairs = [x for x in _pairs(rows) if x[4] is None]
    families = list(dict.fromkeys(f for f, *_ in pairs))
    kinds = [k for k in COMMANDS if any(c == k for _, c, *_ in pairs)]
    table = {(f, c): (p, s) for f, c, p, s, _ in pairs}
    fig, axes = plt.subplots(3, 1, figsize=PLOT_SIZE, sharex=True)
    measures = (("fell_pct", "fell (% of robots)"), ("stops_pct", "stopped (% of robots)"),
                ("progress_mean_m", "mean progress along +x (m)"))
    bars = [(w, k) for k in kinds for w in WALKERS]
    width = 0.8 / max(len(bars), 1)
    colours = {"perfect": "tab:blue", "mjx": "tab:orange"}
    x = np.arange(len(families))
    for ax, (key, label) in zip(axes, measures, strict=True):
        for j, (walker, kind) in enumerate(bars):
            values = []
            for f in families:
                row = table.get((f, kind), (None, None))[WALKERS.index(walker)]
                values.append(np.nan if row is None or row[key] is None else row[key])
            ax.bar(x + (j - 0.5 * (len(bars) - 1)) * width, values, width, color=colours[walker],
                   hatch="//" if kind == "forward" else None, edgecolor="white",
                   label=f"{'perfect' if walker == 'perfect' else 'simulated (MJX)'}, {kind} commands")
        ax.set_ylabel(label)
        if key.endswith("_pct"):
            ax.set_ylim(0, max(1.0, ax.get_ylim()[1]))
        ax.grid(axis="y", alpha=0.3)
        ax.axhline(0.0, color="black", lw=0.6)
    axes[0].legend(fontsize=8, ncol=2, loc="upper left")
    axes[-1].set_xticks(x, families, rotation=20)
    first = next((r for r in rows if r.get("name") == "walk" and "skipped" not in r), {})
    axes[0].set_title(f"HRP-2 joystick per terrain family: {first.get('batch', '?')} robots x "
                      f"{first.get('steps', '?')} steps, perfect robot vs MJX biped")
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=PLOT_DPI)
        plt.close(fig)
    return fig

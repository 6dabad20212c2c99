"""The walking benchmark's terrain families: twelve kinds of ground, each a batch of 5 m x 2 m maps from one key.

``ijoy bench walk`` (:mod:`ijoy_jax.apps.bench_walk`) walks a batch of robots over each family, every robot on
its own map: a sweep file's ``[terrain] walk = "<name>"`` (:mod:`ijoy_jax.sweep`) gives replicate r the map
:meth:`WalkFamily.one` draws from its key, map r of :meth:`WalkFamily.maps`. A family (:class:`WalkFamily`)
draws ``batch`` maps of one grid from its parameter range (:data:`FAMILIES`, in the benchmark's table order):
level ground, 2D clutter, slopes up, down and across, rough ground, staggered stepping stones, single-lane
platforms, stairs up and down, windows of a fractal ground image, and natural ground (windows of a second
image, 0-6 cm per map). Every map is 2.5D (``has_height=True``)
and of the same grid, with the robot's start at :data:`START` on flat ground, so one compiled walker serves
every family. Most families are the registry's generators (:data:`ijoy_jax.terrain.generators.FAMILIES`)
batched with per-map parameters drawn here; the stones, the platforms and the image windows are built from
them (or from :mod:`ijoy_jax.terrain.scene`) in the shapes the benchmark needs.

The numbers a family needs from the robot or the simulator are plain constants here, equal to theirs (tested):
the platforms' highest top is HRP-2's ``max_step_height`` (:data:`PLATFORM_HEIGHT_MAX`), the clutter's height the
one the simulation gives a 2D map's obstacle cells (:data:`CLUTTER_HEIGHT`). The terrain layer stays below the
robot and the simulator.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import tempfile
from collections.abc import Callable, Mapping
from types import MappingProxyType

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.jit_cache import compiled_count
from ijoy_jax.prng import as_key
from ijoy_jax.terrain import generators, grid, scene
from ijoy_jax.terrain.grid import Terrain

__all__ = [
    "CLUTTER",
    "CLUTTER_HEIGHT",
    "FAMILIES",
    "IMAGE_EXPONENT",
    "IMAGE_PIXELS",
    "IMAGE_RMS",
    "IMAGE_SCALE",
    "IMAGE_WAVELENGTHS",
    "NATURAL_RANGE",
    "NATURAL_SEED",
    "PAD_FRONT",
    "PLATFORM_HEIGHT_MAX",
    "PLATFORM_HEIGHT_MIN",
    "RESOLUTION",
    "ROUGH_CORRELATION",
    "ROUGH_RMS",
    "SIZE",
    "SLOPE_DEG",
    "STAIR_COUNT",
    "STAIR_FIRST",
    "STAIR_FORWARD",
    "STAIR_REACH",
    "STAIR_RISE",
    "STAIR_RUNS",
    "START",
    "START_RADIUS",
    "STONES",
    "WalkFamily",
    "clutter2d",
    "cross",
    "downhill",
    "flat_maps",
    "grid_shape",
    "ground_image",
    "image",
    "natural",
    "load_ground",
    "platforms",
    "rough",
    "rough_params",
    "stairs_down",
    "stairs_up",
    "start_zone",
    "stone_row",
    "stones",
    "uphill",
    "window_offsets",
    "write_ground_png",
]

SIZE = (5.0, 2.0)
"""Map extent (m) along x (the walking direction) and y."""
RESOLUTION = 0.02
"""Default cell size (m): 250 x 100 cells."""
START = (0.5, 1.0)
"""Where every robot stands (m): the midpoint of its feet, facing +x."""
START_RADIUS = 0.35
"""Start zone radius (m, the generators' default): it holds HRP-2's double stance and is flat (or the plane)."""
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
treads of 0.35 m it marks time before the second riser (tests/test_experiments.py section 7 has the
geometry)."""
STAIR_COUNT = 6
"""Risers per stair (6 x 15 cm = 0.9 m at most, inside :data:`HEIGHT_RANGE`)."""
STAIR_FIRST = 0.6
"""Distance (m) from the start point to the first riser."""
STAIR_REACH = 0.30
"""The stairs' robot reaches this far (m): ``robots.hrp2(reach=...)``, a longer step than HRP-2's default."""
STAIR_FORWARD = 0.375
"""Held forward command on the stairs (m/s): :data:`STAIR_REACH` per 0.8 s step, the longest step, which is
the one that crosses a riser (at the benchmark's 0.25 m/s, 0.2 m steps, the robot marks time before the first
one)."""
PLATFORM_HEIGHT_MIN = 0.02
"""Lowest platform (m); the highest is :data:`PLATFORM_HEIGHT_MAX`."""
PLATFORM_HEIGHT_MAX = float(np.float32(0.1))
"""Highest platform (m): HRP-2's ``max_step_height`` (0.1 m, a float32 leaf of ``robots.hrp2()``, so 0.1 rounded
to float32), the highest step its selector accepts."""
IMAGE_PIXELS = (512, 512)
"""Size of the generated ground image (pixels = cells: 10.24 m square at 2 cm)."""
IMAGE_RMS = 0.015
"""RMS height (m) of the generated ground image: at 2 cm, with the 1 cm roughness limit under a foot, the
selector finds a way on few windows (docs/walk_families.md has the runs)."""
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
      reach: None for the benchmark's robot (``robots.hrp2()``); else the ``reach`` (m) of the family's own,
        ``robots.hrp2(reach=...)`` (the benchmark builds it).
      forward: the held forward command (m/s) of the family's "forward" rows; None: the run's ``forward``.
    """

    name: str
    make: Callable[..., Terrain]
    ranges: str
    reach: float | None = None
    forward: float | None = None

    def one(self, key, *, shape, resolution: float) -> Terrain:
        """One map of ``shape`` (nx, ny) cells of ``resolution`` m drawn from ``key``: :attr:`make`'s batch of one
        (its parameters drawn from the family's range), without the batch axis. Traceable: a sweep draws
        replicate r's map as ``one(fold_in(key(seed), r))`` (``[terrain] walk``, :mod:`ijoy_jax.sweep`)."""
        shape = tuple(int(n) for n in shape)
        return jax.tree_util.tree_map(lambda a: a[0], self.make(key, 1, shape=shape, resolution=float(resolution)))

    def maps(self, key, batch: int, *, shape, resolution: float) -> Terrain:
        """``batch`` maps, map i :meth:`one` of ``jax.random.split(key, batch)[i]`` (which is ``fold_in(key, i)``:
        the sweep's replicate i of seed ``key``), as one jitted program per family, batch and grid (a new key
        reuses it); a leading batch axis on every leaf."""
        return _jitted(self)(as_key(key), batch, shape=tuple(int(n) for n in shape), resolution=float(resolution))

    def compiled_programs(self) -> int:
        """How many programs :meth:`maps` holds compiled for this family (in this process).

        Read it before and after a loop of calls to learn how many compiles the loop caused: each new batch
        size or grid compiles once; a new key, or the grid given as a list, reuses the program.
        """
        return compiled_count(_jitted(self))


@functools.cache
def _jitted(family: WalkFamily) -> Callable[..., Terrain]:
    def maps(key, batch, *, shape, resolution):
        one = functools.partial(family.one, shape=shape, resolution=resolution)
        return jax.vmap(one)(jax.random.split(key, batch))

    return jax.jit(maps, static_argnums=1, static_argnames=("shape", "resolution"))


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
    return dict(
        start_x=START[0] / (shape[0] * resolution),
        start_y=START[1] / (shape[1] * resolution),
        start_radius=START_RADIUS,
    )


def _uniform(key, batch, lo, hi) -> jax.Array:
    return jax.random.uniform(key, (batch,), jnp.float32, lo, hi)


def _keys(key, batch: int):
    return jax.random.split(as_key(key), batch)


def flat_maps(key, batch: int, *, shape, resolution: float) -> Terrain:
    """``batch`` maps of level ground at height 0 (2.5D): the "flat" family's maps."""
    params = generators.FlatParams(**start_zone(shape, resolution))
    return generators.batch("flat", _keys(key, batch), params, shape=shape, resolution=resolution, has_height=True)


CLUTTER = dict(count=17, size_min=0.04, size_max=0.12)
"""2D clutter: `sweeps/margin_physics.toml`'s obstacles at its density (14 on 8 m^2, here 17 on 10 m^2)."""
CLUTTER_HEIGHT = 0.1
"""Height (m) of the clutter's obstacles: ``BipedParams.obstacle_height``, the height the simulation gives a 2D
map's obstacle cells (:func:`ijoy_jax.sim.hfield.physical_heights`)."""


def clutter2d(key, batch: int, *, shape, resolution: float) -> Terrain:
    """2D obstacles (the margin sweep's clutter), stored as the 2.5D map the physics makes of them.

    A 2D map's obstacle cells stand ``BipedParams.obstacle_height`` (:data:`CLUTTER_HEIGHT`, 0.1 m) tall in the
    simulation (:func:`ijoy_jax.sim.hfield.physical_heights`); here they carry that height and stay obstacles
    (``free`` False), so the map shares the other families' 2.5D compile. The registry's "obstacles" family
    draws them on a 2.5D map with every top at that height: the cells a 2D map would block, raised to it. The
    selector chooses the steps it chooses on the 2D map (tested): a foothold's grown footprint must be free
    either way, so its height terms are 0, and 0.1 m obstacles do not exceed the swing corridor's 0.1 m clearance.
    """
    params = generators.ObstacleParams(
        **CLUTTER, top_min=CLUTTER_HEIGHT, top_max=CLUTTER_HEIGHT, **start_zone(shape, resolution)
    )
    return generators.batch(
        "obstacles",
        _keys(key, batch),
        params,
        shape=shape,
        resolution=resolution,
        has_height=True,
        max_count=CLUTTER["count"],
    )


def _slope(direction: Callable[[jax.Array, int], jax.Array]):
    def make(key, batch: int, *, shape, resolution: float) -> Terrain:
        k_angle, k_dir = jax.random.split(as_key(key))
        angle = jnp.deg2rad(_uniform(k_angle, batch, *SLOPE_DEG))
        params = generators.SlopeParams(angle=angle, direction=direction(k_dir, batch), **start_zone(shape, resolution))
        return generators.batch("slope", _keys(key, batch), params, shape=shape, resolution=resolution, has_height=True)

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
    return generators.RoughParams(
        amplitude=_uniform(k_amp, batch, *ROUGH_RMS),
        correlation_length=_uniform(k_len, batch, *ROUGH_CORRELATION),
        **start_zone(shape, resolution),
    )


def rough(key, batch: int, *, shape, resolution: float) -> Terrain:
    """Gaussian rough ground, RMS uniform in :data:`ROUGH_RMS`, correlation length in :data:`ROUGH_CORRELATION`.

    The start zone is a flat pad at 0 that ramps into the field over one correlation length
    (:func:`ijoy_jax.terrain.generators.rough`); the parameters are :func:`rough_params`.
    """
    params = rough_params(key, batch, shape=shape, resolution=resolution)
    return generators.batch(
        "rough",
        _keys(jax.random.fold_in(as_key(key), 1), batch),
        params,
        shape=shape,
        resolution=resolution,
        has_height=True,
    )


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
    standing feet (:data:`PAD_FRONT`). With the perfect robot, the held forward command at
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
            **{n: v for n, v in STONES.items()}, start_x=x0 / width_x, start_y=row_y, start_radius=0.0
        )
        return generators.batch(
            "stepping_stones", _keys(k, batch), params, shape=shape, resolution=resolution, has_height=True
        )

    a, b = lattice(k_a, first), lattice(k_b, first + 0.5 * p)
    centres = grid.flat(shape, resolution, has_height=True).cell_centres()
    even = stone_row(centres[..., 1], p) % 2 == 0
    # The start zone, cut off just ahead of the standing feet (their grown footprints end 0.141 m ahead), so
    # the first stones are where the stagger puts them and no foothold straddles the pad and a stone.
    pad = (jnp.sum((centres - jnp.asarray(START)) ** 2, axis=-1) <= zone["start_radius"] ** 2) & (
        centres[..., 0] < START[0] + PAD_FRONT
    )
    height = jnp.where(pad, jnp.float32(0.0), jnp.where(even, a.height, b.height))
    return a.replace(height=height, free=a.free & b.free)


def platforms(key, batch: int, *, shape, resolution: float, max_height: float | None = None) -> Terrain:
    """Single-lane raised platforms: two boxes in a row along +x beside the centre line, under one foot's lane.

    Per map: a lane (left or right of the centre line, half each); two platforms 0.8-1.2 m long and
    0.4-0.5 m wide whose inner edge runs 1 cm beside the centre line, the first starting 0.9-1.3 m
    from the map's origin (0.4-0.8 m ahead of the start), the second 0.3-0.6 m after it; each top
    uniform in [:data:`PLATFORM_HEIGHT_MIN`, ``max_height``] (default :data:`PLATFORM_HEIGHT_MAX`: HRP-2's
    ``max_step_height``, 0.1 m), so one foot walks on it and the other beside it. Boxes are surfaces drawn with
    :func:`ijoy_jax.terrain.scene.rasterize`.
    """
    top = PLATFORM_HEIGHT_MAX if max_height is None else float(max_height)
    ground = flat_maps(key, batch, shape=shape, resolution=resolution)
    u = jax.random.uniform(as_key(key), (batch, 8), jnp.float32)
    side = jnp.where(u[:, 0] < 0.5, 1.0, -1.0)
    length = 0.8 + 0.4 * u[:, 1:3]  # (B, 2)
    width = 0.4 + 0.1 * u[:, 3:5]
    x0 = 0.9 + 0.4 * u[:, 5]
    x1 = x0 + length[:, 0] + 0.3 + 0.3 * u[:, 6]
    height = PLATFORM_HEIGHT_MIN + (top - PLATFORM_HEIGHT_MIN) * jax.random.uniform(
        jax.random.fold_in(as_key(key), 1), (batch, 2), jnp.float32
    )
    cx = jnp.stack([x0 + 0.5 * length[:, 0], x1 + 0.5 * length[:, 1]], axis=1)
    cy = START[1] + side[:, None] * (0.01 + 0.5 * width)
    boxes = jnp.stack([cx, cy, jnp.zeros_like(cx), length, width, height], axis=-1)  # (B, 2, 6)
    return jax.vmap(lambda t, b: scene.rasterize(t, boxes=b))(ground, boxes)


def _stairs(sign: float):
    def make(key, batch: int, *, shape, resolution: float) -> Terrain:
        k_rise, k_run, k_map = jax.random.split(as_key(key), 3)
        run = jax.random.choice(k_run, jnp.asarray(STAIR_RUNS, jnp.float32), (batch,))
        params = generators.StairParams(
            rise=sign * _uniform(k_rise, batch, *STAIR_RISE),
            run=run,
            num_steps=STAIR_COUNT,
            first=STAIR_FIRST,
            **start_zone(shape, resolution),
        )
        return generators.batch(
            "stairs",
            _keys(k_map, batch),
            params,
            shape=shape,
            resolution=resolution,
            has_height=True,
            max_count=STAIR_COUNT,
        )

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


def load_ground(path=None, *, resolution: float = RESOLUTION, height_scale: float = IMAGE_SCALE,
                seed: int = 0) -> Terrain:
    """The ground image as one Terrain (:func:`ijoy_jax.terrain.from_image`, a pixel per cell).

    ``path`` None: the generated image (:func:`write_ground_png` of ``seed``) through a temporary file.
    """
    if path is not None:
        return grid.from_image(path, resolution, height_scale=height_scale)
    with tempfile.TemporaryDirectory() as tmp:
        png = write_ground_png(os.path.join(tmp, "ground.png"), seed=seed)
        return grid.from_image(png, resolution, height_scale=height_scale)


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
    centres = grid.flat(shape, resolution, has_height=True).cell_centres()
    dist = jnp.sqrt(jnp.sum((centres - jnp.asarray(START)) ** 2, axis=-1))
    taper = jnp.clip((dist - START_RADIUS) / 0.2, 0.0, 1.0)
    i0 = jnp.asarray([int(START[0] / resolution), int(START[1] / resolution)])

    def one(off):
        h = jax.lax.dynamic_slice(ground.height, (off[0], off[1]), shape)
        return taper * (h - h[i0[0], i0[1]])

    height = jax.vmap(one)(offsets)
    return Terrain(
        height=height,
        free=jnp.ones(height.shape, bool),
        origin=jnp.zeros((batch, 2), jnp.float32),
        resolution=float(resolution),
        has_height=True,
    )


NATURAL_RANGE = 0.06
"""Height range (m) of each :func:`natural` map: 0-6 cm from its lowest to its highest cell, as MuJoCo
Playground's rough-terrain height field spans 0-5 cm (its humanoids' rough-ground training scene)."""
NATURAL_SEED = 1
"""Seed of the ground image :func:`natural` cuts its windows from (:func:`ground_image`)."""


def natural(key, batch: int, *, shape, resolution: float) -> Terrain:
    """Natural rough ground spanning :data:`NATURAL_RANGE`: windows of a second fractal ground image.

    The windows are :func:`image`'s (the start pad included) from the ground image of seed
    :data:`NATURAL_SEED`, each scaled so its heights span :data:`NATURAL_RANGE` from lowest to highest cell
    (about 0.8 cm RMS).
    """
    ground = load_ground(resolution=resolution, seed=NATURAL_SEED)
    maps = image(key, batch, shape=shape, resolution=resolution, ground=ground)
    h = maps.height
    span = jnp.max(h, axis=(1, 2), keepdims=True) - jnp.min(h, axis=(1, 2), keepdims=True)
    return maps.replace(height=h * (NATURAL_RANGE / jnp.maximum(span, 1e-6)))


FAMILIES: Mapping[str, WalkFamily] = MappingProxyType(
    {
        f.name: f
        for f in (
            WalkFamily("flat", flat_maps, "level ground"),
            WalkFamily("clutter2d", clutter2d, "17 obstacles 4-12 cm, 0.1 m tall (2D)"),
            WalkFamily("uphill", uphill, "2-10 deg up along +x"),
            WalkFamily("downhill", downhill, "2-10 deg down along +x"),
            WalkFamily("cross", cross, "2-10 deg across (+-y)"),
            WalkFamily("rough", rough, "RMS 1-3 cm, correlation 10-20 cm"),
            WalkFamily("stones", stones, "36 cm stones, 4 cm gaps, rows staggered by 20 cm"),
            WalkFamily("platforms", platforms, "one lane, 2-10 cm high"),
            WalkFamily(
                "stairs_up", stairs_up, "6 risers 5-15 cm, treads 30 or 40 cm", reach=STAIR_REACH, forward=STAIR_FORWARD
            ),
            WalkFamily(
                "stairs_down",
                stairs_down,
                "6 risers 5-15 cm down, treads 30 or 40 cm",
                reach=STAIR_REACH,
                forward=STAIR_FORWARD,
            ),
            WalkFamily("image", image, "fractal ground image (PNG), 1.5 cm RMS"),
            WalkFamily("natural", natural, "fractal ground, 0-6 cm per map (Playground-like)"),
        )
    }
)
"""The benchmark's terrain families by name, in table order; read-only."""

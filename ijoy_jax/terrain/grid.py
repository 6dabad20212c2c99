"""The environment e of the paper: a grid of cells, each free or obstacle, with an elevation.

One pytree covers both of the paper's cases: a 2D occupancy grid (flat, only
the free/obstacle flag matters) and a 2.5D height map (flag plus elevation).
Arrays are indexed ``[ix, iy]``: the first axis runs along world x, the second
along world y, and cell ``(ix, iy)`` is centred at
``origin + (index + 0.5) * resolution``. Positions outside the map count as
obstacles.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.extras import require
from ijoy_jax.limits import MAX_MAP_CELLS, check_map_shape
from ijoy_jax.struct import pytree_dataclass, static_field


@pytree_dataclass
class Terrain:
    """A terrain map (the paper's environment e).

    Leaves (traced)::

      height: (nx, ny) float32, elevation of each cell in metres (zeros in 2D).
      free: (nx, ny) bool, True where a foot may stand, False for obstacles.
      origin: (2,) float32, world (x, y) of the map's lower corner, metres.

    Static::

      resolution: cell edge length in metres (Python float; fixes window sizes).
      has_height: False for a 2D occupancy grid, True for a 2.5D height map.
        2D terrains skip the height metrics (they would all be zero).
    """

    height: jax.Array
    free: jax.Array
    origin: jax.Array
    resolution: float = static_field()
    has_height: bool = static_field(default=True)

    @property
    def shape(self) -> tuple[int, int]:
        """Grid shape ``(nx, ny)``."""
        return tuple(self.free.shape[-2:])  # type: ignore[return-value]

    @property
    def size(self) -> jax.Array:
        """(2,) extent of the map in metres along x and y."""
        return jnp.asarray(self.shape, jnp.float32) * self.resolution

    def cell_centres(self) -> jax.Array:
        """(nx, ny, 2) world (x, y) of every cell centre, metres."""
        nx, ny = self.shape
        gx = (jnp.arange(nx) + 0.5) * self.resolution
        gy = (jnp.arange(ny) + 0.5) * self.resolution
        xy = jnp.stack(jnp.meshgrid(gx, gy, indexing="ij"), axis=-1)
        return xy + self.origin

    def to_numpy(self) -> dict[str, Any]:
        """The terrain as NumPy arrays (for plotting and saving)."""
        return {
            "height": np.asarray(self.height),
            "free": np.asarray(self.free),
            "origin": np.asarray(self.origin),
            "resolution": self.resolution,
            "has_height": self.has_height,
        }


def _is_concrete(x: Any) -> bool:
    return not isinstance(x, jax.core.Tracer)


def _dtype(value: Any) -> np.dtype:
    return value.dtype if hasattr(value, "dtype") else np.asarray(value).dtype


def _check_numeric(name: str, value: Any, kinds: str = "biuf") -> None:
    if _dtype(value).kind not in kinds:
        raise TypeError(f"{name} must be an array of {'bools' if kinds == 'b' else 'numbers'}, got dtype "
                        f"{_dtype(value)}")


def _check_finite(name: str, value: Any) -> None:
    if _is_concrete(value) and not np.all(np.isfinite(np.asarray(value))):
        raise ValueError(f"{name} must be finite (no NaN or inf)")


def check_terrain(terrain) -> None:
    """Check a :class:`Terrain`'s values where they are concrete (tracers are skipped); raise on the first bad one.

    What :func:`from_arrays` checks, for a terrain changed since by ``replace``: a 2D ``free`` of bools and a
    numeric ``height`` of its shape, finite heights, a finite (2,) origin and a positive finite resolution.
    The public boundaries (:func:`ijoy_jax.foot_cost_terms`, :func:`ijoy_jax.select_step`,
    :func:`ijoy_jax.rollout`) call it; inside a trace a non-finite origin or height is flagged instead
    (:func:`terrain_supported`).

    Raises:
      TypeError: not a Terrain, or a leaf of the wrong dtype. ValueError: a bad shape or value, naming it.
    """
    if not isinstance(terrain, Terrain):
        raise TypeError(f"terrain must be an ijoy_jax.Terrain, got {type(terrain).__name__}")
    res = terrain.resolution
    if isinstance(res, bool) or not isinstance(res, (int, float, np.integer, np.floating)):
        raise ValueError(f"terrain.resolution must be a number of metres, got {res!r}")
    _check_resolution("terrain.resolution", float(res))
    for name, kinds, what in (("free", "b", "bool"), ("height", "biuf", "numeric"), ("origin", "biuf", "numeric")):
        dtype = _dtype(getattr(terrain, name))
        if dtype.kind not in kinds:
            raise TypeError(f"terrain.{name} must be {what}, got dtype {dtype}")
    if np.ndim(terrain.free) != 2 or np.shape(terrain.height) != np.shape(terrain.free):
        raise ValueError(f"terrain.free must be 2D and terrain.height of its shape, got {np.shape(terrain.free)} "
                         f"and {np.shape(terrain.height)}")
    if np.shape(terrain.origin) != (2,):
        raise ValueError(f"terrain.origin must have shape (2,), got {np.shape(terrain.origin)}")
    _check_finite("terrain.origin", terrain.origin)
    if _is_concrete(terrain.height):
        with jax.ensure_compile_time_eval():  # on the device, also inside a trace: one bool comes back
            finite = bool(jnp.all(jnp.isfinite(terrain.height)))
        if not finite:
            raise ValueError("terrain.height must be finite (no NaN or inf)")


def terrain_supported(terrain: Terrain) -> jax.Array:
    """() bool: the terrain's origin and heights are finite (traceable): what :func:`check_terrain` refuses
    where they are concrete. Where False (a NaN height set by ``replace`` or vmap inside a jit) every step is
    ``unsupported``: the whole map, as the boundary refuses the whole map, so that both FootCost paths agree
    (a NaN reaches different candidates through their different sums)."""
    return jnp.all(jnp.isfinite(terrain.origin)) & jnp.all(jnp.isfinite(terrain.height))


MIN_RESOLUTION = 1e-4
"""m: the finest cell a map may have (0.1 mm). Finer, a footprint's window is beyond any memory (HRP-2's spans
3000 cells a side at 0.1 mm) and a window's cell count overflows: ``resolution=1e-300`` was accepted and
failed later with an OverflowError."""


def _check_resolution(label: str, res) -> None:
    if not np.isfinite(res) or res < MIN_RESOLUTION:
        raise ValueError(f"{label} must be a finite number of metres >= MIN_RESOLUTION ({MIN_RESOLUTION:g} m), "
                         f"got {res!r}")


def grid_spec(resolution, origin) -> tuple[float, jax.Array]:
    """Validate a grid's resolution (finite, metres, >= :data:`MIN_RESOLUTION`) and origin ((2,), finite); return
    them typed."""
    if isinstance(resolution, bool) or np.ndim(resolution) != 0 or _dtype(resolution).kind not in "iuf":
        raise TypeError(f"resolution must be a number of metres, got {resolution!r}")
    res = float(resolution)
    _check_resolution("resolution", res)
    _check_numeric("origin", origin)
    origin = jnp.asarray(origin, jnp.float32)
    if origin.shape != (2,):
        raise ValueError(f"origin must have shape (2,), got {origin.shape}")
    _check_finite("origin", origin)
    return res, origin


def from_arrays(height, free=None, resolution: float = 0.02, origin=(0.0, 0.0)) -> Terrain:
    """Build a :class:`Terrain` from arrays indexed ``[ix, iy]``.

    Args:
      height: (nx, ny) elevations in metres, or None for a 2D (flat) terrain.
      free: (nx, ny) bool, True where a foot may stand; None means all free
        (then ``height`` is required).
      resolution: cell edge length in metres, > 0.
      origin: (2,) world (x, y) of the lower corner of cell (0, 0), metres.

    Returns:
      Terrain with float32 heights (zeros and ``has_height=False`` if ``height``
      is None).

    Raises:
      ValueError: on mismatched or non-2D shapes, empty grids, non-positive
        resolution, or NaN/inf in heights, origin or resolution.

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> free = np.ones((100, 80), bool); free[60:70, :] = False   # a wall
      >>> t = ij.terrain.from_arrays(None, free, resolution=0.02)
      >>> t.shape
      (100, 80)
    """
    if height is None and free is None:
        raise ValueError("from_arrays needs height, free, or both")
    given = np.shape(height if height is not None else free)
    if len(given) == 2 and min(given) > 0:  # (an empty grid is named below)
        check_map_shape(given, "terrain grid")
    res, origin = grid_spec(resolution, origin)
    has_height = height is not None
    if has_height:
        _check_numeric("height", height)
        height = jnp.asarray(height, jnp.float32)
        if height.ndim != 2:
            raise ValueError(f"height must be 2D (nx, ny), got shape {height.shape}")
        _check_finite("height", height)
    if free is not None:
        _check_numeric("free", free)
        free_arr = jnp.asarray(free)
        if free_arr.ndim != 2:
            raise ValueError(f"free must be 2D (nx, ny), got shape {free_arr.shape}")
        if free_arr.dtype != jnp.bool_:
            if _is_concrete(free_arr) and not np.all(np.isin(np.asarray(free_arr), [0, 1])):
                raise ValueError("free must be boolean (or 0/1)")
            free_arr = free_arr.astype(bool)
    else:
        free_arr = jnp.ones(height.shape, bool)
    if not has_height:
        height = jnp.zeros(free_arr.shape, jnp.float32)
    if height.shape != free_arr.shape:
        raise ValueError(f"height {height.shape} and free {free_arr.shape} must have the same shape")
    if min(free_arr.shape) < 1:
        raise ValueError(f"terrain grid must not be empty, got shape {free_arr.shape}")
    return Terrain(height=height, free=free_arr, origin=origin, resolution=res, has_height=has_height)


def flat(shape: tuple[int, int], resolution: float = 0.02, origin=(0.0, 0.0), has_height: bool = False) -> Terrain:
    """An obstacle-free terrain of the given grid ``shape`` (nx, ny) at height 0."""
    nx, ny = check_map_shape(shape)
    height = np.zeros((nx, ny), np.float32) if has_height else None
    return from_arrays(height, np.ones((nx, ny), bool), resolution, origin)


def from_image(
    image,
    resolution: float,
    height_scale: float = 1.0,
    origin=(0.0, 0.0),
    free=None,
    obstacle_above: float | None = None,
) -> Terrain:
    """Build a 2.5D terrain from an image-like height map.

    The image is read as a picture is seen: row 0 is the top (largest y),
    column 0 the left (smallest x). So ``height[ix, iy] = image[ny - 1 - iy, ix]``.

    Args:
      image: (rows, cols) array (uint8, uint16 or float), or (rows, cols, C)
        whose first channel is used, or a path to an image file (read with
        Pillow; a palette image is converted through its palette first, so
        its colours are read, not its palette indices).
      resolution: cell edge length in metres, > 0.
      height_scale: metres per image unit (e.g. 0.5 / 255 for a uint8 map whose
        white is 0.5 m).
      origin: (2,) world (x, y) of the map's lower-left corner, metres.
      free: optional free mask in the same image layout; default all free.
      obstacle_above: optional height (metres; a number, not NaN); cells
        higher than it become obstacles (``free=False``).

    Returns:
      Terrain with ``has_height=True``.
    """
    if isinstance(image, (str, bytes)) or hasattr(image, "__fspath__"):
        require("plot", "PIL", what="terrain.from_image of an image file")
        from PIL import Image

        try:
            opened = Image.open(image)
        except Image.DecompressionBombError as e:  # beyond twice Pillow's own limit, refused before decoding
            raise ValueError(f"image {str(image)!r} is too large to decode ({e}); a map holds at most "
                             f"ijoy_jax.limits.MAX_MAP_CELLS = {MAX_MAP_CELLS} cells") from None
        with opened:
            cols, rows = opened.size  # from the header: checked before the pixels are decoded
            check_map_shape((cols, rows), f"image {str(image)!r} of {cols} x {rows} pixels")
            # A palette image's pixels are indices into its palette: read the colours they stand for.
            image = np.asarray(opened.convert("RGBA") if opened.mode in ("P", "PA") else opened)
    img = np.asarray(image)
    if img.ndim in (2, 3):
        check_map_shape(img.shape[:2], f"image of shape {img.shape}")
    if img.ndim == 3 and img.shape[2] >= 1:
        img = img[..., 0]
    if img.ndim != 2:
        raise ValueError(f"image must be 2D (rows, cols) or (rows, cols, channels >= 1), got shape {img.shape}")
    if img.dtype.kind not in "biuf":
        raise ValueError(f"image must hold numbers, got dtype {img.dtype}")
    if not np.isfinite(height_scale):
        raise ValueError("height_scale must be finite")
    if obstacle_above is not None and (isinstance(obstacle_above, bool) or not isinstance(obstacle_above, numbers.Real)
                                       or math.isnan(obstacle_above)):
        raise ValueError(f"obstacle_above must be a height in metres (a number, not NaN) or None, "
                         f"got {obstacle_above!r}")
    height = np.flipud(img).T.astype(np.float64) * height_scale
    free_arr = np.ones(height.shape, bool) if free is None else np.flipud(np.asarray(free, bool)).T
    if obstacle_above is not None:
        free_arr = free_arr & (height <= obstacle_above)
    return from_arrays(height.astype(np.float32), free_arr, resolution, origin)

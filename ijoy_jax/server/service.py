"""The footstep server's state and request handlers, without the network: frames in, frames out.

A :class:`Service` holds one robot (chosen at start-up; its traced scalar leaves may change at run time
without a recompile) and up to ``limits.max_maps`` named terrain maps, each with its prepared tables
(:func:`ijoy_jax.select.prepare`: the terrain's :class:`~ijoy_jax.footcost.TerrainIndex` and the robot's
target set, so a step request builds neither). :meth:`Service.handle` answers one request message and never
raises: every failure is an error reply with a code (:data:`~ijoy_jax.server.schema.ERROR_CODES`).

A step is :func:`ijoy_jax.select_step` (the exhaustive method, as its default) on the named map, then
:func:`ijoy_jax.foot_cost_terms` of the chosen pose for its named cost terms. Decisions run one at a time
in the calling thread (:mod:`ijoy_jax.server.server` calls :meth:`Service.handle` from its one loop), so
replies equal in-process ``select_step`` bit for bit.

Compiled programs: what a request runs is compiled for its map's kind (:func:`program_key`: the grid shape
in cells, the resolution and 2D or 2.5D), once, on the first request on a map of that kind (a second or more
per kind, during which the calling loop answers no one). A :class:`ProgramCache` keeps the programs of the
``max_programs`` most recently used kinds (:data:`DEFAULT_MAX_PROGRAMS`) and drops the least recently used,
with their compiled code, so a client that sends a new shape for every map costs compile time, not memory
without end. Deployments use a few fixed map shapes and compile them before serving (:meth:`Service.warm_up`,
``ijoy serve --warm-up``).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
import traceback
from collections import OrderedDict
from collections.abc import Hashable, Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax import __version__, geometry, robots, select
from ijoy_jax.footcost import FootCostTerms, TerrainIndex, foot_cost_terms, index_terrain, window_cells
from ijoy_jax.footcost.index import update_columns
from ijoy_jax.footcost.query import check_frame
from ijoy_jax.robots import Robot
from ijoy_jax.server import schema
from ijoy_jax.server.schema import DEFAULT_MAP, Limits, ProtocolError, json_float
from ijoy_jax.targets import make_targets
from ijoy_jax.terrain import Terrain, from_arrays

log = logging.getLogger("ijoy_jax.server")

TERM_NAMES = tuple(FootCostTerms._fields)
"""The names of a step reply's ``terms`` (every field of :class:`~ijoy_jax.FootCostTerms`), in that order."""

MIN_UPDATE_COLUMNS = 16
"""Narrowest column band a window update rebuilds (a power of two; wider bands are the next power of two)."""

DEFAULT_MAX_PROGRAMS = 8
"""Map kinds (:func:`program_key`) whose compiled programs a :class:`Service` keeps by default: twice the
default ``Limits.max_maps``, so the maps a default server holds never evict each other's programs, with room
for as many warm-up kinds again (each warm-up shape is two kinds: 2D and 2.5D)."""


def _decide(terrain: Terrain, robot: Robot, prepared: select.Prepared, stance, side, command, swing_from,
            p0_index) -> tuple[select.StepChoice, FootCostTerms]:
    """One step request: :func:`ijoy_jax.select_step` with the map's prepared tables, and
    :func:`ijoy_jax.foot_cost_terms` of the chosen pose (the chosen action; the step in place, action
    ``p0_index``, when none is valid), in one program. Both public functions, traced here: their checks
    of values ran at the server's boundary (the request's schema, ``set_terrain``, ``set_robot``), not
    once more per request."""
    choice = select.select_step(terrain, robot, stance, side, command, swing_from=swing_from,
                                index=prepared.index, targets=prepared.targets)
    action = jnp.where(choice.valid, choice.index, p0_index)[None].astype(jnp.int32)
    terms = foot_cost_terms(terrain, robot, stance, side, choice.pose[None], swing_from=swing_from,
                            action_index=action, index=prepared.index)
    return choice, jax.tree.map(lambda a: a[0], terms)


def check_max_programs(value) -> int:
    """``value`` as a number of map kinds a :class:`ProgramCache` keeps (ValueError names it unless it is an
    integer of at least 1)."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"max_programs must be a positive integer (map kinds whose compiled programs are kept), "
                         f"got {value!r}")
    return int(value)


def program_key(terrain: Terrain) -> tuple:
    """What of ``terrain`` decides the programs a request on it runs: its pytree structure (which carries the
    static ``resolution`` and ``has_height``) and its leaves' shapes and dtypes. The robot's static fields are
    the service's own and never change; its leaves, the stance and the command are traced."""
    leaves, structure = jax.tree.flatten(terrain)
    return structure, tuple((tuple(np.shape(a)), np.dtype(a.dtype).name) for a in leaves)


def describe_key(key: tuple) -> str:
    """A :func:`program_key` in words, for a log line (e.g. ``"20x20 maps at 0.05 m (2.5D)"``)."""
    structure, leaves = key
    terrain = jax.tree.unflatten(structure, [np.zeros(shape, dtype) for shape, dtype in leaves])
    nx, ny = terrain.shape
    return f"{nx}x{ny} maps at {terrain.resolution:g} m ({'2.5D' if terrain.has_height else '2D'})"


class Programs:
    """The programs of one map kind: the index (``set_terrain``, a whole-map update), a column band's update
    (one program per band width) and a step decision (with and without ``swing_from``).

    Each is a :func:`jax.jit` of a function object of its own, made here: JAX keys its caches of traced and
    compiled programs on the function, so a module-level jitted function would keep every shape it ever saw
    for the life of the process, while these are freed with this object. Their compiled programs are named
    ``jit_served_index``, ``jit_served_update`` and ``jit_served_decide`` (in profiles and in
    ``jax.devices()[0].client.live_executables()``).
    """

    def __init__(self):
        def served_index(terrain, robot):
            return index_terrain(terrain, robot)

        def served_update(index, terrain, robot, start, width):
            return update_columns(index, terrain, robot, start, width)

        def served_decide(*args):
            return _decide(*args)

        self.index = jax.jit(served_index)
        self.update = jax.jit(served_update, static_argnames="width")
        self.decide = jax.jit(served_decide)


class ProgramCache:
    """The :class:`Programs` of at most ``max_programs`` map kinds, least recently used dropped first.

    Attributes:
      max_programs: map kinds kept (:func:`check_max_programs`).
      builds: kinds whose programs were made (a first use, or a use after they were dropped).
      evictions: kinds dropped to make room.

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> cache = ProgramCache(1)
      >>> a = cache.get(ij.terrain.from_arrays(None, np.ones((20, 20), bool), 0.05))
      >>> b = cache.get(ij.terrain.from_arrays(None, np.ones((20, 24), bool), 0.05))
      >>> len(cache), cache.builds, cache.evictions
      (1, 2, 1)
    """

    def __init__(self, max_programs: int = DEFAULT_MAX_PROGRAMS):
        self.max_programs = check_max_programs(max_programs)
        self._entries: OrderedDict[Hashable, Programs] = OrderedDict()
        self.builds = 0
        self.evictions = 0

    def __len__(self) -> int:
        return len(self._entries)

    def keys(self) -> list[tuple]:
        """The kinds held (:func:`program_key`), least recently used first."""
        return list(self._entries)

    def get(self, terrain: Terrain) -> Programs:
        """The programs for ``terrain``'s kind, now the most recently used (made, and the least recently used
        kind dropped when full, if it was not held)."""
        key = program_key(terrain)
        programs = self._entries.get(key)
        if programs is not None:
            self._entries.move_to_end(key)
            return programs
        while len(self._entries) >= self.max_programs:
            old, _ = self._entries.popitem(last=False)
            self.evictions += 1
            log.info("dropped the compiled programs for %s, the least recently used kind (max_programs = %d): "
                     "a request on such a map compiles them again", describe_key(old), self.max_programs)
        programs = self._entries[key] = Programs()
        self.builds += 1
        return programs


@dataclasses.dataclass
class MapState:
    """One held map: the terrain, its prepared tables, host copies of its arrays and its revision."""

    terrain: Terrain
    prepared: select.Prepared
    height: np.ndarray  # (nx, ny) float32, host copy (window updates write here first)
    free: np.ndarray  # (nx, ny) bool
    revision: int

    def describe(self) -> dict:
        """The map as the ``info`` reply lists it."""
        t = self.terrain
        return {"shape": list(t.shape), "resolution": t.resolution, "origin": [float(v) for v in np.asarray(t.origin)],
                "has_height": t.has_height, "revision": self.revision}


_COMPILES = {"count": 0}
_COMPILE_EVENT = "/jax/core/compile/jaxpr_to_mlir_module_duration"
_listener_lock = threading.Lock()
_listening = False


def _count_compiles() -> None:
    """Count this process's lowerings to XLA (each new program, whether compiled or read from a cache)."""
    global _listening
    with _listener_lock:
        if _listening:
            return

        def listener(event, duration, **kwargs):
            if event == _COMPILE_EVENT:
                _COMPILES["count"] += 1

        jax.monitoring.register_event_duration_secs_listener(listener)
        _listening = True


def compile_count() -> int:
    """Programs this process has lowered since the first :class:`Service` was made (for no-recompile checks)."""
    return _COMPILES["count"]


def _term(value):
    """A cost term or metric as a reply carries it: float32 as :func:`json_float`, the action index as an int."""
    value = np.asarray(value)
    return int(value) if value.dtype.kind in "iu" else json_float(value)


def _f32(name: str, values, *, pose: bool = False) -> np.ndarray:
    """JSON numbers as float32 (what select_step does with them), refusing values float32 cannot hold; a
    ``pose`` (x, y, theta) has a heading beyond :data:`ijoy_jax.geometry.MAX_ANGLE` reduced by whole turns in
    float64 first, as select_step's boundary does (a float32 of 2 pi 1e7 rad is 4 rad coarse)."""
    a64 = np.asarray(values, np.float64)
    if pose and a64.shape[-1:] == (3,):
        geometry.check_headings(name, a64)  # beyond what float64 can place: invalid_value, as select_step refuses
        a64 = geometry.reduce_turns(a64)
    with np.errstate(over="ignore"):
        a = a64.astype(np.float32)
    if not np.isfinite(a).all():
        i = int(np.argmax(~np.isfinite(a)))
        raise ProtocolError("non_finite", f"{name}[{i}] = {a64.flat[i]!r} overflows float32")
    return a


class Service:
    """The footstep server's state and handlers (see the module docstring).

    Args:
      robot: the robot every decision is for (e.g. ``ij.robots.hrp2(margin=0.02)``).
      name: the robot's name for the ``info`` reply.
      options: how the robot was built (reported as is, e.g. ``{"margin": 0.02, "density": 1.0}``).
      limits: input limits (:class:`~ijoy_jax.server.schema.Limits`).
      max_programs: map kinds whose compiled programs are kept (:class:`ProgramCache`; a positive integer,
        default :data:`DEFAULT_MAX_PROGRAMS`).

    Example:
      >>> import numpy as np, ijoy_jax as ij
      >>> from ijoy_jax.server import Service, schema
      >>> service = Service(ij.robots.hrp2())
      >>> frames = schema.encode({"version": 1, "type": "set_terrain", "resolution": 0.02},
      ...                        {"free": np.ones((60, 60), bool)})
      >>> schema.decode_reply(service.handle(frames)).header["revision"]
      1
      >>> reply = service.handle(schema.encode({"version": 1, "type": "step", "stance": [0.6, 0.5, 0.0],
      ...                                       "stance_side": -1, "command": [0.2, 0.0, 0.0]}))
      >>> schema.decode_reply(reply).header["valid"]
      True
    """

    def __init__(self, robot: Robot, *, name: str = "custom", options: Mapping[str, Any] | None = None,
                 limits: Limits | None = None, max_programs: int = DEFAULT_MAX_PROGRAMS):
        robots.check_robot(robot)
        self.programs = ProgramCache(max_programs)
        _count_compiles()
        self.robot = robot
        self.name = name
        self.options = dict(options or {})
        self.limits = limits or Limits()
        self.targets = make_targets(robot)
        self.maps: dict[str, MapState] = {}
        self.stats = {"requests": 0, "errors": 0, "started": time.time()}
        p0 = np.asarray(robot.p0)
        self._p0_index = int(np.argmin(np.abs(np.asarray(robot.actions) - p0).sum(-1)))  # the step in place

    # -------------------------------------------------------------------------------------------- the boundary

    def handle(self, frames: Sequence) -> list[bytes]:
        """Answer one request message (frames, envelope stripped) with a reply message's frames. Never raises."""
        self.stats["requests"] += 1
        rid, rtype = None, None
        try:
            request = schema.decode_request(frames, self.limits)
            rid, rtype = request.header.get("id"), request.type
            header, arrays = getattr(self, f"_on_{rtype}")(request)
            return schema.encode({"version": schema.PROTOCOL_VERSION, "type": rtype, "ok": True, "id": rid,
                                  **header}, arrays)
        except ProtocolError as e:
            code, message, extra = e.code, e.message, e.extra
        except (ValueError, TypeError) as e:  # the library's boundary checks: a value it refuses, named
            code, message, extra = "invalid_value", str(e), {}
        except Exception as e:  # noqa: BLE001  a bug: reply, log it, keep serving
            log.error("internal error on a %s request:\n%s", rtype, traceback.format_exc())
            code, message, extra = "internal", f"{type(e).__name__}: {e}", {}
        self.stats["errors"] += 1
        if rid is None and frames:
            rid = schema.request_id(frames)
        return schema.encode(schema.error_header(code, message, rid, rtype, **extra))

    # ---------------------------------------------------------------------------------------------- handlers

    def _on_hello(self, req):
        version = schema.negotiate(req.header.get("versions", [req.header["version"]]))
        return {"version": version, "supported": list(schema.SUPPORTED_VERSIONS), "server": self._server_name(),
                "robot": {"name": self.name, "num_actions": self.robot.num_actions},
                "limits": self.limits.to_json()}, None

    def _on_info(self, req):
        leaves = {n: float(np.asarray(robots.get_leaf(self.robot, n))) for n in robots.SCALAR_LEAVES}
        robot = {"name": self.name, "options": self.options, "num_actions": self.robot.num_actions,
                 "leaves": leaves, "units": {n: s.unit for n, s in robots.SCALAR_LEAVES.items()},
                 "settable": list(robots.SCALAR_LEAVES)}
        stats = {"requests": self.stats["requests"], "errors": self.stats["errors"], "compiles": compile_count(),
                 "uptime_s": time.time() - self.stats["started"]}
        header = {"server": self._server_name(), "supported": list(schema.SUPPORTED_VERSIONS), "robot": robot,
                  "limits": self.limits.to_json(), "maps": {k: m.describe() for k, m in self.maps.items()},
                  "terms": list(TERM_NAMES), "stats": stats}
        arrays = {"actions": np.asarray(self.robot.actions, np.float32), "p0": np.asarray(self.robot.p0, np.float32)}
        return header, arrays

    def _on_set_terrain(self, req):
        h = req.header
        name = h.get("map", DEFAULT_MAP)
        if name not in self.maps and len(self.maps) >= self.limits.max_maps:
            raise ProtocolError("too_many_maps", f"the server holds {len(self.maps)} maps (max_maps = "
                                                 f"{self.limits.max_maps}): drop one or reuse a name "
                                                 f"({sorted(self.maps)})")
        height, free = req.arrays.get("height"), req.arrays.get("free")
        res = float(h["resolution"])
        origin = _f32("origin", h.get("origin", [0.0, 0.0]))
        try:
            cells = max(window_cells(self.robot.max_radius, res), window_cells(0.5 * self.robot.max_swing, res))
        except OverflowError:  # a denormal resolution (1e-320 m): windows beyond any count
            cells = math.inf
        if cells > self.limits.max_window_cells:
            raise ProtocolError("too_large", f"resolution {res!r} m gives the robot's footprint and swing windows "
                                             f"{cells} cells across, above max_window_cells = "
                                             f"{self.limits.max_window_cells}: use a coarser map")
        terrain = from_arrays(None if height is None else np.asarray(height, np.float32),
                              None if free is None else np.asarray(free, bool), res, origin)
        check_frame(terrain)
        t0 = time.perf_counter()
        index = jax.block_until_ready(self.programs.get(terrain).index(terrain, self.robot))
        revision = self.maps[name].revision + 1 if name in self.maps else 1
        self.maps[name] = MapState(terrain, select.Prepared(index, self.targets),
                                   np.array(terrain.height, np.float32), np.array(terrain.free, bool), revision)
        return {"map": name, "revision": revision, "shape": list(terrain.shape), "has_height": terrain.has_height,
                "compute_us": (time.perf_counter() - t0) * 1e6}, None

    def _on_update_terrain(self, req):
        h = req.header
        name = h.get("map", DEFAULT_MAP)
        m = self._map(name, "update_terrain")
        (ix, iy), (wx, wy) = h["offset"], next(iter(req.arrays.values())).shape
        nx, ny = m.terrain.shape
        if ix + wx > nx or iy + wy > ny:
            raise ProtocolError("invalid_value", f"window [{ix}:{ix + wx}, {iy}:{iy + wy}] leaves the map of shape "
                                                 f"[{nx}, {ny}]")
        if "height" in req.arrays and not m.terrain.has_height:
            raise ProtocolError("invalid_field", f"arrays: map {name!r} is 2D (set without height): a window "
                                                 "update takes 'free' only")
        height, free = m.height.copy(), m.free.copy()
        if "height" in req.arrays:
            height[ix:ix + wx, iy:iy + wy] = np.asarray(req.arrays["height"], np.float32)
        if "free" in req.arrays:
            free[ix:ix + wx, iy:iy + wy] = np.asarray(req.arrays["free"], bool)
        old = m.terrain
        terrain = old.replace(height=jnp.asarray(height), free=jnp.asarray(free))
        t0 = time.perf_counter()
        index, (c0, c1) = self._rebuild(m.prepared.index, terrain, ix, wx)
        m.terrain, m.height, m.free = terrain, height, free
        m.prepared = select.Prepared(jax.block_until_ready(index), m.prepared.targets)
        m.revision += 1
        return {"map": name, "revision": m.revision, "shape": [nx, ny], "has_height": terrain.has_height,
                "rebuilt_columns": [c0, c1], "compute_us": (time.perf_counter() - t0) * 1e6}, None

    def _rebuild(self, index: TerrainIndex, terrain: Terrain, ix: int, wx: int):
        """The index of ``terrain`` after its columns ``ix .. ix + wx - 1`` changed: those columns of the old
        index rebuilt, in a band of a power-of-two width (one program per band width), or all of it when the
        band would cover half the map or more."""
        nx = terrain.shape[0]
        programs = self.programs.get(terrain)
        band = max(MIN_UPDATE_COLUMNS, 1 << max(wx - 1, 0).bit_length())
        if 2 * band >= nx:
            return programs.index(terrain, self.robot), (0, nx)
        start = min(ix, nx - band)
        return programs.update(index, terrain, self.robot, start, band), (start, start + band)

    def _on_drop_terrain(self, req):
        name = req.header.get("map", DEFAULT_MAP)
        m = self._map(name, "drop_terrain")
        del self.maps[name]
        return {"map": name, "revision": m.revision}, None

    def _on_step(self, req):
        h = req.header
        stance, command = _f32("stance", h["stance"], pose=True), _f32("command", h["command"])
        swing = h.get("swing_from")
        swing = None if swing is None else _f32("swing_from", swing, pose=True)
        name = h.get("map", DEFAULT_MAP)
        m = self._map(name, "step")
        side = int(h["stance_side"])
        t0 = time.perf_counter()
        decide = self.programs.get(m.terrain).decide
        choice, terms = jax.device_get(decide(m.terrain, self.robot, m.prepared, stance, side, command, swing,
                                              self._p0_index))
        compute_us = (time.perf_counter() - t0) * 1e6
        vec = lambda a: [json_float(v) for v in np.asarray(a).ravel()]  # noqa: E731
        return {"map": name, "revision": m.revision, "valid": bool(choice.valid), "index": int(choice.index),
                "pose": vec(choice.pose), "foothold": vec(choice.foothold), "cost": json_float(choice.cost),
                "foot_cost": json_float(choice.foot_cost), "target": vec(choice.target),
                "command_ok": bool(choice.command_ok), "unsupported": bool(choice.unsupported),
                "evaluated": int(choice.evaluated),
                "terms": {k: _term(getattr(terms, k)) for k in TERM_NAMES},
                "compute_us": compute_us}, None

    def _on_set_robot(self, req):
        leaves = req.header["leaves"]
        unknown = sorted(set(leaves) - set(robots.SCALAR_LEAVES))
        if unknown:
            raise ProtocolError("invalid_field", f"leaves: {unknown} are not settable leaves (settable: "
                                                 f"{list(robots.SCALAR_LEAVES)})")
        values = {n: jnp.asarray(_f32(n, v), jnp.float32) for n, v in leaves.items()}
        robot = robots.set_leaves(self.robot, values)
        robots.check_robot(robot)  # ValueError -> invalid_value, naming the leaf; the robot is unchanged
        if "rotation_weight" in values:  # L_i is sorted by dist, which weighs rotations: rebuild it (no recompile)
            self.targets = make_targets(robot)
            for m in self.maps.values():
                m.prepared = select.Prepared(m.prepared.index, self.targets)
        self.robot = robot
        return {"leaves": {n: float(np.asarray(robots.get_leaf(robot, n))) for n in robots.SCALAR_LEAVES}}, None

    # ----------------------------------------------------------------------------------------------- helpers

    def _map(self, name: str, what: str) -> MapState:
        if name not in self.maps:
            held = f"it holds {sorted(self.maps)}" if self.maps else "none is set yet: send set_terrain first"
            raise ProtocolError("no_terrain", f"{what}: the server holds no map {name!r} ({held})")
        return self.maps[name]

    @staticmethod
    def _server_name() -> str:
        return f"ijoy_jax {__version__} (jax {jax.__version__}, {jax.default_backend()})"

    # ------------------------------------------------------------------------------------------------ warm-up

    def warm_up(self, shape: tuple[int, int], resolution: float = 0.02) -> dict:
        """Compile every program a request on a map of ``shape`` cells at ``resolution`` m runs (2D and 2.5D,
        with and without ``swing_from``, a whole-map and a window update), so the first request does not wait
        for a compile. Leaves the service as it was.

        Returns:
          ``{"shape", "resolution", "seconds", "programs"}``: wall time and programs lowered.

        Raises:
          ValueError: a shape beyond the service's limits (``max_cells``, ``max_side``), before anything is built.
        """
        if not self.limits.holds(shape):  # before a map of that shape is allocated
            raise ValueError(f"warm-up {shape[0]}x{shape[1]}: {self.limits.shape_refusal(shape)}; raise "
                             f"--max-cells or warm up a smaller shape")
        t0, c0 = time.perf_counter(), compile_count()
        saved_maps, saved_stats = dict(self.maps), dict(self.stats)
        nx, ny = shape
        x, y = 0.5 * nx * resolution, 0.5 * ny * resolution
        try:
            self.maps = {}
            for has_height in (False, True):
                arrays = {"free": np.ones(shape, bool)}
                if has_height:
                    arrays["height"] = np.zeros(shape, np.float32)
                self._ok(self.handle(schema.encode({"version": 1, "type": "set_terrain",
                                                    "resolution": resolution}, arrays)))
                window = {k: v[:4, :4] for k, v in arrays.items()}
                self._ok(self.handle(schema.encode({"version": 1, "type": "update_terrain", "offset": [0, 0]},
                                                   window)))
                for swing in (None, [x - 0.1, y + 0.19, 0.0]):
                    self._ok(self.handle(schema.encode({"version": 1, "type": "step", "stance": [x, y, 0.0],
                                                        "stance_side": -1, "command": [0.1, 0.0, 0.0],
                                                        "swing_from": swing})))
        finally:
            self.maps, self.stats = saved_maps, saved_stats
        return {"shape": list(shape), "resolution": resolution, "seconds": time.perf_counter() - t0,
                "programs": compile_count() - c0}

    @staticmethod
    def _ok(frames) -> dict:
        header = schema.decode_reply(frames).header
        if not header["ok"]:
            raise ValueError(f"warm-up: {header['code']}: {header['message']}")
        return header


def parse_shape(text: str) -> tuple[tuple[int, int], float]:
    """``"NXxNY"`` or ``"NXxNY@RES"`` (cells, metres) as ``((nx, ny), res)`` (res 0.02 when not given)."""
    dims, _, res = text.partition("@")
    try:
        nx, ny = (int(v) for v in dims.lower().split("x"))
        r = float(res) if res else 0.02
    except ValueError:
        raise ValueError(f"a map shape is NXxNY or NXxNY@RES (e.g. 200x200@0.02), got {text!r}") from None
    if nx < 1 or ny < 1 or not math.isfinite(r) or r <= 0:
        raise ValueError(f"a map shape needs positive sizes and resolution, got {text!r}")
    return (nx, ny), r

"""The live view: a browser page that shows a drive as it happens and takes the stick from the keyboard or a gamepad.

A small aiohttp server (one thread, its own asyncio loop) serves one page (``static/index.html``,
``static/view.js``: a top-down canvas drawing, no build step) and a WebSocket. The page comes with the scene
and the latest state written into it (:func:`page_html`), so its first paint, at the page's load event,
already shows the robot; the WebSocket then sends every new state. The page draws the terrain (the height
map as an image, obstacles dark) with x and y axes in metres along its edges, both feet, the chosen next
foothold, every candidate of the current decision (a dot per action of S: green to yellow by FootCost, red
where invalid), the haptic cue's reach (the polygon of the footholds the next decision can reach per
direction), the command (the stick's position and the cue's force on it) and the decision latency (a bar per
decision against the step time). Keys w/s, a/d, q/e (or the arrow keys, with shift for turning) and a
gamepad through the browser's Gamepad API send stick axes back over the WebSocket into a
:class:`ijoy_jax.live.SharedAxes` the drive reads.

The same page at ``/3d`` (or its "3D view" button) shows the drive in 3D instead of the map (``static/view3d.js``,
three.js vendored in ``static/``, no network needed): the terrain as a height-field mesh (obstacles dark), the
robot's bodies at their simulated poses (every visible geom of a MuJoCo robot, the G1's meshes as themselves;
the perfect robot's soles), the chosen foothold and the past ones, and a camera that follows the robot and
orbits with the mouse. The bodies come from :meth:`ViewServer.set_body`; their poses travel in every
published state, their meshes once (``/meshes.bin``, :func:`mesh_bytes`).

Every JSON text the server sends is strict JSON (:func:`finite_json`): a NaN or an infinity (a diverged
simulation, an invalid candidate's cost) arrives as ``null``.

On a remote GPU machine: ``ijoy drive --port 8765`` there, ``ssh -L 8765:localhost:8765 HOST`` here, and
open http://localhost:8765 (docs/drive.md). The server binds 127.0.0.1 by default.
"""

from __future__ import annotations

import asyncio
import io
import json
import math
import numbers
import threading
from importlib import resources

import numpy as np

from ijoy_jax import robots
from ijoy_jax.live.bodies import BodyGeoms
from ijoy_jax.live.inputs import SharedAxes
from ijoy_jax.robots import Robot
from ijoy_jax.terrain import Terrain

__all__ = ["DEFAULT_OBSTACLE_HEIGHT", "DEFAULT_PORT", "MAX_FOOTHOLDS", "MAX_MESH_SIDE", "MAX_MESSAGE_BYTES",
           "ViewServer", "finite_json", "mesh_bytes", "page_html", "page_message", "terrain_image", "terrain_mesh"]

DEFAULT_PORT = 8765
"""The view's default TCP port."""
MAX_MESSAGE_BYTES = 4096
"""Largest WebSocket message a page may send (a stick message is under 100 bytes); aiohttp closes a connection
that sends more."""
DEFAULT_OBSTACLE_HEIGHT = 0.1
"""m: how high the 3D view raises a 2D map's obstacle cells when the body has no physics (the perfect robot); a
MuJoCo biped's own walls' height replaces it (:attr:`ijoy_jax.live.bodies.BodyGeoms.obstacle_height`)."""
MAX_MESH_SIDE = 512
"""Most vertices along either side of the 3D view's terrain mesh: a larger map is sampled every few cells."""
MAX_FOOTHOLDS = 100
"""Past chosen footholds a published state carries (the latest ones)."""
_POSE_DECIMALS = 4
"""A published geom pose's decimals: 0.1 mm, and 1e-4 of a unit quaternion's components."""
_VENDORED = {"view3d.js": "application/javascript", "three.module.min.js": "application/javascript",
             "three.core.min.js": "application/javascript", "OrbitControls.js": "application/javascript",
             "three.LICENSE": "text/plain"}
"""The 3D view's files in ``static/``, served under their names (three.js r176 and its orbit controls, MIT
licence in ``three.LICENSE``)."""


def _finite(x):
    """``x`` as plain JSON values: arrays and NumPy scalars as lists and Python numbers, every NaN or infinity as
    None."""
    if isinstance(x, dict):
        return {str(k): _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    if isinstance(x, (np.ndarray, np.generic)) or (hasattr(x, "__array__") and not isinstance(x, (str, bytes))):
        a = np.asarray(x)
        if a.dtype.kind in "biu":
            return a.tolist()
        if a.dtype.kind == "f":  # whole arrays at once: a state's candidates are hundreds of numbers
            finite = np.isfinite(a)
            if finite.all():
                return a.tolist()
            out = a.astype(object)
            out[~finite] = None
            return out.tolist()
        return _finite(a.tolist())
    if isinstance(x, bool):
        return x
    if isinstance(x, numbers.Integral):
        return int(x)
    if isinstance(x, numbers.Real):
        v = float(x)
        return v if math.isfinite(v) else None
    return x


def finite_json(value) -> str:
    """Strict JSON text of ``value`` (dicts, lists, arrays, numbers, strings): every NaN or infinity written as
    ``null``, so a browser's ``JSON.parse`` reads whatever a drive publishes (Python's ``json.dumps`` writes
    ``NaN``, which is not JSON).

    Example:
      >>> import numpy as np
      >>> finite_json({"pos": np.array([1.0, np.nan]), "cost": float("inf")})
      '{"pos":[1.0,null],"cost":null}'
    """
    return json.dumps(_finite(value), allow_nan=False, separators=(",", ":"))


def page_message(text: str) -> dict | None:
    """A page's WebSocket message as a JSON object, or None where it is not one: not JSON, JSON that is not an
    object (``[1, 2, 3]``, ``42``, ``null``), or nested too deeply for the parser. The view ignores such a
    message and keeps the connection: a page cannot stop the drive or fill its log."""
    try:
        data = json.loads(text)
    except (ValueError, RecursionError):
        return None
    return data if isinstance(data, dict) else None


_INITIAL = '<script id="ijoy-initial" type="application/json">null</script>'
"""The page's placeholder for the scene and state it starts with (static/index.html)."""


def page_html(scene: dict, state: str) -> str:
    """The view's page with the scene and the latest state written into it, so its first paint shows the robot.

    The page draws them as its load event fires (the terrain image is an ``<img>`` of the page, so the load event
    waits for it), before the WebSocket brings newer states: a screenshot taken at the load event shows the
    terrain and the feet rather than an empty map.

    Args:
      scene: the scene as ``/scene.json`` serves it ({} before :meth:`ViewServer.set_scene`).
      state: the latest state as JSON text, as the WebSocket sends it ("{}" before the first
        :meth:`ViewServer.publish`).

    Returns:
      The HTML text. Every ``<`` in the embedded JSON is written ``\\u003c`` (the same JSON value), so no text in
      a state (``</script>``, ``<!--``) can end the script element early.
    """
    template = (resources.files("ijoy_jax.live") / "static" / "index.html").read_text()
    data = '{"scene": ' + finite_json(scene) + ', "state": ' + state + "}"
    data = data.replace("<", "\\u003c")
    return template.replace(_INITIAL, f'<script id="ijoy-initial" type="application/json">{data}</script>', 1)


def terrain_image(terrain: Terrain) -> bytes:
    """PNG bytes of the terrain seen from above: heights in a grey-green ramp, obstacles dark red-brown.

    Row 0 of the image is the map's top (largest y), column 0 its left (smallest x), one pixel per cell.
    """
    from PIL import Image

    free = np.asarray(terrain.free, bool)
    h = np.asarray(terrain.height, np.float64)
    if terrain.has_height and np.ptp(h) > 0:
        u = (h - h.min()) / np.ptp(h)
    else:
        u = np.full(h.shape, 0.5)
    low, high = np.array([205, 214, 196]), np.array([96, 128, 88])
    rgb = low[None, None] * (1 - u[..., None]) + high[None, None] * u[..., None]
    rgb[~free] = (70, 40, 36)
    img = np.flipud(np.transpose(rgb, (1, 0, 2))).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


def terrain_mesh(terrain: Terrain) -> dict:
    """The terrain as the 3D view's height-field mesh, JSON-ready: one vertex per cell centre (every
    ``stride``-th cell where a side has more than :data:`MAX_MESH_SIDE` cells).

    Returns:
      ``{"nx", "ny"}`` vertices along x and y; ``"origin"`` (x, y) of vertex (0, 0), m; ``"step"`` m between
      vertices; ``"stride"`` cells per vertex; ``"z"`` (ny * nx,) heights (m, mm precision; 0 on a 2D map) and
      ``"obstacle"`` (ny * nx,) 1 where any cell a vertex stands for is not free, both row j (along y) after
      row j - 1, vertex i of row j at ``j * nx + i``; ``"has_height"``.
    """
    free = np.asarray(terrain.free, bool)
    nx, ny = free.shape
    stride = max(1, math.ceil(max(nx, ny) / MAX_MESH_SIDE))
    mx, my = math.ceil(nx / stride), math.ceil(ny / stride)
    blocked = np.zeros((mx * stride, my * stride), bool)  # padding counts as free: only real cells block
    blocked[:nx, :ny] = ~free
    obstacle = blocked.reshape(mx, stride, my, stride).any(axis=(1, 3))
    h = np.asarray(terrain.height, np.float64)[::stride, ::stride] if terrain.has_height else np.zeros((mx, my))
    h = np.where(np.isfinite(h), h, 0.0)
    res = float(terrain.resolution)
    origin = np.asarray(terrain.origin, np.float64) + 0.5 * res
    return {"nx": int(mx), "ny": int(my), "origin": origin.tolist(), "step": res * stride, "stride": int(stride),
            "z": np.round(h.T.ravel(), 3).tolist(), "obstacle": obstacle.T.ravel().astype(int).tolist(),
            "has_height": bool(terrain.has_height)}


def mesh_bytes(meshes) -> bytes:
    """The bodies' meshes (:meth:`ijoy_jax.live.bodies.BodyGeoms.meshes`) as the 3D view reads them, at
    ``/meshes.bin``: little-endian 4-byte words, the count N (uint32), each mesh's vertex and triangle counts
    (2 N uint32), then each mesh's vertices (3 V float32, m) and triangles (3 F uint32), mesh after mesh.

    Example:
      >>> import numpy as np
      >>> tri = (np.eye(3, dtype=np.float32), np.array([[0, 1, 2]], np.uint32))
      >>> len(mesh_bytes([tri]))  # 4 (N) + 8 (counts) + 36 (vertices) + 12 (one triangle)
      60
    """
    meshes = [(np.asarray(v, "<f4").reshape(-1, 3), np.asarray(f, "<u4").reshape(-1, 3)) for v, f in meshes]
    counts = np.array([len(meshes)] + [n for v, f in meshes for n in (len(v), len(f))], "<u4")
    return b"".join([counts.tobytes()] + [a.tobytes() for v, f in meshes for a in (v, f)])


class ViewServer:
    """The live view's web server (start it, give it the scene and the body, publish states; it fills ``axes``).

    Args:
      host, port: where to listen (port 0: any free port; :attr:`url` tells which).
      axes: the :class:`~ijoy_jax.live.SharedAxes` the page's keyboard and gamepad set (a new one if None).
    """

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, axes: SharedAxes | None = None):
        self.host, self.port = host, int(port)
        self.axes = SharedAxes() if axes is None else axes
        self._scene: dict = {}
        self._png = b""
        self._state = "{}"
        self._version = 0
        self._terrain = None
        self._mesh = "null"
        self._geoms: BodyGeoms | None = None
        self._meshes = mesh_bytes([])
        self._bodies_version = 0
        self._footholds: list = []  # past chosen footholds: [x, y, z, yaw, side] (side +1 left)
        self._chosen = None  # the latest decision's foothold, until the next decision
        self._decision = None
        self._lock = threading.Lock()
        self._ready = threading.Event()
        self._loop = None
        self._thread = None
        self._error: BaseException | None = None
        self.clients = 0

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    # -- the drive's side ---------------------------------------------------------------------------------------

    def set_scene(self, terrain: Terrain, robot: Robot, start=None) -> None:
        """The terrain and the robot's footprint and step geometry (once per drive)."""
        nx, ny = terrain.shape
        p0 = np.asarray(robot.p0, np.float64)
        scene = {"origin": np.asarray(terrain.origin, np.float64).tolist(), "resolution": float(terrain.resolution),
                 "shape": [int(nx), int(ny)], "foot": [float(robot.foot_length), float(robot.foot_width)],
                 "step_time": float(robot.step_time), "p0": p0.tolist(), "has_height": bool(terrain.has_height),
                 "start": None if start is None else np.asarray(start, np.float64).tolist(),
                 "obstacle_height": DEFAULT_OBSTACLE_HEIGHT, "bodies": None}
        png = terrain_image(terrain)
        mesh = finite_json(terrain_mesh(terrain))
        with self._lock:
            self._scene, self._png, self._mesh = scene, png, mesh
            self._robot, self._terrain = robot, terrain
            self._geoms, self._footholds, self._chosen, self._decision = None, [], None, None
            self._meshes = mesh_bytes([])

    def set_body(self, body) -> None:
        """The robot that walks (once per drive, after :meth:`set_scene`; :func:`ijoy_jax.live.run`'s
        ``on_body``): the 3D view draws its geoms (:class:`~ijoy_jax.live.bodies.BodyGeoms`), their sizes in the
        scene, their meshes at ``/meshes.bin`` and their poses in every state :meth:`publish` sends. Publish from
        the thread that steps the body."""
        with self._lock:
            terrain, robot = self._terrain, getattr(self, "_robot", None)
        if terrain is None:
            raise RuntimeError("set_scene(terrain, robot) first: the body stands on the scene's terrain")
        geoms = BodyGeoms(body, terrain, robot)
        meshes = mesh_bytes(geoms.meshes())
        with self._lock:
            self._bodies_version += 1
            scene = dict(self._scene)
            scene["bodies"] = {"version": self._bodies_version, **geoms.describe()}
            if geoms.obstacle_height is not None:
                scene["obstacle_height"] = geoms.obstacle_height
            self._scene, self._geoms, self._meshes = scene, geoms, meshes

    def publish(self, state: dict) -> None:
        """The drive's latest state (:func:`ijoy_jax.live.drive`'s ``on_tick``); sent to every page."""
        state = dict(state)
        robot = getattr(self, "_robot", None)
        if robot is not None and "reach" in state and "next_stance" in state:
            state["reach_world"] = _reach_polygon(robot, state["next_stance"], state["next_side"], state["reach"],
                                                  state.get("reach_turn", 0.0))
        state["input_source"] = self.axes.source
        with self._lock:
            geoms, version = self._geoms, self._bodies_version
        if geoms is not None:
            pos, quat = geoms.poses()
            state["bodies"] = {"version": version, "pos": np.round(pos, _POSE_DECIMALS).ravel(),
                               "quat": np.round(quat, _POSE_DECIMALS).ravel()}
        state["footholds"] = self._past_footholds(state)
        text = finite_json(state)
        with self._lock:
            self._state = text
            self._version += 1

    def _past_footholds(self, state: dict) -> list:
        """The chosen footholds before the latest decision's, oldest first (at most :data:`MAX_FOOTHOLDS`), each
        [x, y, z, yaw, side] (m, rad; side +1 for the left foot): a decision's foothold joins them when the
        next decision arrives, if it was valid."""
        decision = state.get("decision")
        if decision is not None and decision != self._decision:
            if self._chosen is not None:
                self._footholds = (self._footholds + [self._chosen])[-MAX_FOOTHOLDS:]
            self._decision, self._chosen = decision, None
            f = np.asarray(state.get("foothold", np.full(6, np.nan)), np.float64).ravel()
            if state.get("valid") and f.shape == (6,) and np.all(np.isfinite(f)):
                side = -float(state.get("stance_side", 0.0))
                self._chosen = [round(float(v), 4) for v in (f[0], f[1], f[2], f[5])] + [side]
        return list(self._footholds)

    def state(self) -> dict:
        """The latest published state (as the page receives it)."""
        return json.loads(self.state_json())

    def state_json(self) -> str:
        """The latest published state as the JSON text the WebSocket sends ("{}" before the first :meth:`publish`):
        strict JSON, each non-finite number written null (:func:`finite_json`)."""
        with self._lock:
            return self._state

    def page(self) -> str:
        """The page as a browser loading it now gets it: :func:`page_html` of the scene and the latest state."""
        with self._lock:
            scene, state = self._scene, self._state
        return page_html(scene, state)

    # -- server -------------------------------------------------------------------------------------------------

    def start(self) -> ViewServer:
        """Start serving in a background thread; returns once it listens (raises OSError if it cannot)."""
        self._thread = threading.Thread(target=self._serve, name="ijoy-view", daemon=True)
        self._thread.start()
        self._ready.wait(30)
        if self._error is not None:
            raise self._error
        return self

    def close(self) -> None:
        if self._loop is not None and self._loop.is_running():
            self._loop.call_soon_threadsafe(self._stop.set)
        if self._thread is not None:
            self._thread.join(timeout=5)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.close()

    def _serve(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as e:  # noqa: BLE001 - reported to start()
            self._error = e
            self._ready.set()

    async def _main(self) -> None:
        from aiohttp import WSMsgType, web

        static = resources.files("ijoy_jax.live") / "static"

        async def page(_):
            return web.Response(text=self.page(), content_type="text/html", headers={"Cache-Control": "no-store"})

        async def script(_):
            return web.Response(text=(static / "view.js").read_text(), content_type="application/javascript")

        vendored = {name: (static / name).read_bytes() for name in _VENDORED}

        def static_file(name):
            async def handler(_):
                return web.Response(body=vendored[name], content_type=_VENDORED[name],
                                    headers={"Cache-Control": "max-age=3600"})

            return handler

        async def mesh(_):
            with self._lock:
                return web.Response(text=self._mesh, content_type="application/json",
                                    headers={"Cache-Control": "no-store"})

        async def meshes(_):
            with self._lock:
                data = self._meshes
            return web.Response(body=data, content_type="application/octet-stream",
                                headers={"Cache-Control": "no-store"})

        async def png(_):
            with self._lock:
                data = self._png
            return web.Response(body=data, content_type="image/png", headers={"Cache-Control": "no-store"})

        async def scene(_):
            with self._lock:
                return web.Response(text=finite_json(self._scene), content_type="application/json",
                                    headers={"Cache-Control": "no-store"})

        async def state(_):
            with self._lock:
                return web.Response(text=self._state, content_type="application/json")

        async def socket(request):
            ws = web.WebSocketResponse(heartbeat=20, max_msg_size=MAX_MESSAGE_BYTES)
            await ws.prepare(request)
            self.clients += 1

            async def sender():
                sent = -1
                while not ws.closed:
                    with self._lock:
                        version, text = self._version, self._state
                    if version != sent:
                        try:
                            await ws.send_str(text)
                        except (ConnectionError, RuntimeError):  # the page went away
                            return
                        sent = version
                    await asyncio.sleep(0.04)

            task = asyncio.create_task(sender())
            try:
                async for msg in ws:
                    if msg.type != WSMsgType.TEXT:
                        continue
                    data = page_message(msg.data)
                    if data is None or data.get("type") != "axes":
                        continue
                    try:
                        self.axes.set(data["axes"], str(data.get("source", "view"))[:32])
                    except (ValueError, KeyError, TypeError):
                        continue  # a malformed stick message from a page is ignored, not fatal
            finally:
                task.cancel()
                self.clients -= 1
            return ws

        app = web.Application()
        app.add_routes([web.get("/", page), web.get("/3d", page), web.get("/view.js", script),
                        web.get("/terrain.png", png), web.get("/terrain3d.json", mesh), web.get("/scene.json", scene),
                        web.get("/state.json", state), web.get("/meshes.bin", meshes), web.get("/ws", socket)]
                       + [web.get("/" + name, static_file(name)) for name in _VENDORED])
        runner = web.AppRunner(app, access_log=None)
        await runner.setup()
        site = web.TCPSite(runner, self.host, self.port)
        await site.start()
        self.port = int(runner.addresses[0][1])
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        self._ready.set()
        await self._stop.wait()
        await runner.cleanup()


def _reach_polygon(robot: Robot, stance, stance_side, reach, turn) -> list:
    """(K, 2) world points: the next step's ideal foothold at the largest open speed per direction."""
    reach = np.asarray(reach, np.float64)
    k = reach.shape[0]
    phi = 2 * np.pi * np.arange(k) / k
    swing = -float(stance_side)
    p0 = np.asarray(robots.side_p0(robot, swing), np.float64)
    dt = float(robot.step_time)
    rel = np.stack([p0[0] + dt * reach * np.cos(phi), p0[1] + dt * reach * np.sin(phi)], 1)
    st = np.asarray(stance, np.float64)
    c, s = np.cos(st[2]), np.sin(st[2])
    return np.stack([st[0] + c * rel[:, 0] - s * rel[:, 1], st[1] + s * rel[:, 0] + c * rel[:, 1]], 1).tolist()

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

On a remote GPU machine: ``ijoy drive --port 8765`` there, ``ssh -L 8765:localhost:8765 HOST`` here, and
open http://localhost:8765 (docs/drive.md). The server binds 127.0.0.1 by default.
"""

from __future__ import annotations

import asyncio
import io
import json
import threading
from importlib import resources

import numpy as np

from ijoy_jax import robots
from ijoy_jax.live.inputs import SharedAxes
from ijoy_jax.recordings import json_ready
from ijoy_jax.robots import Robot
from ijoy_jax.terrain import Terrain

__all__ = ["DEFAULT_PORT", "MAX_MESSAGE_BYTES", "ViewServer", "page_html", "page_message", "terrain_image"]

DEFAULT_PORT = 8765
"""The view's default TCP port."""
MAX_MESSAGE_BYTES = 4096
"""Largest WebSocket message a page may send (a stick message is under 100 bytes); aiohttp closes a connection
that sends more."""


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
    data = '{"scene": ' + json.dumps(scene) + ', "state": ' + state + "}"
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


class ViewServer:
    """The live view's web server (start it, give it the scene, publish states; it fills ``axes``).

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
                 "start": None if start is None else np.asarray(start, np.float64).tolist()}
        png = terrain_image(terrain)
        with self._lock:
            self._scene, self._png = scene, png
            self._robot = robot

    def publish(self, state: dict) -> None:
        """The drive's latest state (:func:`ijoy_jax.live.drive`'s ``on_tick``); sent to every page."""
        state = dict(state)
        robot = getattr(self, "_robot", None)
        if robot is not None and "reach" in state and "next_stance" in state:
            state["reach_world"] = _reach_polygon(robot, state["next_stance"], state["next_side"], state["reach"],
                                                  state.get("reach_turn", 0.0))
        state["input_source"] = self.axes.source
        text = json.dumps(json_ready(state))
        with self._lock:
            self._state = text
            self._version += 1

    def state(self) -> dict:
        """The latest published state (as the page receives it)."""
        with self._lock:
            return json.loads(self._state)

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
            with self._lock:
                scene, state = self._scene, self._state
            return web.Response(
                text=page_html(scene, state), content_type="text/html", headers={"Cache-Control": "no-store"}
            )

        async def script(_):
            return web.Response(text=(static / "view.js").read_text(), content_type="application/javascript")

        async def png(_):
            with self._lock:
                data = self._png
            return web.Response(body=data, content_type="image/png", headers={"Cache-Control": "no-store"})

        async def scene(_):
            with self._lock:
                return web.json_response(self._scene)

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
        app.add_routes([web.get("/", page), web.get("/view.js", script), web.get("/terrain.png", png),
                        web.get("/scene.json", scene), web.get("/state.json", state), web.get("/ws", socket)])
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

"""The live view in a real browser: Debian's Chromium (headless) driven by Playwright against the view's real
aiohttp server and a real-time drive. The page loads, draws the scene, and a key held in the page changes the
command the drive loop sees. The map is the small one of every server and live test (tests/_server_util.py), so
the drive's programs are those tests/test_live.py compiled on the same xdist worker (tests/conftest.py).
The page's first paint (at its load event, before any WebSocket message) shows the robot, and its metre axes
agree with the map's extent. What needs no browser (the page's embedded JSON) is in the fast tier."""

import json
import shutil
import threading
import time
import urllib.request
from html.parser import HTMLParser

import numpy as np
import pytest
from _server_util import RES, SHAPE  # tests/ is on sys.path (pytest rootdir import)
from hypothesis import given, settings
from hypothesis import strategies as st

from ijoy_jax import live
from ijoy_jax.live.view import ViewServer, page_html

slow = pytest.mark.slow  # drives Debian's Chromium, a system package .ci/run installs

NO_WEBSOCKET = "window.WebSocket = function () { return { send() {}, close() {}, readyState: 0 }; };"
"""A page init script: a WebSocket that never connects, so what the page shows came with the page itself."""
AXIS_RGB = (200, 208, 216)  # view.js's axis colour, #c8d0d8
FEET_RGB = {"left": (58, 123, 213), "right": (232, 163, 61)}  # view.js's feet fills (drawn at 0.85 alpha)
COLOUR_TOL = 40  # per channel: the feet's alpha blend over the terrain and the outline's antialiasing

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def _browser():
    if CHROMIUM is None:
        pytest.fail("the live-view test needs Chromium: apt-get update && apt-get install -y chromium "
                    "(.ci/run installs it)")
    from playwright.sync_api import sync_playwright

    return sync_playwright()


SMALL_MAP = {"kind": "family", "family": "obstacles", "seed": 3, "shape": list(SHAPE), "resolution": RES}


def _drive_in_view(body: str, wait_s: float, model: str = "biped"):
    """A real-time drive of ``body`` (of ``model``) on the small clutter map, its stick the view's, and the view's
    server with its 3D body: yields the server once the drive ticks (within ``wait_s``), then stops the drive."""
    settings = live.DriveSettings(terrain=SMALL_MAP, body=body, model=model)
    terrain, robot, start = live.open_terrain(settings.terrain, model=model)
    view = ViewServer(port=0).start()
    view.set_scene(terrain, robot, start)
    stop = threading.Event()
    out = {}
    ready = threading.Event()

    def on_tick(state):
        view.publish(state)
        ready.set()

    def run():
        out["result"] = live.run(settings, view.axes, realtime=True, on_tick=on_tick, stop=stop, terrain=terrain,
                                 robot=robot, start=start, on_body=view.set_body)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    assert ready.wait(wait_s), "the drive never ticked"
    yield view
    stop.set()
    thread.join(timeout=60)
    view.close()
    assert out["result"].decisions, "the drive made no decision"


@pytest.fixture(scope="module")
def drive_with_view():
    """A real-time drive of the perfect robot on a clutter map, its stick the view's, and the view's server (its
    3D body the robot's soles)."""
    yield from _drive_in_view("perfect", 120)


@slow
def test_view_loads_draws_and_keys_drive_the_loop(drive_with_view, tmp_path):
    view = drive_with_view
    with _browser() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1200, "height": 760})
        page.goto(view.url)
        # the page has the scene, is receiving states and drawing them
        page.wait_for_function("window.ijoy && window.ijoy.states > 5 && window.ijoy.frames > 5", timeout=30000)
        assert np.allclose(view.state()["command"], 0.0)  # nobody touches the stick yet
        page.click("#map")
        page.keyboard.down("w")
        page.keyboard.down("q")
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not (view.state()["command"][0] > 0 and view.state()["command"][2] > 0):
            time.sleep(0.05)  # both key-downs, each its own event
        cmd = view.state()["command"]
        assert cmd[0] == pytest.approx(0.25) and cmd[2] > 0.4, cmd  # full forward and full left turn (HRP-2 range)
        assert view.axes.source == "keyboard"
        # wait for a decision made with the held command, so the picture shows the robot turning
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not view.state().get("reach_turn", 0) > 0:
            time.sleep(0.05)
        shot = tmp_path / "view.png"
        page.screenshot(path=str(shot))
        page.keyboard.up("w")
        page.keyboard.up("q")
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and any(view.state()["command"]):  # both key-ups, each its own event
            time.sleep(0.05)
        assert view.state()["command"] == [0.0, 0.0, 0.0]  # released: the loop sees the stick centred
        browser.close()
    from PIL import Image

    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert img.shape[:2] == (760, 1200)
    # the scene is drawn: the terrain's light ground, dark obstacles and the feet's blue and orange are on screen
    colours = img.reshape(-1, 3)
    blue = np.all(np.abs(colours - [58, 123, 213]) < 40, axis=1).sum()
    orange = np.all(np.abs(colours - [232, 163, 61]) < 40, axis=1).sum()
    assert blue > 100 and orange > 100, (blue, orange)
    assert len(np.unique(colours // 16, axis=0)) > 30  # a picture, not a blank page


class _Initial(HTMLParser):
    """The text of the page's ``<script id="ijoy-initial">`` element, as a browser's parser delimits it."""

    def __init__(self):
        super().__init__()
        self.inside, self.text, self.found = False, "", 0

    def handle_starttag(self, tag, attrs):
        if tag == "script" and dict(attrs).get("id") == "ijoy-initial":
            self.inside, self.found = True, self.found + 1

    def handle_endtag(self, tag):
        self.inside = False

    def handle_data(self, data):
        if self.inside:
            self.text += data


_json_text = st.lists(
    st.sampled_from(["<", ">", "/", "!", "-", "&", '"', "\\", "script", "</script>", "<!--", "\u2028", "é", "x", " "]),
    max_size=8,
).map("".join)  # strings made of the pieces that could end or confuse an HTML script element
_json_value = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(10**6), 10**6)
    | st.floats(allow_nan=False, allow_infinity=False)
    | _json_text,
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(_json_text, inner, max_size=3),
    max_leaves=8,
)


@given(
    scene=st.dictionaries(_json_text, _json_value, max_size=3),
    state=st.dictionaries(_json_text, _json_value, max_size=4),
)
@settings(derandomize=True, deadline=None, max_examples=60)
def test_page_carries_the_scene_and_state_whatever_their_text(scene, state):
    # any text in a scene or state (``</script>``, ``<!--``) comes back as the same JSON value from the one script
    # element the page reads it from: nothing in a state can end that element early or inject markup
    parser = _Initial()
    parser.feed(page_html(scene, json.dumps(state)))
    parser.close()
    assert parser.found == 1
    assert json.loads(parser.text) == {"scene": scene, "state": state}


def test_page_before_the_drive_starts_carries_an_empty_scene():
    # a server asked for the page before set_scene: the page falls back to waiting for scene.json
    parser = _Initial()
    parser.feed(page_html({}, "{}"))
    assert json.loads(parser.text) == {"scene": {}, "state": {}}


def _launch(p):
    return p.chromium.launch(executable_path=CHROMIUM, headless=True, args=["--no-sandbox"])


def _feet_pixels(img):
    colours = img.reshape(-1, 3)
    return {side: int(np.all(np.abs(colours - rgb) < COLOUR_TOL, axis=1).sum()) for side, rgb in FEET_RGB.items()}


@slow
def test_first_paint_at_load_shows_the_robot_without_the_websocket(drive_with_view, tmp_path):
    # the page's WebSocket never connects here: the terrain and the feet on the screenshot taken as the load event
    # fires came with the page itself
    view = drive_with_view
    shot = tmp_path / "first_paint.png"
    with _browser() as p:
        browser = _launch(p)
        page = browser.new_page(viewport={"width": 1200, "height": 760})
        page.add_init_script(NO_WEBSOCKET)
        page.goto(view.url, wait_until="load")
        page.screenshot(path=str(shot))
        status = page.inner_text("#status")
        box = page.locator("#map").bounding_box()
        got = page.evaluate("({states: window.ijoy.states, initial: window.ijoy.initial, frames: window.ijoy.frames})")
        browser.close()
    from PIL import Image

    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert got["states"] == 0 and got["initial"] is True and got["frames"] >= 1, got
    assert status.startswith("step ") and "connecting" not in status, status
    x0, y0 = int(box["x"]), int(box["y"])
    canvas = img[y0 : y0 + int(box["height"]), x0 : x0 + int(box["width"])]
    feet = _feet_pixels(canvas)
    assert feet["left"] > 100 and feet["right"] > 100, feet
    assert len(np.unique(canvas.reshape(-1, 3) // 16, axis=0)) > 10  # the terrain, not an empty map


@slow
def test_map_axes_are_in_metres_along_the_maps_edges(drive_with_view, tmp_path):
    view = drive_with_view
    with urllib.request.urlopen(view.url + "scene.json", timeout=10) as r:
        scene = json.load(r)
    shot = tmp_path / "axes.png"
    with _browser() as p:
        browser = _launch(p)
        page = browser.new_page(viewport={"width": 1200, "height": 760})
        page.goto(view.url, wait_until="load")
        page.wait_for_function("document.getElementById('map').dataset.xTicks !== undefined", timeout=10000)
        page.screenshot(path=str(shot))
        d = page.evaluate("({...document.getElementById('map').dataset})")
        browser.close()
    ox, oy = scene["origin"]
    wx, wy = SHAPE[0] * RES, SHAPE[1] * RES  # 2 m x 1.6 m
    step = float(d["tickStep"])
    assert step == 0.5
    xt, yt = json.loads(d["xTicks"]), json.loads(d["yTicks"])
    assert xt == pytest.approx([ox + 0.5 * i for i in range(5)])  # 0, 0.5, ..., 2.0 from the map's origin
    assert yt == pytest.approx([oy + 0.5 * i for i in range(4)])  # 0, 0.5, 1.0, 1.5
    assert json.loads(d["xTickLabels"]) == [f"{v:.1f}" for v in xt]
    assert json.loads(d["yTickLabels"]) == [f"{v:.1f}" for v in yt]
    # each tick sits where its value is on the drawn map: left to right for x, bottom to top for y
    left, top, right, bottom = json.loads(d["mapPx"])
    xpx, ypx = np.array(json.loads(d["xTicksPx"])), np.array(json.loads(d["yTicksPx"]))
    assert xpx == pytest.approx(left + (np.array(xt) - ox) / wx * (right - left), abs=0.5)
    assert ypx == pytest.approx(bottom - (np.array(yt) - oy) / wy * (bottom - top), abs=0.5)
    from PIL import Image

    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    near_axis = lambda patch: int(np.all(np.abs(patch - AXIS_RGB) < COLOUR_TOL, axis=-1).sum())  # noqa: E731
    for x in xpx:  # the tick mark under the map's bottom edge and its label below it
        x = int(round(x))
        assert near_axis(img[int(bottom) + 2 : int(bottom) + 7, x - 1 : x + 2]) > 0, x
        assert near_axis(img[int(bottom) + 9 : int(bottom) + 24, x - 14 : x + 15]) > 5, x
    for y in ypx:  # the tick mark left of the map's left edge and its label left of it
        y = int(round(y))
        assert near_axis(img[y - 1 : y + 2, int(left) - 7 : int(left) - 2]) > 0, y
        assert near_axis(img[y - 8 : y + 9, int(left) - 40 : int(left) - 10]) > 5, y


_NICE = {m * 10.0**e for m in (1, 2, 2.5, 5) for e in range(-3, 7)}


@slow
def test_axis_ticks_suit_any_map():
    # the tick rule over map extents from 5 cm to 500 m, at any origin, drawn 360 to 4000 px wide: a step of 1, 2,
    # 2.5 or 5 times a power of ten, ticks at its multiples covering the extent (3 to 7 of them, 60 px apart or
    # more), labels that read back as their values
    with _browser() as p:
        browser = _launch(p)
        page = browser.new_page()
        page.set_content("<canvas id='map'></canvas><div id='status'></div><script>" + _view_js() + "</script>")

        @given(lo=st.floats(-1000, 1000), extent=st.floats(0.05, 500), px=st.floats(360, 4000))
        @settings(derandomize=True, deadline=None, max_examples=60)
        def check(lo, extent, px):
            k = px / extent
            got = page.evaluate(
                "([lo, e, k]) => { const s = tickStep(e, k); return [s, ticks(lo, lo + e, s)]; }", [lo, extent, k]
            )
            step, ticks = got
            assert any(step == pytest.approx(n, rel=1e-12) for n in _NICE), step
            assert extent / step <= 6 + 1e-9 and step * k >= 60 - 1e-9
            values = np.array([t["value"] for t in ticks])
            assert 3 <= len(values) <= 7, (step, values)
            tol = 1e-6 * max(1.0, abs(lo) + extent)
            assert values[0] >= lo - tol and values[-1] <= lo + extent + tol
            assert values[0] - lo < step + tol and lo + extent - values[-1] < step + tol
            assert np.diff(values) == pytest.approx(step, abs=tol)
            assert np.round(values / step) * step == pytest.approx(values, abs=tol)
            assert [float(t["label"]) for t in ticks] == pytest.approx(values, abs=tol)

        check()
        browser.close()


def _view_js():
    from importlib import resources

    return (resources.files("ijoy_jax.live") / "static" / "view.js").read_text()


# ------------------------------------------------------------------------------------------------- the 3D view

def _strict(text):
    """JSON text parsed as a browser's JSON.parse would: NaN, Infinity and -Infinity are not JSON."""

    def refuse(token):
        raise ValueError(f"not JSON: {token}")

    return json.loads(text, parse_constant=refuse)


def _small_scene():
    import ijoy_jax as ij

    robot = ij.robots.hrp2()
    return ij.terrain.flat((20, 16), 0.05), robot


def test_published_states_and_scene_are_strict_json_with_nan_as_null():
    # a diverged simulation or an invalid candidate's cost (NaN, inf) in a state, a NaN in the scene: every text
    # the view sends parses as strict JSON, each non-finite number null, the finite ones unchanged
    terrain, robot = _small_scene()
    view = ViewServer(port=0)  # not started: publish and the page need no server
    view.set_scene(terrain, robot, np.array([[0.5, 0.6, np.nan], [0.5, 0.4, 0.0]]))
    nan, inf = float("nan"), float("inf")
    view.publish({"t": np.float32(0.5), "latency_s": nan, "candidate_cost": np.array([1.5, inf, -inf, np.nan]),
                  "feet": np.array([[0.5, 0.6, 0.0], [np.nan, 0.4, 0.0]], np.float32), "nested": {"x": [inf, (nan, 2)]},
                  "flags": np.array([True, False]), "step": np.int64(3)})
    text = view.state_json()
    got = _strict(text)
    assert got["latency_s"] is None and got["candidate_cost"] == [1.5, None, None, None]
    assert got["feet"] == [[0.5, pytest.approx(0.6), 0.0], [None, pytest.approx(0.4), 0.0]]
    assert got["nested"] == {"x": [None, [None, 2]]} and got["flags"] == [True, False] and got["step"] == 3
    assert got["t"] == 0.5 and view.state() == got
    parser = _Initial()
    parser.feed(view.page())
    page = _strict(parser.text)
    assert page["scene"]["start"] == [[0.5, 0.6, None], [0.5, 0.4, 0.0]] and page["state"] == got


@given(value=st.recursive(st.floats() | st.integers(-(10**6), 10**6) | st.booleans() | st.none() | st.text(max_size=4),
                          lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=3), inner,
                                                                                       max_size=3), max_leaves=10))
@settings(derandomize=True, deadline=None, max_examples=80)
def test_finite_json_is_strict_json_of_the_same_finite_values(value):
    from ijoy_jax.live.view import finite_json

    def expect(x):  # the value with every NaN and infinity as None
        if isinstance(x, dict):
            return {k: expect(v) for k, v in x.items()}
        if isinstance(x, list):
            return [expect(v) for v in x]
        if isinstance(x, float) and not np.isfinite(x):
            return None
        return x

    assert _strict(finite_json(value)) == expect(value)


def test_perfect_body_geoms_are_its_soles_on_the_ground():
    # the perfect robot's 3D bodies: two boxes of its footprint at its feet, standing on a 2.5D map's heights
    import ijoy_jax as ij
    from ijoy_jax.live.bodies import SOLE_THICKNESS, BodyGeoms

    robot = ij.robots.hrp2()
    height = np.zeros((20, 16), np.float32)
    height[10:] = 0.07  # a 7 cm step from x = 0.5 m on
    terrain = ij.terrain.from_arrays(height, resolution=0.05)
    start = np.array([[0.3, 0.5, 0.2], [0.7, 0.3, -0.4]], np.float32)
    geoms = BodyGeoms(live.PerfectBody(robot, start), terrain, robot)
    assert geoms.names == ("left_sole", "right_sole") and geoms.types == ("box", "box")
    np.testing.assert_allclose(geoms.sizes[0], [robot.foot_length / 2, robot.foot_width / 2, SOLE_THICKNESS / 2])
    pos, quat = geoms.poses()
    np.testing.assert_allclose(pos, [[0.3, 0.5, SOLE_THICKNESS / 2], [0.7, 0.3, 0.07 + SOLE_THICKNESS / 2]],
                               atol=1e-6)
    np.testing.assert_allclose(quat, [[np.cos(0.1), 0, 0, np.sin(0.1)], [np.cos(-0.2), 0, 0, np.sin(-0.2)]],
                               atol=1e-6)
    described = geoms.describe()
    assert described["types"] == ["box", "box"] and np.shape(described["rgba"]) == (2, 4)
    assert described["mesh"] == [-1, -1] and geoms.meshes() == []
    assert geoms.obstacle_height is None


def _parse_meshes(data: bytes) -> list:
    """/meshes.bin as view3d.js's parseMeshes reads it: N, then N (vertex, triangle) counts, then the arrays."""
    words = np.frombuffer(data, "<u4")
    n = int(words[0])
    counts, at, out = words[1 : 1 + 2 * n].reshape(n, 2), 4 * (1 + 2 * n), []
    for nv, nf in counts:
        v = np.frombuffer(data, "<f4", 3 * int(nv), at).reshape(-1, 3)
        at += 12 * int(nv)
        f = np.frombuffer(data, "<u4", 3 * int(nf), at).reshape(-1, 3)
        at += 12 * int(nf)
        out.append((v, f))
    assert at == len(data)  # nothing after the last mesh
    return out


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 40), st.integers(0, 30)), max_size=4), st.integers(0, 2**31))
def test_mesh_bytes_are_what_the_page_reads(sizes, seed):
    from ijoy_jax.live.view import mesh_bytes

    rng = np.random.default_rng(seed)
    meshes = [(rng.normal(size=(nv, 3)).astype(np.float32), rng.integers(0, nv, (nf, 3)).astype(np.uint32))
              for nv, nf in sizes]
    back = _parse_meshes(mesh_bytes(meshes))
    assert len(back) == len(meshes)
    for (v, f), (v2, f2) in zip(meshes, back, strict=True):
        np.testing.assert_array_equal(v2, v)
        np.testing.assert_array_equal(f2, f)


def test_terrain_mesh_has_a_vertex_per_cell_and_samples_large_maps():
    from ijoy_jax import terrain as terrain_mod
    from ijoy_jax.live.view import MAX_MESH_SIDE, terrain_mesh

    height = np.arange(6 * 4, dtype=np.float32).reshape(6, 4) / 100
    free = np.ones((6, 4), bool)
    free[2, 3] = False
    mesh = terrain_mesh(terrain_mod.from_arrays(height, free, resolution=0.1, origin=(1.0, -1.0)))
    assert (mesh["nx"], mesh["ny"], mesh["stride"]) == (6, 4, 1) and mesh["step"] == pytest.approx(0.1)
    assert mesh["origin"] == pytest.approx([1.05, -0.95])  # cell (0, 0)'s centre
    z = np.array(mesh["z"]).reshape(4, 6)  # row j along y, vertex i of row j at j * nx + i
    np.testing.assert_allclose(z, height.T, atol=5e-4)
    assert np.flatnonzero(mesh["obstacle"]).tolist() == [3 * 6 + 2]
    n = MAX_MESH_SIDE * 2 + 1  # a map wider than the mesh's limit: every third cell, a wall kept where it is thin
    free = np.ones((n, 3), bool)
    free[4, :] = False
    big = terrain_mesh(terrain_mod.flat((n, 3), 0.02).replace(free=free))
    assert big["stride"] == 3 and big["nx"] == (n + 2) // 3 and big["ny"] == 1
    assert np.flatnonzero(big["obstacle"]).tolist() == [1]


def test_published_states_carry_past_footholds():
    # a decision's foothold joins the past ones when the next decision arrives, if it was valid; its side is the
    # swing foot's (the decision's stance side negated)
    terrain, robot = _small_scene()
    view = ViewServer(port=0)
    view.set_scene(terrain, robot)
    f = lambda x: np.array([x, 0.5, 0.0, 0.0, 0.0, 0.1], np.float32)  # noqa: E731
    decisions = [(1, f(0.2), True, -1.0), (1, f(0.2), True, -1.0), (2, f(0.4), True, 1.0), (3, f(np.nan), False, -1.0),
                 (4, f(0.6), True, -1.0), (5, f(0.8), True, 1.0)]
    seen = []
    for j, foothold, valid, side in decisions:
        view.publish({"decision": j, "foothold": foothold, "valid": valid, "stance_side": side})
        seen.append(view.state()["footholds"])
    assert seen[0] == seen[1] == []
    assert seen[2] == [[0.2, 0.5, 0.0, pytest.approx(0.1), 1.0]]
    assert seen[3] == seen[2] + [[0.4, 0.5, 0.0, pytest.approx(0.1), -1.0]]
    assert seen[4] == seen[3]  # the invalid decision 3 stood: no foothold
    assert [p[0] for p in seen[5]] == [0.2, 0.4, 0.6]


LEG_RGB = (0.5, 0.5, 0.9)  # the MuJoCo biped's thighs and shins (sim.model's geom rgba): the one blue on screen
BLUE_OVER = 25  # a leg pixel: blue above red and green by this much (lit and shaded, still blue)


@pytest.fixture(scope="module")
def native_drive_with_view():
    """A real-time drive of the MuJoCo biped on native MuJoCo on the small clutter map, the view's stick, and
    the view's server with its 3D body."""
    yield from _drive_in_view("native", 300)


def _robot_x(view):
    """m: the mean x of the robot's geoms in the latest published state."""
    return float(np.mean(np.reshape(view.state()["bodies"]["pos"], (-1, 3))[:, 0]))


def _legs_on_screen(img, pixels):
    """Per leg geom (thigh, shin), the blue pixels in a 15 px square at its projected centre."""
    out = {}
    for name, x, y, front in pixels:
        if not any(part in name for part in ("thigh", "shin")):
            continue
        x, y = int(round(x)), int(round(y))
        assert front and 0 <= x < img.shape[1] and 0 <= y < img.shape[0], (name, x, y)  # in view
        patch = img[max(0, y - 7) : y + 8, max(0, x - 7) : x + 8].reshape(-1, 3)
        blue = (patch[:, 2] > patch[:, 0] + BLUE_OVER) & (patch[:, 2] > patch[:, 1] + BLUE_OVER)
        out[name] = int(blue.sum())
    return out


@slow
def test_3d_view_shows_the_robot_and_follows_it(native_drive_with_view, tmp_path):
    # /3d in Chromium (WebGL): the terrain mesh and every geom of the MuJoCo biped at its simulated pose; its
    # legs' blue is on screen where the page projects them; held forward, the robot walks and the camera follows
    # it, so the legs are still in view after it walked
    view = native_drive_with_view
    scene = json.load(urllib.request.urlopen(view.url + "scene.json", timeout=10))
    bodies = scene["bodies"]
    assert len(bodies["names"]) == len(bodies["types"]) >= 10 and "torso" in bodies["names"]
    assert set(bodies["types"]) <= {"box", "sphere", "capsule", "cylinder", "ellipsoid"}
    legs = [n for n in bodies["names"] if "thigh" in n or "shin" in n]
    for name in legs:
        assert bodies["rgba"][bodies["names"].index(name)][:3] == pytest.approx(LEG_RGB)
    state = view.state()
    n = len(bodies["names"])
    assert len(state["bodies"]["pos"]) == 3 * n and len(state["bodies"]["quat"]) == 4 * n
    shots = [tmp_path / "view3d_start.png", tmp_path / "view3d_walked.png"]
    from PIL import Image

    with _browser() as p:
        browser = _launch(p)
        page = browser.new_page(viewport={"width": 1200, "height": 760})
        errors = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(view.url + "3d")
        page.wait_for_function("window.ijoy3d && ijoy3d.terrain && ijoy3d.bodies > 0 && ijoy3d.frames > 3",
                               timeout=60000)
        assert page.evaluate("ijoy3d.bodies") == len(bodies["names"])
        page.screenshot(path=str(shots[0]))
        before = page.evaluate("({pixels: ijoy3d.bodyPixels(), follow: ijoy3d.follow})")
        x0 = _robot_x(view)
        view.axes.set([1.0, 0.0, 0.0], "test")  # full forward
        deadline = time.monotonic() + 40
        while time.monotonic() < deadline and _robot_x(view) < x0 + 0.3:
            time.sleep(0.1)
        view.axes.set([0.0, 0.0, 0.0], "test")
        walked = _robot_x(view) - x0
        time.sleep(1.0)  # the camera's target catches up (a fraction of the way each frame)
        page.screenshot(path=str(shots[1]))
        after = page.evaluate("({pixels: ijoy3d.bodyPixels(), follow: ijoy3d.follow})")
        box = page.locator("#view3d canvas").bounding_box()
        browser.close()
    assert not errors, errors
    assert walked > 0.3, walked
    assert after["follow"][0] - before["follow"][0] > 0.25, (before["follow"], after["follow"])  # the camera followed
    for shot, seen in zip(shots, (before, after), strict=True):
        img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
        canvas = img[int(box["y"]) : int(box["y"] + box["height"]), int(box["x"]) : int(box["x"] + box["width"])]
        assert len(np.unique(canvas.reshape(-1, 3) // 16, axis=0)) > 30, shot  # a picture, not a blank canvas
        dark = np.all(np.abs(canvas.reshape(-1, 3) - [70, 40, 36]) < 30, axis=1).sum()
        assert dark > 50, (shot, dark)  # the map's obstacles, dark on the mesh
        on_screen = _legs_on_screen(img, seen["pixels"])
        assert len(on_screen) == len(legs) == 4, on_screen
        assert sum(n > 20 for n in on_screen.values()) >= 3, (shot, on_screen)  # the legs' blue where they are drawn
    print(f"3D view screenshots: {shots[0]} {shots[1]}")


@slow
def test_the_g1s_bodies_are_its_visual_meshes_where_the_renderer_draws_them():
    # the G1 on native MuJoCo: what the 3D view draws of it is what ijoy_jax.sim.render draws, from the same model
    # (sim.bodies.build_model(..., meshes=True)): its visible geoms (MuJoCo's default groups 0-2: the meshes, not
    # the collision capsules), its meshes' vertices in their geoms' frames, at the kinematics of the body's qpos
    import mujoco

    from ijoy_jax.live.bodies import BodyGeoms
    from ijoy_jax.live.view import mesh_bytes
    from ijoy_jax.sim import bodies as sim_bodies

    terrain, robot, start = live.open_terrain(SMALL_MAP, model="g1")
    body = live.session.build_body("native", terrain, robot, start, model="g1")
    geoms = BodyGeoms(body, terrain, robot)
    m = sim_bodies.build_model(body.sim.params, terrain, meshes=True)
    ids = [g for g in range(m.ngeom) if m.geom_bodyid[g] > 0 and m.geom_type[g] > 1 and m.geom_rgba[g, 3] > 0
           and m.geom_group[g] <= 2]
    is_mesh = np.array([m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH for g in ids])
    assert len(geoms.names) == len(ids) and is_mesh.sum() > 50
    assert [t == "mesh" for t in geoms.types] == is_mesh.tolist() and ((geoms.mesh >= 0) == is_mesh).all()
    assert not {"left_thigh", "left_shin", "left_foot"} & set(geoms.names)  # the collision shapes are hidden
    meshes = geoms.meshes()
    assert len(meshes) == geoms.mesh.max() + 1 == len({int(m.geom_dataid[g]) for g in np.asarray(ids)[is_mesh]})
    for k, g in enumerate(ids):
        if not is_mesh[k]:
            continue
        v = meshes[geoms.mesh[k]][0]
        lo, hi = v.min(0), v.max(0)  # MuJoCo's bounding box in the geom's frame is the vertices'
        np.testing.assert_allclose(np.r_[(lo + hi) / 2, (hi - lo) / 2], m.geom_aabb[g], atol=1e-5)
        assert meshes[geoms.mesh[k]][1].max() < len(v)
    d = mujoco.MjData(m)
    d.qpos[:] = body.d.qpos
    mujoco.mj_kinematics(m, d)
    pos, quat = geoms.poses()
    np.testing.assert_allclose(pos[is_mesh], d.geom_xpos[np.asarray(ids)[is_mesh]], atol=1e-12)
    mesh_rgb = {tuple(np.round(c[:3], 2)) for c in geoms.rgba[is_mesh]}
    assert mesh_rgb == {(0.7, 0.7, 0.7), (0.2, 0.2, 0.2)}  # the G1's materials, silver and black
    assert len(mesh_bytes(meshes)) > 10**6  # megabytes: served once per body, not with every state


@pytest.fixture(scope="module")
def g1_drive_with_view():
    """A real-time drive of the Unitree G1 on native MuJoCo on the small clutter map, and the view's server."""
    yield from _drive_in_view("native", 300, model="g1")


GREY_SPREAD, GREY_MIN = 10, 70  # a G1 pixel: its silver or dark grey, lit (channels within this of each other;
# the terrain's lightest green spreads 18, the background is darker)
ROBOT_PX = 80  # px: how far the robot's pixels reach beyond the projected centres of its geoms


@slow
def test_3d_view_draws_the_g1_with_its_meshes(g1_drive_with_view, tmp_path):
    # /3d in Chromium: the G1's visual meshes come from /meshes.bin after the scene and replace their placeholder
    # boxes; on screen the robot is its grey, where the page projects its geoms, and nothing else is
    from PIL import Image

    view = g1_drive_with_view
    scene = json.load(urllib.request.urlopen(view.url + "scene.json", timeout=10))
    bodies = scene["bodies"]
    uses = [k for k in bodies["mesh"] if k >= 0]
    data = urllib.request.urlopen(view.url + "meshes.bin", timeout=30).read()
    assert len(_parse_meshes(data)) == max(uses) + 1 and bodies["types"].count("mesh") == len(uses) > 50
    shot = tmp_path / "view3d_g1.png"
    with _browser() as p:
        browser = _launch(p)
        page = browser.new_page(viewport={"width": 1200, "height": 760})
        errors = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(view.url + "3d")
        page.wait_for_function("window.ijoy3d && ijoy3d.terrain && ijoy3d.meshes > 0 && ijoy3d.frames > 3",
                               timeout=60000)
        assert page.evaluate("ijoy3d.meshes") == max(uses) + 1
        time.sleep(1.0)  # the camera's target settles on the robot
        page.screenshot(path=str(shot))
        pixels = page.evaluate("ijoy3d.bodyPixels()")
        box = page.locator("#view3d canvas").bounding_box()
        browser.close()
    assert not errors, errors
    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    x0, y0 = int(box["x"]), int(box["y"])
    canvas = img[y0 : y0 + int(box["height"]), x0 : x0 + int(box["width"])]
    grey = (canvas.max(2) - canvas.min(2) < GREY_SPREAD) & (canvas.max(2) > GREY_MIN)
    at = np.array([(x - x0, y - y0) for _, x, y, front in pixels if front])
    assert len(at) == len(pixels) > 50  # every geom in front of the camera
    (lo_x, lo_y), (hi_x, hi_y) = at.min(0) - ROBOT_PX, at.max(0) + ROBOT_PX
    ys, xs = np.nonzero(grey)
    inside = (xs >= lo_x) & (xs <= hi_x) & (ys >= lo_y) & (ys <= hi_y)
    assert grey.sum() > 5000 and inside.mean() > 0.99, (int(grey.sum()), float(inside.mean()))
    tx, ty = np.round([(x - x0, y - y0) for name, x, y, _ in pixels if name == "torso_link"][0]).astype(int)
    assert grey[ty - 4 : ty + 5, tx - 4 : tx + 5].sum() > 40  # the torso's silver where the page draws it
    print(f"3D view screenshot: {shot}")


@slow
def test_3d_view_of_the_perfect_robot_shows_its_soles(drive_with_view, tmp_path):
    # the perfect robot in 3D: its two soles, boxes in the feet's colours (left blue, right orange), drawn where
    # the page projects them
    view = drive_with_view
    shot = tmp_path / "view3d_perfect.png"
    with _browser() as p:
        browser = _launch(p)
        page = browser.new_page(viewport={"width": 1200, "height": 760})
        page.goto(view.url + "3d")
        page.wait_for_function("window.ijoy3d && ijoy3d.terrain && ijoy3d.bodies === 2 && ijoy3d.frames > 3",
                               timeout=60000)
        page.screenshot(path=str(shot))
        pixels = page.evaluate("ijoy3d.bodyPixels()")
        browser.close()
    from PIL import Image

    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert [px[0] for px in pixels] == ["left_sole", "right_sole"]
    for (name, x, y, front), rgb in zip(pixels, FEET_RGB.values(), strict=True):
        x, y = int(round(x)), int(round(y))
        assert front and 0 <= x < img.shape[1] and 0 <= y < img.shape[0], (name, x, y)
        patch = img[y - 6 : y + 7, x - 6 : x + 7].reshape(-1, 3)
        # lit from above, a sole's top is its colour, somewhat brighter or darker
        hue = np.all(np.abs(patch / np.maximum(patch.sum(1, keepdims=True), 1) - np.array(rgb) / sum(rgb)) < 0.06,
                     axis=1)
        assert hue.sum() > 40, (name, int(hue.sum()))

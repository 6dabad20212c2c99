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


@pytest.fixture(scope="module")
def drive_with_view():
    """A real-time drive of the perfect robot on a clutter map, its stick the view's, and the view's server."""
    settings = live.DriveSettings(terrain={"kind": "family", "family": "obstacles", "seed": 3, "shape": list(SHAPE),
                                           "resolution": RES})
    terrain, robot, start = live.open_terrain(settings.terrain)
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
                                 robot=robot, start=start)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    assert ready.wait(120), "the drive never ticked"
    yield view
    stop.set()
    thread.join(timeout=60)
    view.close()
    assert out["result"].decisions, "the drive made no decision"


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

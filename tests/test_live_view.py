"""The live view in a real browser: Debian's Chromium (headless) driven by Playwright against the view's real
aiohttp server and a real-time drive. The page loads, draws the scene, and a key held in the page changes the
command the drive loop sees. The map is the small one of every server and live test (tests/_server_util.py), so
the drive's programs are those tests/test_live.py compiled on the same xdist worker (tests/conftest.py)."""

import shutil
import threading
import time

import numpy as np
import pytest
from _server_util import RES, SHAPE  # tests/ is on sys.path (pytest rootdir import)

from ijoy_jax import live
from ijoy_jax.live.view import ViewServer

pytestmark = pytest.mark.slow  # drives Debian's Chromium, a system package .ci/run installs

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

"""The demo (``ijoy demo``), run small: the printed metrics are plain numbers that say what happened, and the
PNG shows both joysticks with a legend."""

import json

import matplotlib.pyplot as plt
import numpy as np
import pytest
from PIL import Image

from ijoy_jax.apps import cli, demo

STEPS = 8  # the naive joystick's 3rd and 6th footholds are on obstacles (demo_scene)
COUNTS = ("steps_taken", "steps_in_place", "steps_stationary", "footholds_on_obstacles", "invalid_footholds")


@pytest.mark.slow
def test_demo_prints_plain_metrics_and_writes_the_figure(tmp_path, capsys, monkeypatch):
    figures = []
    close = plt.close
    monkeypatch.setattr(plt, "close", lambda fig=None: (figures.append(fig), close(fig)))
    from ijoy_jax import progress

    monkeypatch.setattr(progress, "SHOW_AFTER_S", 0.0)  # the compile line at once (a cached compile is quick)
    png = tmp_path / "demo.png"
    assert cli.main(["demo", "--out", str(png), "--steps", str(STEPS)]) == 0
    out, err = capsys.readouterr()
    what = f"the two rollouts ({STEPS} steps, the intelligent and the naive joystick)"
    assert err.startswith(f"ijoy demo: compiling {what}: ") and f"ijoy demo: compiled {what} in " in err, err
    result = json.loads(out)
    for name in ("intelligent", "naive"):
        s = result[name]
        for k in COUNTS:
            assert type(s[k]) is int, (name, k)
            assert f'"{k}": {s[k]},' in out or f'"{k}": {s[k]}\n' in out  # printed as 24, not 24.0
        assert type(s["stopped"]) is bool and s["steps_taken"] == STEPS
    smart, naive = result["intelligent"], result["naive"]
    assert smart["footholds_on_obstacles"] == smart["invalid_footholds"] == 0
    assert np.isfinite(smart["mean_foot_cost"]) and smart["distance_along"] > 0.5
    assert naive["footholds_on_obstacles"] == naive["invalid_footholds"] == 2
    assert naive["mean_foot_cost"] == float("inf")  # printed as Infinity, not an average of the valid ones
    assert result["png"] == str(png)

    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    assert img.shape == (990, 1100, 3)  # 10 x 9 inches at 110 dpi
    blue = (np.abs(img - [31, 119, 180]).sum(-1) < 30).sum()  # tab:blue left feet
    red = (np.abs(img - [214, 39, 40]).sum(-1) < 30).sum()  # tab:red right feet
    assert blue > 500 and red > 500

    (fig,) = [f for f in figures if f is not None]
    titles = [ax.get_title() for ax in fig.axes]
    assert titles[0].startswith("naive joystick: 8 steps, 2 on obstacles")
    assert titles[1].startswith("intelligent joystick: 8 steps, 0 on obstacles")
    for ax in fig.axes:
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        assert {"left foot", "right foot", "foothold on an obstacle", "obstacle"} <= set(legend)


def test_demo_scene_has_obstacles_in_the_lanes_and_a_wall():
    t = demo.demo_scene()
    free = np.asarray(t.free)
    assert t.shape == (200, 120) and not t.has_height
    assert not free[187, :].any()  # the wall at x = 3.75 m spans the map
    assert (~free[:150]).sum() > 20  # the small obstacles before it

"""Plot helpers: facet polygons are the paper's 12 rhombi; platform vertices as scipy's halfspace intersection."""

import jax.numpy as jnp
import matplotlib
import numpy as np
import pytest

from ijoy_jax.haptics import leg as L
from ijoy_jax.haptics import platform as P
from ijoy_jax.haptics import plot
from ijoy_jax.haptics import workspace as W

matplotlib.use("Agg")


@pytest.fixture(scope="module")
def leg_ws():
    return L.leg_workspace(L.alduro_leg(-1.0), jnp.array(L.PAPER_Q))


def test_facets_are_twelve_rhombi(leg_ws):
    p = leg_ws.planes
    valid = np.asarray(p.valid)
    pts = plot.zonotope_points(leg_ws.jacobian, leg_ws.travel_minus, leg_ws.travel_plus)
    assert pts.shape == (16, 3)
    polys = plot.facet_polygons(np.asarray(p.normals)[valid], np.asarray(p.offsets)[valid], pts)
    assert len(polys) == 12 and all(len(poly) == 4 for poly in polys)
    for poly in polys:  # parallelograms: opposite sides equal
        np.testing.assert_allclose(poly[1] - poly[0], poly[2] - poly[3], atol=1e-5)


def test_polytope_vertices_match_scipy(leg_ws):
    from scipy.spatial import ConvexHull, HalfspaceIntersection

    pw = P.platform_workspace(P.alduro_platform(), P.nominal_q())
    a, b = P.translation_halfspaces(pw)
    ours = plot.polytope_vertices(a, b)
    hs = HalfspaceIntersection(np.hstack([a, -b[:, None]]), np.zeros(3))
    theirs = hs.intersections[ConvexHull(hs.intersections).vertices]
    assert len(ours) == len(theirs)
    for v in theirs:
        assert np.min(np.linalg.norm(ours - v, axis=1)) < 1e-5


def test_plots_draw(leg_ws):
    import matplotlib.pyplot as plt

    f = W.repulsive_force_decay(leg_ws.jacobian, leg_ws.travel_minus, leg_ws.travel_plus, 1.0, 0.05)
    fig = plt.figure()
    ax = plot.plot_leg_workspace(
        leg_ws.jacobian,
        leg_ws.travel_minus,
        leg_ws.travel_plus,
        f,
        ax=fig.add_subplot(1, 2, 1, projection="3d"),
        scale=0.5,
    )
    assert "12 planes" in ax.get_title()
    pw = P.platform_workspace(P.alduro_platform(), P.nominal_q())
    ax2 = plot.plot_platform_workspace(
        pw, P.platform_force(pw, 1.0, 0.05).force, ax=fig.add_subplot(1, 2, 2, projection="3d")
    )
    assert "facets" in ax2.get_title()
    fig.canvas.draw()
    plt.close(fig)

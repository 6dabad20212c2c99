"""Physically simulated walking: an HRP-2-like biped in MuJoCo XLA that executes the joystick's footsteps.

Modules: :mod:`.model` (the MjSpec robot and the terrain's height field),
:mod:`.kinematics` (leg forward and analytic inverse kinematics),
:mod:`.preview` (LIPM/ZMP preview control), :mod:`.swing` (swing-foot paths
over the terrain), :mod:`.controller` (the walking pattern generator: a
footstep to joint targets, tick by tick), :mod:`.walker` (the MJX robot as a
:class:`ijoy_jax.control.Walker` and its rollout), :mod:`.bench` (physics
steps per second).

Status (issue 7): the robot stands and steps in place under position control;
longer steps still fall, because the controller has no stabiliser yet.
"""

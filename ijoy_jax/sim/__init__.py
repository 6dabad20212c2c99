"""Physically simulated walking: an HRP-2-like biped in MuJoCo XLA that executes the joystick's footsteps.

Modules: :mod:`.model` (the MjSpec robot and the terrain's height field),
:mod:`.kinematics` (leg forward and analytic inverse kinematics),
:mod:`.preview` (LIPM/ZMP preview control), :mod:`.swing` (swing-foot paths
over the terrain).
"""

"""The Robot pytree and its TerrainMetrics: what a robot model holds, and which of it is traced or static.

An action is a displacement ``(dx, dy, dtheta)`` of the swing foot relative to
the stance foot, in the stance foot's frame (metres, radians). ``Robot.actions``
holds the LEFT swing foot's set relative to a RIGHT stance foot; the right
foot's set is its mirror ``(dx, -dy, -dtheta)`` (:func:`~ijoy_jax.robots.side_actions`).

Every number a user may sweep or tune is a traced leaf of :class:`~ijoy_jax.robots.Robot`
(and its :class:`~ijoy_jax.robots.TerrainMetrics`), so changing it never recompiles and it
can be vmapped over or differentiated. Only the action-set size (an array shape) and
two window sizes that bound the footprint (``max_radius``, ``max_swing``;
Python floats) are static. The types hold no rules: :mod:`~ijoy_jax.robots.build`
builds a valid robot and checks one.
"""

from __future__ import annotations

import jax

from ijoy_jax.struct import pytree_dataclass, static_field


@pytree_dataclass
class TerrainMetrics:
    """Weights and hard limits of the 2.5D terrain metrics (traced leaves, scalars).

    The metrics follow the biped planner the paper cites (Chestnutt et al.
    2003): a plane is fitted (least squares) to the heights of the cells under
    the foot, and::

      slope      angle of that plane from horizontal (rad),
      roughness  mean absolute deviation of those cells from the plane (m),
      bump       largest height of a cell above the plane (m),
      step       |height change| from the stance foot's plane to this one (m);
                 its limit is per action (``Robot.max_step_height``),
      band       largest |deviation| from the plane in the safety band, the
                 cells touched by the footprint grown by the margin but not
                 by the footprint itself: catches edges and drop-offs (m),
      support    how much nearer the ankle the rested sole's contact polygon
                 comes than the whole sole's (m). The sole touches the
                 ground at six points (toe, middle and heel of each long
                 edge, ``contact_inset`` in from the edges: the simulated
                 biped's sole spheres; heights interpolated bilinearly
                 between cell centres, as a height field's surface is) and
                 rests on the plane through three of them that stays above
                 the others and lies lowest under the ankle
                 (:mod:`ijoy_jax.footcost.sole`); the points within
                 ``contact_tol`` of it form its contact polygon, and the
                 centre of pressure can move from the ankle to that
                 polygon's nearest edge before the sole rocks. The metric is
                 the whole sole's margin (``min(half length, half width) -
                 contact_inset``) less the polygon's: 0 where the sole rests
                 on all six points, on a plane of any tilt; the whole margin
                 where it rests on two diagonal corners or on its front half
                 (a dome under the middle, a twisted surface, a ridge under
                 it: the footholds the simulated biped fell on). Partial
                 footholds whose polygon holds the ankle with room to spare
                 pass. The rested sole's tilt is the foothold's (the
                 ``ankle`` limits apply to it) and its height the step's.

    A metric beyond its limit makes the cost +inf; otherwise its term is
    ``weight * metric``. Weights are cost units per radian or per metre.
    ``contact_inset`` and ``contact_tol`` (m) are not metrics: where the
    sole's contact points lie, and how close to the rested sole a point
    counts as touching.
    """

    slope_weight: jax.Array
    slope_limit: jax.Array
    roughness_weight: jax.Array
    roughness_limit: jax.Array
    bump_weight: jax.Array
    bump_limit: jax.Array
    step_weight: jax.Array
    band_weight: jax.Array
    band_limit: jax.Array
    support_weight: jax.Array
    support_limit: jax.Array
    contact_inset: jax.Array
    contact_tol: jax.Array


@pytree_dataclass
class Robot:
    """A robot model and its joystick parameters (the paper's footprint and S).

    Leaves (traced; scalars unless noted; metres, radians, seconds)::

      foot_length: footprint length along the foot's own x axis.
      foot_width: footprint width.
      margin: safety margin; validity uses the footprint grown by it on every
        side, a ``(length + 2 margin) x (width + 2 margin)`` rectangle.
      step_time: duration of one step, the Delta t of p_next = p0 + Delta t * j.
      p0: (3,) step-in-place action of the LEFT swing foot (dx, dy, dtheta).
      actions: (N, 3) the action set S of the LEFT swing foot (dx, dy, dtheta).
      action_cost: (N,) cost of taking each action (>= 0; part of FootCost).
      clearance: (N,) swing-path clearance of each action: terrain between
        the start and end footholds higher than this above the higher of the
        two makes the step invalid.
      max_step_height: (N,) allowed |height change| from the stance foothold.
      max_sole_pitch, max_sole_roll: the largest tilt of the sole from
        horizontal, about the foot's own y axis (pitch) and x axis (roll), that
        the ankles can realise (rad): a foothold whose rested sole tilts
        further is refused (FootCost's ``ankle`` term). See
        :func:`make_robot` for HRP-2's values and where they come from.
      max_sole_distance: the largest distance between the stance and swing
        sole centres in 3D (m; the horizontal step and the height change of
        the two rested soles): beyond it the legs cannot stand on both
        footholds (FootCost's ``reach`` term). See :func:`make_robot`.
      metrics: TerrainMetrics weights and limits.
      w: weight of dist against FootCost, cost(p) = FootCost + w dist(p, p_next).
      rotation_weight: dist = |translation| + rotation_weight * |rotation|
        (cost units per radian before w); large, so the commanded rotation is
        preferred whenever such a step is valid.

    Static::

      max_radius: largest half-diagonal of the grown footprint the fixed-size
        windows cover (m); a larger footprint or margin is flagged invalid.
      max_swing: longest swing-path segment the path window covers (m).
      target_grid: the lattice of the paper's target set F, ``(lo, step,
        counts)`` per axis (:func:`target_lattice`).
    """

    foot_length: jax.Array
    foot_width: jax.Array
    margin: jax.Array
    step_time: jax.Array
    p0: jax.Array
    actions: jax.Array
    action_cost: jax.Array
    clearance: jax.Array
    max_step_height: jax.Array
    max_sole_pitch: jax.Array
    max_sole_roll: jax.Array
    max_sole_distance: jax.Array
    metrics: TerrainMetrics
    w: jax.Array
    rotation_weight: jax.Array
    max_radius: float = static_field()
    max_swing: float = static_field()
    target_grid: tuple = static_field()

    @property
    def num_actions(self) -> int:
        """Size N of the action set (static)."""
        return self.actions.shape[-2]

"""The columns of a sweep's tables: the metrics every result row holds, their units, and the parameter prefixes.

The scenario table (:func:`ijoy_jax.sweep.scenarios`) holds the parameters (``robot.*``, ``terrain.*``,
``sim.*``, ``selector.*``), a result table adds the metrics below. The run counts these columns towards a
sweep's host memory before it starts; loading, aggregating and plotting read them by these names.
"""

from __future__ import annotations

from ijoy_jax.terrain import generators

__all__ = ["EXTRA_METRICS", "METRICS", "PARAMETER_PREFIXES", "PHYSICS_METRICS", "UNITS", "WALK_METRICS",
           "WALK_PHYSICS_METRICS", "walk_metrics"]

METRICS = (
    "steps_taken",
    "steps_in_place",
    "steps_stationary",
    "stopped",
    "footholds_on_obstacles",
    "footholds_near_obstacles",
    "invalid_footholds",
    "distance_along",
    "distance_across",
    "mean_deviation",
    "mean_foot_cost",
    "commands_not_finite",
    "unsupported_decisions",
)
"""Rollout metrics (:meth:`ijoy_jax.Trajectory.summary`) in every results table (``footholds_near_obstacles``:
footholds taken with an obstacle within :data:`ijoy_jax.control.NEAR_OBSTACLE` of the foot; absent from
results written before it existed, which aggregate without it)."""

PHYSICS_METRICS = (
    "fell",
    "collided",
    "obstacle_contacts",
    "placement_error_mean",
    "placement_error_p95",
    "yaw_error_mean",
    "tilt_error_p95",
    "dynamics_invalid",
)
"""Per-scenario metrics of a ``walker = "mjx"`` sweep (:func:`ijoy_jax.sim.walker.summary`): the robot fell,
touched an obstacle (``collided``) and in how many steps, its touch-down errors (m, rad), and whether a
physics value was out of bounds (``dynamics_invalid``; refused before compute, so False)."""

WALK_METRICS = ("steps_made", "progress", "footholds_on_obstacles_made")
"""Per-scenario metrics of a walk sweep (``[terrain] walk``), what ``ijoy bench walk`` tabulates: ``steps_made``,
steps taken that ended with the robot standing (all steps taken, for the perfect robot); ``progress`` (m),
how far the midpoint of the feet moved along +x from the start feet to their touch-downs after the last step
made; ``footholds_on_obstacles_made``, steps made onto an obstacle cell (bare footprint)
(:func:`ijoy_jax.sweep.programs.walk_summary`)."""

WALK_PHYSICS_METRICS = (
    "standing_contacts",
    "made_placement_error_mean",
    "made_placement_error_p95",
    "made_tilt_error_p95",
)
"""With ``walker = "mjx"``, a walk sweep's figures over the steps made (after a fall the loop may go on choosing
steps the robot no longer makes; :data:`PHYSICS_METRICS` count those too): ``standing_contacts``, steps begun
standing during which a sole or shin touched an obstacle cell; the mean and 95th percentile of the touch-down
error (m) and the 95th percentile of the sole tilt error (rad) over the steps made (NaN for a robot that made
none)."""


def walk_metrics(walk: bool, walker: str) -> tuple[str, ...]:
    """The walk metrics a sweep's results hold: () without ``[terrain] walk``, else :data:`WALK_METRICS` and with
    ``walker = "mjx"`` :data:`WALK_PHYSICS_METRICS`."""
    if not walk:
        return ()
    return WALK_METRICS + (WALK_PHYSICS_METRICS if walker == "mjx" else ())


EXTRA_METRICS = generators.METRIC_NAMES
"""Family-specific metrics (every family's ``metric_names``, :data:`ijoy_jax.terrain.generators.METRIC_NAMES`),
aggregated when present; bars: ``bars_crossed`` bars passed by both feet, ``crossed`` every bar passed
(fraction of scenarios)."""

UNITS = {
    "steps_taken": "steps",
    "steps_in_place": "steps",
    "steps_stationary": "steps",
    "stopped": "fraction",
    "footholds_on_obstacles": "footholds",
    "footholds_near_obstacles": "footholds",
    "invalid_footholds": "footholds",
    "distance_along": "m",
    "distance_across": "m",
    "mean_deviation": "m",
    "mean_foot_cost": "cost units",
    "commands_not_finite": "decisions",
    "unsupported_decisions": "decisions",
    "robot.w": "cost units per m",
    "robot.rotation_weight": "cost units per rad",
    "robot.margin": "m",
    "robot.step_time": "s",
    "robot.foot_length": "m",
    "robot.foot_width": "m",
    "robot.max_sole_pitch": "rad",
    "robot.max_sole_roll": "rad",
    "robot.max_sole_distance": "m",
    "robot.density": "x HRP-2's 496 actions",
    "robot.reach": "m",
    "terrain.rise": "m",
    "terrain.run": "m",
    "command.vx": "m/s",
    "command.vy": "m/s",
    "command.wz": "rad/s",
    "bars_crossed": "bars",
    "crossed": "fraction",
    "terrain.width": "m",
    "fell": "fraction",
    "collided": "fraction",
    "obstacle_contacts": "steps",
    "placement_error_mean": "m",
    "placement_error_p95": "m",
    "yaw_error_mean": "rad",
    "tilt_error_p95": "rad",
    "dynamics_invalid": "fraction",
    "steps_made": "steps",
    "progress": "m",
    "footholds_on_obstacles_made": "footholds",
    "standing_contacts": "steps",
    "made_placement_error_mean": "m",
    "made_placement_error_p95": "m",
    "made_tilt_error_p95": "rad",
    "sim.friction": "coefficient",
    "sim.mass_scale": "x nominal",
    "sim.kp_scale": "x nominal",
    "sim.latency": "s",
    "sim.stance_noise": "m",
    "sim.push": "N s",
    "selector.horizon": "steps scored",
    "selector.refine": "0 or 1",
    "selector.discount": "1",
}
"""Units of metrics and parameters, for tables and axis labels."""

PARAMETER_PREFIXES = ("robot.", "terrain.", "sim.", "selector.")
"""The prefixes of the parameter columns (the rest are ids and metrics)."""

"""Per-scenario metrics that need a terrain family's geometry, computed inside the sweep's jit.

:meth:`ijoy_jax.Trajectory.summary` knows the rollout only; whether the robot
got past an obstacle also needs the obstacle. :data:`FAMILY_METRICS` names the
extra metrics each family adds to the results table (the sweep computes them
from the same posed objects its generator rasterises, :func:`ijoy_jax.terrain.generators.objects`).

``bars``: :func:`bar_crossings` of the final stance.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

import jax
import jax.numpy as jnp

__all__ = ["FAMILY_METRICS", "bar_crossings"]

FAMILY_METRICS: Mapping[str, tuple[str, ...]] = MappingProxyType({"bars": ("bars_crossed", "crossed")})
"""Extra per-scenario metrics by terrain family (added to :data:`ijoy_jax.sweep.METRICS` in results)."""


def bar_crossings(boxes, feet, foot_length, foot_width) -> dict[str, jax.Array]:
    """Which bars the robot has got past: both feet wholly beyond the bar's far face at the end.

    A bar is a box row ``(x, y, yaw, length, width, top)`` of
    :func:`ijoy_jax.terrain.generators.objects` (``length == 0``: an empty slot). Its
    far face (the side at larger x) is the line
    ``x_far(y) = x + (y - y_bar) cot(yaw) + (width / 2) / |sin(yaw)|``
    (an untilted bar has yaw = pi/2: ``x_far = x + width / 2``), extended
    over the whole map even for a single-lane bar. A foot at pose
    ``(fx, fy, theta)`` is beyond it when the rear of its footprint
    rectangle, ``fx - (L |cos theta| + W |sin theta|) / 2``, is at or past
    ``x_far`` anywhere over the foot's y extent ``fy +- (L |sin theta| + W |cos theta|) / 2``.

    Args:
      boxes: (n, 6) bar rows, metres and radians.
      feet: (2, 3) final foot poses (world x, y, theta).
      foot_length, foot_width: footprint L x W without margin, metres.

    Returns:
      ``{"bars_crossed": () int32 number of bars crossed by both feet,
      "crossed": () bool, every present bar crossed (True when there is none)}``.
    """
    boxes = jnp.asarray(boxes, jnp.float32)
    feet = jnp.asarray(feet, jnp.float32)
    x, y, yaw, length, width = (boxes[:, i] for i in range(5))
    present = length > 0
    s, c = jnp.sin(yaw), jnp.cos(yaw)
    s = jnp.where(jnp.abs(s) < 1e-6, 1e-6, s)  # a bar along x has no far face across the walk
    cot = c / s
    th = feet[:, 2]
    hx = 0.5 * (foot_length * jnp.abs(jnp.cos(th)) + foot_width * jnp.abs(jnp.sin(th)))
    hy = 0.5 * (foot_length * jnp.abs(jnp.sin(th)) + foot_width * jnp.abs(jnp.cos(th)))
    rear = feet[:, 0] - hx  # (2,)
    far = (x[:, None] + (feet[None, :, 1] - y[:, None]) * cot[:, None] + jnp.abs(cot)[:, None] * hy[None, :]
           + 0.5 * width[:, None] / jnp.abs(s)[:, None])  # (n, 2)
    past = jnp.all(rear[None, :] >= far, axis=1) & present
    return {"bars_crossed": jnp.sum(past).astype(jnp.int32), "crossed": jnp.all(past | ~present)}

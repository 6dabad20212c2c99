"""LIPM/ZMP preview control: the walking pattern generator's centre-of-mass planner.

The cart-table model (Kajita et al. 2003) with the CoM at constant height
``z_c`` and the CoM jerk as input, per horizontal axis::

    x = [c, cdot, cddot]            (m, m/s, m/s^2)
    x[k+1] = A x[k] + B u[k]        (u: jerk, m/s^3)
    p[k]   = C x[k],  C = [1, 0, -z_c / g]   (ZMP, m)

The servo of Katayama et al. (1985) minimises
``sum_k q e[k]^2 + r du[k]^2`` with ``e = p - p_ref`` over the augmented state
``[e, dx]`` (error plus state increments), which gives integral action::

    u[k] = -Gi sum_{i<=k} e[i] - Gx x[k] - sum_{j=1}^{N-1} Gd[j] p_ref[k+j]

The gains come from the discrete algebraic Riccati equation (DARE) of the
augmented 4-state system, solved in JAX by the structured doubling algorithm
(SDA, Chu et al. 2004), so ``preview_gains`` runs under ``jit`` with the CoM
height, time step and weights traced (only the horizon is static).

Everything here is for one robot; batch with ``jax.vmap``. x and y are the two
columns of a (3, 2) state and share one set of gains.

References:
  S. Kajita et al., "Biped walking pattern generation by using preview control
  of zero-moment point", ICRA 2003.
  T. Katayama et al., "Design of an optimal controller for a discrete-time
  system subject to previewable demand", Int. J. Control 41(3), 1985.
  E. K.-W. Chu, H.-Y. Fan, W.-W. Lin, "A structure-preserving doubling
  algorithm for discrete-time algebraic Riccati equations", 2004/2005.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

# Doubling steps of the SDA. Step k of the doubling is worth 2**k Riccati
# iterations, and the error contracts like rho(A_closed)**(2**(k+1)); with the
# slowest closed-loop pole of these systems above 0.999 per tick (the preview
# servo at dt = 1 ms), 2**40 iterations are far past convergence. Once
# converged the iteration is a fixed point (A_k underflows to 0), so extra
# steps cost nothing but time. Tests check the DARE residual against SciPy.
SDA_ITERATIONS = 40
# The doubling stops once max |A_k| falls below this (dimensionless): the
# remaining correction to P is then O(CONVERGED_A**2) relative.
CONVERGED_A = 1e-3


class PreviewGains(NamedTuple):
    """Cart-table model and preview-servo gains (one set for both axes).

    Fields::

      dt: () float, control period (s).
      A: (3, 3) state transition of [c, cdot, cddot] over one tick.
      B: (3,) jerk input vector.
      C: (3,) ZMP output row, ``[1, 0, -z_c / g]``.
      Gi: () integral gain on the summed ZMP error (m/s^3 per m).
      Gx: (3,) state feedback gains.
      Gd: (N,) preview gains; ``Gd[j]`` weighs the reference ``j`` ticks ahead.
        ``Gd[0] = 0``: the current reference acts through the error integral.
        ``Gd[1] = -Gi`` (Katayama's ``Gd(1)``).
      P: (4, 4) DARE solution of the augmented system (kept for checks).
    """

    dt: jax.Array
    A: jax.Array
    B: jax.Array
    C: jax.Array
    Gi: jax.Array
    Gx: jax.Array
    Gd: jax.Array
    P: jax.Array


def _check_static(horizon) -> int:
    if isinstance(horizon, bool) or not isinstance(horizon, (int,)) and not hasattr(horizon, "__index__"):
        raise ValueError(f"horizon must be a Python int (static), got {horizon!r}")
    horizon = int(horizon)
    if horizon < 1:
        raise ValueError(f"horizon must be >= 1 tick, got {horizon}")
    return horizon


def _check_positive(name: str, value) -> None:
    """Raise for a concrete value that is not a finite positive number (traced values pass)."""
    if isinstance(value, jax.core.Tracer):
        return
    try:
        v = float(value)
    except TypeError:
        return
    if not math.isfinite(v) or v <= 0.0:
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")


def cart_table(com_height, dt, gravity=9.81) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Discrete cart-table model ``(A (3, 3), B (3,), C (3,))`` for CoM height (m) and period (s)."""
    dt = jnp.asarray(dt, jnp.result_type(float))
    zc = jnp.asarray(com_height, dt.dtype)
    one, zero = jnp.ones_like(dt), jnp.zeros_like(dt)
    a = jnp.stack(
        [
            jnp.stack([one, dt, 0.5 * dt * dt]),
            jnp.stack([zero, one, dt]),
            jnp.stack([zero, zero, one]),
        ]
    )
    b = jnp.stack([dt**3 / 6.0, 0.5 * dt * dt, dt])
    c = jnp.stack([one, zero, -zc / jnp.asarray(gravity, dt.dtype)])
    return a, b, c


def solve_dare(a, b, q, r, iterations: int = SDA_ITERATIONS) -> jax.Array:
    """Stabilising solution P (n, n) of ``P = A'PA - A'PB (r + B'PB)^-1 B'PA + Q`` (single input).

    Structured doubling algorithm (SDA): with ``G0 = b b'/r``, ``H0 = Q``,
    ``A0 = A`` and ``W = I + G H``::

        A' = A W^-1 A,  G' = G + A W^-1 G A^T,  H' = H + A^T H W^-1 A

    ``H`` converges quadratically to P (it equals the Riccati recursion after
    ``2**k`` steps). Needs (A, b) stabilisable and (A, Q) detectable; a fixed
    number of doublings (static) keeps it differentiable under ``jit``.

    Args:
      a: (n, n) state matrix.
      b: (n,) input vector.
      q: (n, n) state weight, symmetric positive semidefinite.
      r: () input weight, > 0.
      iterations: static number of doubling steps.

    Returns:
      (n, n) symmetric P.
    """
    n = a.shape[0]
    eye = jnp.eye(n, dtype=a.dtype)
    g0 = jnp.outer(b, b) / r

    def body(_, carry):
        ak, gk, hk = carry
        # Converged once A_k has collapsed (it falls from O(10) to O(1e-6) in
        # one doubling); W is then so ill-conditioned (cond ~ 1e9) that a
        # float32 solve would return NaN, so freeze, feeding the solve safe
        # values (double-where keeps gradients finite).
        done = jnp.max(jnp.abs(ak)) < CONVERGED_A
        w = jnp.where(done, eye, eye + gk @ hk)
        a_safe = jnp.where(done, 0.0, ak)
        w_ag = jnp.linalg.solve(w, jnp.concatenate([a_safe, jnp.where(done, 0.0, gk)], axis=1))
        w_a, w_g = w_ag[:, :n], w_ag[:, n:]  # W^-1 A, W^-1 G (one factorisation)
        a_next = a_safe @ w_a
        g_next = gk + a_safe @ w_g @ a_safe.T
        h_next = hk + a_safe.T @ hk @ w_a
        g_next = jnp.where(done, gk, 0.5 * (g_next + g_next.T))
        h_next = jnp.where(done, hk, 0.5 * (h_next + h_next.T))
        return jnp.where(done, ak, a_next), g_next, h_next

    _, _, p = lax.fori_loop(0, iterations, body, (a, g0, q))
    return p


def preview_gains(com_height, dt, horizon: int, q=1.0, r=1e-6, gravity=9.81) -> PreviewGains:
    """Preview-servo gains of the cart-table model (Kajita 2003, Katayama 1985).

    Args:
      com_height: () CoM height z_c above the ZMP plane (m); may be traced.
      dt: () control period (s), > 0; may be traced.
      horizon: static int N >= 1, number of reference samples the controller
        reads (``zmp_future`` of :func:`preview_update`): the current one and
        ``N - 1`` ahead, so the preview time is ``(N - 1) * dt``.
      q: () weight on the squared ZMP error (1/m^2); may be traced.
      r: () weight on the squared jerk increment; may be traced.
      gravity: () gravitational acceleration (m/s^2).

    Returns:
      :class:`PreviewGains` in the floating dtype of the inputs (float32 by
      default).

    Raises:
      ValueError: horizon not an int >= 1, or a concrete dt, com_height, r
        not positive and finite.

    Example:
      >>> g = preview_gains(0.8, 0.005, 321)
      >>> g.Gd.shape
      (321,)
    """
    horizon = _check_static(horizon)
    for name, v in (("dt", dt), ("com_height", com_height), ("r", r), ("gravity", gravity)):
        _check_positive(name, v)
    return _preview_gains(com_height, dt, horizon, q, r, gravity)


@functools.partial(jax.jit, static_argnums=2)
def _preview_gains(com_height, dt, horizon: int, q, r, gravity) -> PreviewGains:
    a, b, c = cart_table(com_height, dt, gravity)
    dtype = a.dtype
    q = jnp.asarray(q, dtype)
    r = jnp.asarray(r, dtype)
    ca = c @ a  # (3,)
    cb = c @ b  # ()
    # Augmented state [e, dx]: e[k+1] = e[k] + CA dx[k] + CB du[k] - dp_ref[k+1].
    at = jnp.zeros((4, 4), dtype).at[0, 0].set(1.0).at[0, 1:].set(ca).at[1:, 1:].set(a)
    bt = jnp.concatenate([cb[None], b])
    qt = jnp.zeros((4, 4), dtype).at[0, 0].set(q)
    p = solve_dare(at, bt, qt, r)
    denom = r + bt @ p @ bt
    k = (bt @ p @ at) / denom  # (4,) = [Gi, Gx]
    gi, gx = k[0], k[1:]
    ac = at - jnp.outer(bt, k)
    # Gd(j) = -(r + B'PB)^-1 B' (Ac')^(j-1) P I,  j = 1 .. N-1.
    x0 = p[:, 0]

    def step(x, _):
        return ac.T @ x, -(bt @ x) / denom

    _, gd = lax.scan(step, x0, None, length=horizon - 1)
    gd = jnp.concatenate([jnp.zeros((1,), dtype), gd])
    return PreviewGains(dt=jnp.asarray(dt, dtype), A=a, B=b, C=c, Gi=gi, Gx=gx, Gd=gd, P=p)


def initial_state(com_xy) -> jax.Array:
    """(3, 2) cart-table state at rest with the CoM over ``com_xy`` (2,) (m): rows c, cdot, cddot."""
    com_xy = jnp.asarray(com_xy, jnp.result_type(float))
    return jnp.zeros((3, 2), com_xy.dtype).at[0].set(com_xy)


def rest_err_sum(gains: PreviewGains, com_xy) -> jax.Array:
    """(2,) error sum that makes a CoM at rest over ``com_xy`` (2,) (m) an equilibrium.

    The textbook control law is not translation invariant for a finite
    horizon: ``Gx[0] + sum(Gd)`` is not 0 (about 0.44 Gi for 1.6 s preview at
    dt = 5 ms, falling to ~0 by 5 s). At rest over ``c`` with the reference
    at ``c``, ``u = 0`` needs ``err_sum = -(Gx[0] + sum(Gd)) c / Gi``. Start
    the servo with this value, not zeros, unless the robot starts at the
    origin; otherwise the first second has a ZMP transient.
    """
    drift = gains.Gx[0] + jnp.sum(gains.Gd)
    return -drift * jnp.asarray(com_xy, gains.Gi.dtype) / gains.Gi


def preview_update(gains: PreviewGains, state, err_sum, zmp_future) -> tuple[jax.Array, jax.Array, jax.Array]:
    """One control tick of the preview servo for x and y at once.

    With ``x = state`` at tick k and ``p_ref[k + j] = zmp_future[j]``::

        err_sum' = err_sum + C x - p_ref[k]
        u        = -Gi err_sum' - Gx x - sum_j Gd[j] p_ref[k + j]
        state'   = A x + B u

    The products are formed about ``zmp_future[0]`` (an exact rearrangement)
    so float32 keeps its precision far from the world origin.

    Args:
      gains: :class:`PreviewGains` with ``Gd`` of shape (N,).
      state: (3, 2) [c, cdot, cddot] per axis (columns x, y) at tick k (m, m/s,
        m/s^2).
      err_sum: (2,) sum of past ZMP errors ``p - p_ref`` (m); start from
        :func:`rest_err_sum` (zeros only for a robot at rest at the origin).
      zmp_future: (N, 2) ZMP reference (m) at ticks k .. k + N - 1, e.g. from
        :func:`zmp_reference`.

    Returns:
      ``(state', err_sum', zmp')``: the state at tick k + 1 (3, 2), the
      updated error sum (2,), and the cart-table ZMP ``C @ state'`` (2,) at
      tick k + 1 (m).

    Example:
      >>> g = preview_gains(0.8, 0.01, 161)
      >>> ref = jnp.zeros((161, 2))
      >>> s, e, z = preview_update(g, initial_state(jnp.zeros(2)), jnp.zeros(2), ref)
    """
    state = jnp.asarray(state)
    zmp_future = jnp.asarray(zmp_future)
    if zmp_future.shape[0] != gains.Gd.shape[0]:
        raise ValueError(f"zmp_future has {zmp_future.shape[0]} samples, the gains' horizon is {gains.Gd.shape[0]}")
    origin = zmp_future[0]
    local = state.at[0].add(-origin)
    ref = zmp_future - origin
    p = gains.C @ local  # (2,)
    err_sum = err_sum + p  # the current reference is 0 in the local frame
    # Exact correction for moving the origin: -(Gx[0] + sum Gd) * origin.
    drift = gains.Gx[0] + jnp.sum(gains.Gd)
    u = -gains.Gi * err_sum - gains.Gx @ local - gains.Gd @ ref - drift * origin
    new = gains.A @ local + gains.B[:, None] * u[None, :]
    zmp = gains.C @ new + origin
    return new.at[0].add(origin), err_sum, zmp


def zmp_reference(waypoints, t, dt, horizon: int, step_time, ds_time) -> jax.Array:
    """ZMP reference (N, 2) at times ``t + k * dt``, ``k = 0 .. N - 1``, for a footstep plan.

    Timing: step m (m = 0 is the current step) occupies
    ``[m * step_time, (m + 1) * step_time)`` measured from the start of the
    current step. During its double support, the first ``ds_time`` seconds,
    the ZMP moves linearly from ``waypoints[m]`` to ``waypoints[m + 1]``; during
    the single support that follows it holds at ``waypoints[m + 1]``, the
    stance foot of step m. From step ``K - 1`` on, the plan is exhausted and
    the ZMP holds at ``waypoints[K - 1]``. Step boundaries fall where
    ``floor(time / step_time)`` changes, at float precision.

    Standing still: make every waypoint from ``waypoints[1]`` on the midpoint
    of the two feet (``waypoints[0]`` the ZMP's current position, e.g. the
    last stance foot): the ZMP shifts to the midpoint during the first double
    support and stays there.

    Args:
      waypoints: (K, 2) ZMP targets (m): ``[0]`` the previous stance foot,
        ``[1]`` the current step's stance foot, ``[2]`` the next, ... K >= 1
        static.
      t: () time since the current step began (s), >= 0 (negative times are
        treated as 0; times past the plan hold its last point).
      dt: () sample spacing (s).
      horizon: static int N >= 1.
      step_time: () duration of one step (s), > 0.
      ds_time: () double-support duration at the start of each step (s),
        ``0 <= ds_time <= step_time``; 0 gives a step change.

    Returns:
      (N, 2) ZMP positions (m).

    Example:
      >>> w = jnp.array([[0.0, 0.1], [0.0, -0.1], [0.2, 0.1], [0.4, -0.1]])
      >>> zmp_reference(w, 0.0, 0.005, 4, 0.8, 0.1)[1]  # 1/20 of the way to w[1]
      Array([0.  , 0.09], dtype=float32)
    """
    horizon = _check_static(horizon)
    waypoints = jnp.asarray(waypoints)
    if waypoints.ndim != 2 or waypoints.shape[1] != 2 or waypoints.shape[0] < 1:
        raise ValueError(f"waypoints must have shape (K, 2) with K >= 1, got {waypoints.shape}")
    _check_positive("step_time", step_time)
    _check_positive("dt", dt)
    dtype = waypoints.dtype
    num = waypoints.shape[0]
    if num == 1:
        return jnp.broadcast_to(waypoints[0], (horizon, 2))
    times = jnp.maximum(jnp.asarray(t, dtype) + jnp.arange(horizon, dtype=dtype) * jnp.asarray(dt, dtype), 0.0)
    step_time = jnp.asarray(step_time, dtype)
    ds_time = jnp.asarray(ds_time, dtype)
    m = jnp.floor(times / step_time)
    phase = times - m * step_time
    m = m.astype(jnp.int32)
    done = m > num - 2
    mc = jnp.clip(m, 0, num - 2)
    ds_pos = ds_time > 0
    alpha = jnp.where(ds_pos, jnp.clip(phase / jnp.where(ds_pos, ds_time, 1.0), 0.0, 1.0), 1.0)
    alpha = jnp.where(done, 1.0, alpha)[:, None]
    return (1.0 - alpha) * waypoints[mc] + alpha * waypoints[mc + 1]


def lipm_sway_amplitude(zmp_amplitude, step_time, com_height, gravity=9.81) -> jax.Array:
    """Peak CoM offset (m) of the periodic LIPM gait whose ZMP alternates between ``+a`` and ``-a``.

    For a square-wave ZMP (no double support) of half-period ``T =
    step_time``, the periodic solution of ``c'' = w^2 (c - p)``, ``w =
    sqrt(g / z_c)``, is ``c = a (1 - cosh(w (t - T/2)) / cosh(w T / 2))``
    during a step on ``+a``; its peak is ``a (1 - 1 / cosh(w T / 2))``. A
    double support lowers it slightly. Use it to size step time against foot
    spacing: the CoM sways less than the feet are apart.

    Args:
      zmp_amplitude: () half the lateral distance between the ZMP targets (m).
      step_time: () duration of one step (s).
      com_height: () CoM height (m).
      gravity: () (m/s^2).

    Returns:
      () peak ``|c|`` (m).
    """
    w = jnp.sqrt(gravity / jnp.asarray(com_height, jnp.result_type(float)))
    return zmp_amplitude * (1.0 - 1.0 / jnp.cosh(0.5 * w * step_time))

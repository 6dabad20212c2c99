"""The virtual spring-damper input filter of the paper's section 2.1, discretised exactly.

The control input ``x_c`` is a virtual mass ``m`` tied to the raw joystick
position ``x_j`` by a spring ``c`` and a damper ``d`` acting on the *relative*
motion::

    m x_c'' = c (x_j - x_c) + d (x_j' - x_c')

    x_c'' + 2 zeta w0 x_c' + w0^2 x_c = 2 zeta w0 x_j' + w0^2 x_j,
    w0 = sqrt(c / m)  [rad/s],   zeta = d / (2 sqrt(c m))  [-].

The paper's printed equations have sign errors: eq. (1) has ``- d dx'`` and
eq. (2) has ``- 2 zeta x_c'`` on the left (negative damping: unstable), and
they write ``w0 = c/m`` and ``zeta = d/2m``; the latter is the decay rate
``zeta * w0``, not a damping ratio. We implement the physical system above.

Transfer function ``H(s) = (2 zeta w0 s + w0^2) / (s^2 + 2 zeta w0 s + w0^2)``:
unit DC gain, zero error for ramps (slow intended motion is followed with
little lag), but only first-order (-20 dB/decade) roll-off and a resonance
peak above 1 for every ``zeta`` because of the zero.

Discretisation: the observable canonical state ``(x_c, w)`` with
``w = x_c' - 2 zeta w0 (x_j - x_c)`` needs no derivative of the raw joystick
signal. Under a zero-order hold of the sample ``u`` over one period ``dt``
the state relaxes exactly towards its rest point ``(u, 0)``::

    (x_c, w)_{k+1} = (u_k, 0) + Ad @ ((x_c, w)_k - (u_k, 0)),  Ad = expm(A dt)

which is the exact ZOH discretisation written in error coordinates: a
constant input is reproduced bit for bit in float32 (unit DC gain exactly; a
direct-form biquad loses ~1e-3 of DC gain at low cut-offs in float32).
``Ad`` has a closed form for 2x2 matrices, evaluated elementwise, so
parameters broadcast against the signal's channels and can be vmapped. The
form never overflows for a stable filter (see :func:`discretize`): overdamped,
it is written with the two real modes' decays ``exp(-mu dt) <= 1`` instead of
``e^-sigma cosh(r)`` (whose ``cosh`` overflows float32 once ``r > ~89``).

Invalid parameters (``w0 <= 0``, ``zeta < 0``, ``dt <= 0`` or anything non-finite)
are refused with a ValueError where concrete (:func:`discretize`,
:func:`spring_damper_filter`); inside jit they are flagged in
``FilterCoeffs.invalid`` and their coefficients are zero, so the filter passes
its (last finite) input straight through: a defined, finite output, never an
explosion.

Output convention: after the filter consumes sample ``k`` its position is the
exact continuous-time response at ``t = (k + 1) dt`` to the input held at
``signal[k]`` over ``[k dt, (k + 1) dt)``: the value a 1 kHz loop sends in the
tick it read the sample. Non-finite samples (NaN, inf) are replaced by the last
finite sample and flagged.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.struct import pytree_dataclass

# |z| below this uses the power series of cosh(sqrt z) and sinh(sqrt z)/sqrt z
# (truncation error < z^4/8! < 3e-17, so exact in float64; also keeps
# gradients finite at critical damping, where z = 0).
_SERIES_BOUND = 1e-3


@pytree_dataclass
class SpringDamper:
    """Spring-damper filter parameters (traced leaves: sweeps and gradients never recompile).

    Attributes:
      natural_frequency: w0 = sqrt(c/m) in rad/s, > 0; any shape broadcastable
        against the signal's channel axes.
      damping_ratio: zeta = d / (2 sqrt(c m)), dimensionless, >= 0.

    Example:
      >>> p = SpringDamper.from_physical(stiffness=400.0, damping=28.0, mass=1.0)
      >>> round(float(p.natural_frequency), 6), round(float(p.damping_ratio), 6)
      (20.0, 0.7)
    """

    natural_frequency: jax.Array
    damping_ratio: jax.Array

    @classmethod
    def create(cls, natural_frequency, damping_ratio) -> SpringDamper:
        """From (w0 [rad/s], zeta [-]) as float arrays."""
        return cls(
            jnp.asarray(natural_frequency, jnp.result_type(float)), jnp.asarray(damping_ratio, jnp.result_type(float))
        )

    @classmethod
    def from_physical(cls, stiffness, damping, mass) -> SpringDamper:
        """From the paper's (c [N/m], d [N s/m], m [kg]) parameterisation.

        ``w0 = sqrt(c/m)``, ``zeta = d / (2 sqrt(c m))``. Only the ratios matter:
        scaling c, d and m together leaves the filter unchanged.
        """
        c, d, m = (jnp.asarray(v, jnp.result_type(float)) for v in (stiffness, damping, mass))
        return cls(jnp.sqrt(c / m), d / (2.0 * jnp.sqrt(c * m)))

    def to_physical(self, mass=1.0) -> tuple[jax.Array, jax.Array, jax.Array]:
        """``(c [N/m], d [N s/m], m [kg])`` for a virtual point of the given mass."""
        m = jnp.asarray(mass, jnp.result_type(float))
        return m * self.natural_frequency**2, 2.0 * m * self.damping_ratio * self.natural_frequency, m

    @property
    def decay_rate(self) -> jax.Array:
        """``zeta * w0 = d / 2m`` in 1/s (what the paper calls zeta)."""
        return self.damping_ratio * self.natural_frequency

    def cutoff_frequency(self) -> jax.Array:
        """The -3 dB frequency of the continuous filter in rad/s.

        ``|H(j w)|^2 = 1/2`` at ``(w/w0)^2 = (1 + 2 zeta^2) + sqrt((1 + 2 zeta^2)^2 + 1)``
        (about 2.06 w0 at zeta = 1/sqrt 2).
        """
        return self.natural_frequency * jnp.sqrt(_cutoff_ratio_sq(self.damping_ratio))

    @classmethod
    def from_cutoff(cls, cutoff, damping_ratio) -> SpringDamper:
        """The filter whose -3 dB frequency is ``cutoff`` (rad/s) at the given damping ratio."""
        zeta = jnp.asarray(damping_ratio, jnp.result_type(float))
        return cls(jnp.asarray(cutoff, zeta.dtype) / jnp.sqrt(_cutoff_ratio_sq(zeta)), zeta)


def _cutoff_ratio_sq(zeta):
    a = 1.0 + 2.0 * zeta**2
    return a + jnp.sqrt(a * a + 1.0)


class FilterCoeffs(NamedTuple):
    """Exact ZOH transition matrix ``Ad = expm(A dt)`` of the state ``(x_c, w)``, elementwise.

    Each field has the broadcast shape of (natural_frequency, damping_ratio, dt),
    dtype float (``invalid`` bool); ``a12`` in seconds, ``a21`` in 1/s, the others
    dimensionless.
    """

    a11: jax.Array
    a12: jax.Array
    a21: jax.Array
    a22: jax.Array
    #: bool, True where (w0, zeta, dt) is not a finite, stable filter (w0 > 0, zeta >= 0, dt > 0) or its
    #: coefficients would not be finite; there all four coefficients are 0: the input passes straight through.
    invalid: jax.Array = False


class FilterState(NamedTuple):
    """Filter state per channel; all fields have the channel shape ``S`` of the signal.

    Fields:
      position: x_c, the control input (units of the joystick signal, e.g. metres).
      aux: w = x_c' - 2 zeta w0 (x_j - x_c), the second observable-form state (units/s).
      last_good: the last finite joystick sample (held when a sample is NaN/inf).
    """

    position: jax.Array
    aux: jax.Array
    last_good: jax.Array


def _cosh_sinhc(z):
    """``(cosh(sqrt z), sinh(sqrt z) / sqrt z)`` for real z of any sign, gradient-safe at 0."""
    small = jnp.abs(z) < _SERIES_BOUND
    zs = jnp.where(small, 0.0, z)
    pos = zs > 0
    r = jnp.sqrt(jnp.where(small, 1.0, jnp.abs(zs)))
    c_big = jnp.where(pos, jnp.cosh(r), jnp.cos(r))
    s_big = jnp.where(pos, jnp.sinh(r), jnp.sin(r)) / r
    zz = jnp.where(small, z, 0.0)
    c_ser = 1.0 + zz * (1.0 / 2.0 + zz * (1.0 / 24.0 + zz / 720.0))
    s_ser = 1.0 + zz * (1.0 / 6.0 + zz * (1.0 / 120.0 + zz / 5040.0))
    return jnp.where(small, c_ser, c_big), jnp.where(small, s_ser, s_big)


def _overdamped(w0, zeta, dt):
    """``expm(A dt)`` for ``zeta > 1`` from the two real modes, without overflow.

    The modes decay at ``mu1 = w0 / (zeta + s)`` (slow; ``zeta - s`` without the
    cancellation) and ``mu2 = w0 (zeta + s)``, ``s = sqrt(zeta^2 - 1)``. With
    ``E1 = exp(-mu1 dt) <= 1``, ``x = (mu2 - mu1) dt = 2 s w0 dt >= 0`` and
    ``g = (1 - e^-x) / x = -expm1(-x) / x`` in ``(0, 1]``::

        a12 = E1 dt g,   a21 = -w0^2 a12,   a11 = E1 (e^-x - mu1 dt g),   a22 = E1 (1 + mu1 dt g)

    (``(E1 - E2) / (mu2 - mu1) = E1 dt g``: the difference of near-equal
    exponentials is an expm1). Every factor is bounded, so nothing overflows
    however large ``w0 dt`` is; only used where ``x`` is away from 0.
    """
    s = jnp.sqrt(zeta - 1.0) * jnp.sqrt(zeta + 1.0)  # no overflow of zeta^2
    wh = w0 * dt
    mu1h = wh / (zeta + s)
    x = 2.0 * s * wh
    e1 = jnp.exp(-mu1h)
    g = -jnp.expm1(-x) / x
    a12 = e1 * dt * g
    return FilterCoeffs(a11=e1 * (jnp.exp(-x) - mu1h * g), a12=a12, a21=-w0 * (e1 * wh * g), a22=e1 * (1.0 + mu1h * g))


def discretize(params: SpringDamper, dt) -> FilterCoeffs:
    """Exact zero-order-hold transition matrix for one sample period.

    With ``A = [[-2 zeta w0, 1], [-w0^2, 0]]`` and ``M = A dt``,
    ``expm(M) = e^a [cosh(r) I + sinh(r)/r (M - a I)]``, ``a = -zeta w0 dt``,
    ``r^2 = (zeta^2 - 1) (w0 dt)^2`` (cos/sin when underdamped, a power series
    near critical damping). Overdamped, the same matrix is evaluated from the
    two real modes' decays (see :func:`_overdamped`), which never overflows:
    the coefficients are finite for every stable ``(w0, zeta, dt)`` in float32.
    Elementwise, so parameters of any broadcastable shape give coefficients of
    that shape.

    Args:
      params: SpringDamper (w0 in rad/s, > 0; zeta >= 0).
      dt: sample period in seconds (> 0), scalar or broadcastable.

    Returns:
      FilterCoeffs. Inside jit, invalid parameters (w0 <= 0, zeta < 0, dt <= 0,
      non-finite) give ``invalid = True`` and zero coefficients (the filter then
      passes its input through).

    Raises:
      ValueError: concrete (not traced) parameters or dt that are invalid.

    Example:
      >>> c = discretize(SpringDamper.create(10.0, 0.7), 1e-3)
      >>> round(float(c.a12), 6)  # ~dt for w0 dt << 1
      0.000993
    """
    _check_concrete_positive("dt", dt)
    _check_concrete_positive("natural_frequency", params.natural_frequency)
    _check_concrete_positive("damping_ratio", params.damping_ratio, allow_zero=True)
    return _discretize(params, dt)


@jax.jit
def _discretize(params: SpringDamper, dt) -> FilterCoeffs:
    w0 = jnp.asarray(params.natural_frequency)
    zeta = jnp.asarray(params.damping_ratio)
    dt = jnp.asarray(dt, jnp.result_type(w0.dtype, float))
    w0, zeta, dt = jnp.broadcast_arrays(w0.astype(dt.dtype), zeta.astype(dt.dtype), dt)
    ok = jnp.isfinite(w0) & jnp.isfinite(zeta) & jnp.isfinite(dt) & (w0 > 0) & (zeta >= 0) & (dt > 0)
    # Safe stand-ins where not ok or not in a branch, so neither value nor gradient sees NaN/inf.
    w0 = jnp.where(ok, w0, 1.0)
    zeta = jnp.where(ok, zeta, 0.5)
    dt = jnp.where(ok, dt, 1.0)
    wh = w0 * dt
    sigma = zeta * wh
    z = (zeta - 1.0) * (zeta + 1.0) * wh * wh
    over = z >= _SERIES_BOUND
    c, s = _cosh_sinhc(jnp.where(over, -1.0, z))  # underdamped and near-critical: bounded cos/sin or series
    e = jnp.exp(-sigma)
    near = FilterCoeffs(a11=e * (c - s * sigma), a12=e * s * dt, a21=-e * s * w0 * wh, a22=e * (c + s * sigma))
    far = _overdamped(w0, jnp.where(over, zeta, 2.0), dt)
    coeffs = [jnp.where(over, f, n) for f, n in zip(far[:4], near[:4], strict=True)]
    ok = ok & jnp.all(jnp.stack([jnp.isfinite(v) for v in coeffs]), axis=0)
    a11, a12, a21, a22 = (jnp.where(ok, v, 0.0) for v in coeffs)
    return FilterCoeffs(a11=a11, a12=a12, a21=a21, a22=a22, invalid=~ok)


def init_state(sample) -> FilterState:
    """State at rest at ``sample`` (shape S); non-finite entries start at 0.

    Example:
      >>> init_state(jnp.array([0.1, 0.2])).position
      Array([0.1, 0.2], dtype=float32)
    """
    x = jnp.asarray(sample, jnp.result_type(float))
    x = jnp.where(jnp.isfinite(x), x, 0.0)
    return FilterState(position=x, aux=jnp.zeros_like(x), last_good=x)


@jax.jit
def filter_step(coeffs: FilterCoeffs, state: FilterState, sample) -> tuple[FilterState, jax.Array]:
    """Consume one joystick sample: the one-sample update for a live loop.

    Args:
      coeffs: from :func:`discretize` (broadcastable to the channel shape S).
      state: FilterState with channel shape S.
      sample: (S) raw joystick position; NaN/inf entries hold the last finite one.

    Returns:
      ``(new_state, held)``: ``new_state.position`` is the control input to send
      now (the exact response one period after the sample); ``held`` (S) bool is
      True where the sample was not finite and the last good value was used.

    Example:
      >>> co = discretize(SpringDamper.create(20.0, 0.7), 1e-3)
      >>> st, held = filter_step(co, init_state(jnp.zeros(2)), jnp.array([1.0, jnp.nan]))
      >>> held
      Array([False,  True], dtype=bool)
    """
    x = jnp.asarray(sample, state.position.dtype)
    good = jnp.isfinite(x)
    u = jnp.where(good, x, state.last_good)
    e1 = state.position - u  # error coordinates around the rest point (u, 0)
    e2 = state.aux
    position = u + (coeffs.a11 * e1 + coeffs.a12 * e2)
    aux = coeffs.a21 * e1 + coeffs.a22 * e2
    return FilterState(position=position, aux=aux, last_good=u), ~good


def _first_finite(signal):
    if signal.shape[0] == 0:  # an empty signal: nothing to start from (static shape)
        return jnp.zeros(signal.shape[1:], signal.dtype)
    finite = jnp.isfinite(signal)
    idx = jnp.argmax(finite, axis=0)
    first = jnp.take_along_axis(signal, idx[None], axis=0)[0]
    return jnp.where(jnp.any(finite, axis=0), first, 0.0)


@jax.jit
def filter_signal(coeffs: FilterCoeffs, signal, state: FilterState | None = None):
    """Filter a whole signal with ``lax.scan`` over :func:`filter_step`.

    Args:
      coeffs: from :func:`discretize`, broadcastable to the channel shape S.
      signal: ``(T, *S)`` raw joystick samples, time on the first axis.
      state: state to continue from; default at rest at each channel's first
        finite sample (0 if a channel has none).

    Returns:
      ``(filtered (T, *S), final_state, held (T, *S) bool)``.

    Example:
      >>> co = discretize(SpringDamper.create(20.0, 0.7), 1e-3)
      >>> y, st, held = filter_signal(co, jnp.ones((5, 2)))
      >>> y.shape, bool(jnp.all(y == 1.0))
      ((5, 2), True)
    """
    signal = jnp.asarray(signal, jnp.result_type(float))
    channels = signal.shape[1:]
    coeff_shape = jnp.broadcast_shapes(*(jnp.shape(c) for c in coeffs[:4]))
    try:
        fits = signal.ndim >= 1 and np.broadcast_shapes(coeff_shape, channels) == channels
    except ValueError:
        fits = False
    if not fits:
        raise ValueError(
            f"signal must have shape (T, *S) with the filter's parameters broadcastable to S; got signal "
            f"{signal.shape} and parameters of shape {coeff_shape}"
        )
    if state is None:
        state = init_state(_first_finite(signal))

    def body(st, x):
        st, held = filter_step(coeffs, st, x)
        return st, (st.position, held)

    final, (y, held) = jax.lax.scan(body, state, signal)
    return y, final, held


def _check_concrete_positive(name, value, allow_zero=False):
    if isinstance(value, jax.core.Tracer):
        return
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number or an array of numbers, got {value!r}") from None
    bad = ~np.isfinite(v) | ((v < 0) if allow_zero else (v <= 0))
    if np.any(bad):
        rel = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {rel}, got {value!r}")


def spring_damper_filter(signal, dt, natural_frequency, damping_ratio):
    """Filter a joystick signal with the (corrected) virtual spring-damper of section 2.1.

    Exact zero-order-hold discretisation of
    ``x_c'' + 2 zeta w0 x_c' + w0^2 x_c = 2 zeta w0 x_j' + w0^2 x_j``, starting at
    rest at the first sample. NaN/inf samples hold the last finite value (use
    :func:`filter_signal` to get the flags too).

    Args:
      signal: ``(T, *S)`` raw joystick positions, time on the first axis (any unit).
      dt: sample period in seconds.
      natural_frequency: w0 = sqrt(c/m) in rad/s, broadcastable to S.
      damping_ratio: zeta = d / (2 sqrt(c m)), broadcastable to S.

    Returns:
      ``(T, *S)`` filtered control input, same shape as ``signal``.

    Example:
      >>> t = jnp.arange(1000) * 1e-3
      >>> y = spring_damper_filter(jnp.stack([t, -t], 1), 1e-3, 2 * jnp.pi * 2.0, 0.7)
      >>> y.shape
      (1000, 2)
    """
    dtype = signal.dtype if hasattr(signal, "dtype") else np.asarray(signal).dtype
    if not (jnp.issubdtype(dtype, jnp.number) or jnp.issubdtype(dtype, jnp.bool_)) or jnp.issubdtype(
        dtype, jnp.complexfloating
    ):
        raise TypeError(f"signal must hold real numbers, got dtype {dtype}")
    if jnp.ndim(signal) < 1:
        raise ValueError("signal must have a time axis: shape (T, ...)")
    _check_concrete_positive("dt", dt)
    _check_concrete_positive("natural_frequency", natural_frequency)
    _check_concrete_positive("damping_ratio", damping_ratio, allow_zero=True)
    return _filter(signal, dt, natural_frequency, damping_ratio)


@jax.jit
def _filter(signal, dt, natural_frequency, damping_ratio):
    params = SpringDamper(
        jnp.asarray(natural_frequency, jnp.result_type(float)), jnp.asarray(damping_ratio, jnp.result_type(float))
    )
    return filter_signal(_discretize(params, dt), signal)[0]

"""The spring-damper input filter against Butterworth filters: the comparison the paper promised.

Same signals for every filter, sampled at 1 kHz (a haptic loop's rate):

* ``intended``: slow intended motion, a 0.5 Hz sine of amplitude 1 (full deflection).
* ``tremor``: band-limited Gaussian noise in 5-12 Hz (physiological tremor), RMS 0.05.
* ``jolt``: one half-sine pulse of 40 ms and height 1 (a jolt of the cabin passed to the hand).
* ``step``: a unit step (a deliberate fast deflection).

Metrics (signals start at rest at 0; steady-state metrics use ``t >= SETTLE_S``):

* ``lag_ms``: phase delay of the 0.5 Hz intended motion, from a least-squares
  sine fit, in milliseconds; ``gain`` its amplitude ratio.
* ``tremor_rms_ratio``: RMS of the filtered tremor over RMS of the tremor.
* ``jolt_peak_ratio``: peak of the filtered jolt over the jolt's peak.
* ``step_overshoot_pct``: step response overshoot in percent.

Two comparisons: at a matched -3 dB cut-off, and at matched tremor suppression
(each filter's cut-off solved so that its tremor RMS ratio hits the target).
Butterworth filters come from ``scipy.signal.butter`` (second-order sections,
the numerically sound form); the spring-damper is this package's JAX filter.
scipy is imported lazily: this module is for analysis, never the force path.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ijoy_jax.haptics.filter import SpringDamper, discretize, filter_signal, init_state
from ijoy_jax.jit_cache import compiled_count

SAMPLE_RATE = 1000.0  # Hz, the haptic loop rate
DURATION_S = 20.0  # long enough for the slowest filter compared to settle (see SETTLE_S)
SETTLE_S = 8.0  # steady-state window starts here: 6 whole periods of the 0.5 Hz motion remain
INTENDED_HZ = 0.5
TREMOR_BAND_HZ = (5.0, 12.0)
TREMOR_RMS = 0.05
JOLT_WIDTH_S = 0.040
EVENT_S = 1.0  # time of the jolt and of the step
MATCHED_CUTOFF_HZ = 2.0
MATCHED_TREMOR_RATIO = 0.1  # -20 dB
DAMPING_RATIOS = (0.5, 1.0 / math.sqrt(2.0), 1.0)
BUTTERWORTH_ORDERS = (1, 2, 3, 4)

Filter = Callable[[np.ndarray], np.ndarray]


def make_signals(
    sample_rate: float = SAMPLE_RATE, duration: float = DURATION_S, seed: int = 0
) -> dict[str, np.ndarray]:
    """The test signals, float64 arrays of shape (T,), plus their time axis ``t`` (s).

    Also ``combined`` = intended + tremor + a jolt every 2 s, for plots.

    Example:
      >>> s = make_signals(duration=2.0)
      >>> sorted(s)
      ['combined', 'intended', 'jolt', 'step', 't', 'tremor']
    """
    n = int(round(duration * sample_rate))
    t = np.arange(n) / sample_rate
    rng = np.random.default_rng(seed)
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1.0 / sample_rate)
    spec[(f < TREMOR_BAND_HZ[0]) | (f > TREMOR_BAND_HZ[1])] = 0.0
    tremor = np.fft.irfft(spec, n)
    fade = np.clip(t / 0.5, 0.0, 1.0) ** 2 * (3.0 - 2.0 * np.clip(t / 0.5, 0.0, 1.0))  # starts at rest
    tremor = tremor * fade
    steady = t >= min(SETTLE_S, t[-1] / 2)
    tremor *= TREMOR_RMS / np.sqrt(np.mean(tremor[steady] ** 2))

    def jolt_at(t0):
        s = (t - t0) / JOLT_WIDTH_S
        return np.where((s >= 0) & (s <= 1), np.sin(np.pi * np.clip(s, 0.0, 1.0)), 0.0)

    intended = np.sin(2.0 * np.pi * INTENDED_HZ * t)
    jolts = sum(jolt_at(t0) for t0 in np.arange(EVENT_S, duration, 2.0))
    return {
        "t": t,
        "intended": intended,
        "tremor": tremor,
        "jolt": jolt_at(EVENT_S),
        "step": (t >= EVENT_S).astype(float),
        "combined": intended + tremor + 0.3 * jolts,
    }


def butterworth(order: int, cutoff_hz: float, sample_rate: float = SAMPLE_RATE) -> Filter:
    """Digital Butterworth low-pass (scipy.signal.butter, SOS form), starting at rest at 0."""
    from scipy import signal as sps

    sos = sps.butter(order, cutoff_hz, btype="low", fs=sample_rate, output="sos")
    return lambda x: sps.sosfilt(sos, x)


@jax.jit
def _sd_run(w0, zeta, dt, x):
    co = discretize(SpringDamper(w0, zeta), dt)
    y, _, _ = filter_signal(co, x, init_state(jnp.zeros((), x.dtype)))
    return y


def spring_damper(natural_frequency: float, damping_ratio: float, sample_rate: float = SAMPLE_RATE) -> Filter:
    """This package's spring-damper (JAX, float32), starting at rest at 0.

    ``natural_frequency`` in rad/s. Parameters are traced: changing them does not recompile.
    """
    w0, zeta, dt = (jnp.float32(v) for v in (natural_frequency, damping_ratio, 1.0 / sample_rate))
    return lambda x: np.asarray(_sd_run(w0, zeta, dt, jnp.asarray(x, jnp.float32)), np.float64)


def compiled_programs() -> int:
    """How many programs the :func:`spring_damper` filters hold compiled (in this process).

    Read it before and after a loop of filters to learn how many compiles the loop caused: each new signal
    length compiles once; new natural frequencies, damping ratios and sample rates reuse the program.
    """
    return compiled_count(_sd_run)


def metrics(filt: Filter, signals: dict[str, np.ndarray], sample_rate: float = SAMPLE_RATE) -> dict[str, float]:
    """The comparison metrics of one filter on :func:`make_signals` output (see module doc)."""
    t = signals["t"]
    w = t >= SETTLE_S
    basis = np.stack([np.sin(2 * np.pi * INTENDED_HZ * t[w]), np.cos(2 * np.pi * INTENDED_HZ * t[w])], 1)
    (a_in, b_in), *_ = np.linalg.lstsq(basis, signals["intended"][w], rcond=None)
    (a_out, b_out), *_ = np.linalg.lstsq(basis, filt(signals["intended"])[w], rcond=None)
    dphi = math.atan2(b_out, a_out) - math.atan2(b_in, a_in)
    dphi = (dphi + math.pi) % (2 * math.pi) - math.pi
    tremor_out = filt(signals["tremor"])
    step_out = filt(signals["step"])
    return {
        "lag_ms": -dphi / (2 * math.pi * INTENDED_HZ) * 1e3,
        "gain": math.hypot(a_out, b_out) / math.hypot(a_in, b_in),
        "tremor_rms_ratio": float(np.sqrt(np.mean(tremor_out[w] ** 2) / np.mean(signals["tremor"][w] ** 2))),
        "jolt_peak_ratio": float(np.max(np.abs(filt(signals["jolt"]))) / np.max(np.abs(signals["jolt"]))),
        "step_overshoot_pct": float(max(np.max(step_out) - 1.0, 0.0) * 100.0),
    }


class FilterSpec(NamedTuple):
    """One compared filter: ``kind`` is "butterworth" (``param`` = order) or
    "spring_damper" (``param`` = damping ratio)."""

    name: str
    kind: str
    param: float

    def make(self, cutoff_hz: float) -> Filter:
        """The filter with its -3 dB cut-off at ``cutoff_hz``."""
        if self.kind == "butterworth":
            return butterworth(int(self.param), cutoff_hz)
        return spring_damper(self.natural_frequency_hz(cutoff_hz) * 2 * math.pi, self.param)

    def natural_frequency_hz(self, cutoff_hz: float) -> float | None:
        """w0 / 2 pi of the spring-damper with this cut-off (None for Butterworth)."""
        if self.kind == "butterworth":
            return None
        return float(SpringDamper.from_cutoff(cutoff_hz, self.param).natural_frequency)


def filter_specs() -> list[FilterSpec]:
    """Rows: Butterworth orders 1-4, then the spring-damper at each damping ratio."""
    return [FilterSpec(f"Butterworth order {n}", "butterworth", n) for n in BUTTERWORTH_ORDERS] + [
        FilterSpec(f"spring-damper, zeta = {z:.3f}", "spring_damper", z) for z in DAMPING_RATIOS
    ]


def matched_tremor_cutoff(spec: FilterSpec, signals, target: float = MATCHED_TREMOR_RATIO) -> float:
    """Cut-off (Hz) at which ``spec``'s tremor RMS ratio equals ``target`` (Brent's method on log f)."""
    from scipy.optimize import brentq

    def f(log_fc):
        return metrics(spec.make(math.exp(log_fc)), signals)["tremor_rms_ratio"] - target

    return math.exp(brentq(f, math.log(0.02), math.log(20.0), xtol=1e-9))


def compare(signals: dict[str, np.ndarray] | None = None) -> dict[str, list[dict]]:
    """Both comparisons: ``{"matched_cutoff": rows, "matched_tremor": rows}``.

    Each row: ``name``, ``kind`` and ``param`` (see :class:`FilterSpec`),
    ``cutoff_hz`` (-3 dB), ``natural_frequency_hz`` (spring-damper only, else
    None) and the :func:`metrics`.

    Example:
      >>> rows = compare()["matched_cutoff"]  # doctest: +SKIP
      >>> print(markdown_table(rows))  # doctest: +SKIP
    """
    signals = make_signals() if signals is None else signals
    specs = filter_specs()
    cutoffs = {
        "matched_cutoff": [MATCHED_CUTOFF_HZ] * len(specs),
        "matched_tremor": [matched_tremor_cutoff(s, signals) for s in specs],
    }
    return {
        key: [
            {
                "name": s.name,
                "kind": s.kind,
                "param": s.param,
                "cutoff_hz": fc,
                "natural_frequency_hz": s.natural_frequency_hz(fc),
                **metrics(s.make(fc), signals),
            }
            for s, fc in zip(specs, fcs, strict=True)
        ]
        for key, fcs in cutoffs.items()
    }


def markdown_table(rows: list[dict]) -> str:
    """One comparison as a Markdown table."""
    head = (
        "| filter | -3 dB cut-off (Hz) | lag of 0.5 Hz motion (ms) | gain at 0.5 Hz "
        "| tremor RMS ratio | jolt peak ratio | step overshoot (%) |\n"
        "|---|---:|---:|---:|---:|---:|---:|\n"
    )
    lines = []
    for r in rows:
        name = r["name"]
        if r["natural_frequency_hz"] is not None:
            name += f", f0 = {r['natural_frequency_hz']:.3f} Hz"
        lines.append(
            f"| {name} | {r['cutoff_hz']:.3f} | {r['lag_ms']:.1f} | {r['gain']:.3f} "
            f"| {r['tremor_rms_ratio']:.4f} | {r['jolt_peak_ratio']:.3f} "
            f"| {r['step_overshoot_pct']:.1f} |"
        )
    return head + "\n".join(lines) + "\n"


def report(result: dict[str, list[dict]] | None = None) -> str:
    """Both tables as Markdown, with their headings."""
    result = compare() if result is None else result
    return (
        f"Matched -3 dB cut-off ({MATCHED_CUTOFF_HZ:g} Hz):\n\n"
        + markdown_table(result["matched_cutoff"])
        + f"\nMatched tremor suppression (tremor RMS ratio {MATCHED_TREMOR_RATIO:g}):\n\n"
        + markdown_table(result["matched_tremor"])
    )


if __name__ == "__main__":
    print(report())

"""The filter comparison: metrics on filters with known answers, and the table's headline claims."""

import math

import jax
import numpy as np
import pytest

from ijoy_jax.haptics import compare as C
from ijoy_jax.haptics import filter as F

# Metrics are computed on simulated signals; a known linear filter's phase delay
# at 0.5 Hz is recovered to well below one sample (1 ms) by the least-squares fit.
LAG_TOL_MS = 0.05


@pytest.fixture(scope="module")
def signals():
    return C.make_signals()


def test_metrics_of_identity_and_delay(signals):
    ident = C.metrics(lambda x: x, signals)
    assert ident["lag_ms"] == pytest.approx(0.0, abs=1e-9)
    assert ident["gain"] == pytest.approx(1.0)
    assert ident["tremor_rms_ratio"] == pytest.approx(1.0)
    assert ident["jolt_peak_ratio"] == pytest.approx(1.0)
    assert ident["step_overshoot_pct"] == 0.0
    delay = C.metrics(lambda x: np.concatenate([np.zeros(25), x[:-25]]), signals)  # 25 samples = 25 ms
    assert delay["lag_ms"] == pytest.approx(25.0, abs=LAG_TOL_MS)
    assert delay["gain"] == pytest.approx(1.0, abs=1e-9)


def test_signals_have_the_stated_content(signals):
    t, tremor = signals["t"], signals["tremor"]
    spec = np.abs(np.fft.rfft(tremor[t >= C.SETTLE_S]))
    f = np.fft.rfftfreq(int(np.sum(t >= C.SETTLE_S)), 1 / C.SAMPLE_RATE)
    inside = (f >= C.TREMOR_BAND_HZ[0] - 0.2) & (f <= C.TREMOR_BAND_HZ[1] + 0.2)
    assert np.sum(spec[inside] ** 2) / np.sum(spec**2) > 0.99
    assert np.sqrt(np.mean(tremor[t >= C.SETTLE_S] ** 2)) == pytest.approx(C.TREMOR_RMS, rel=1e-9)
    assert np.max(signals["jolt"]) == pytest.approx(1.0, abs=1e-3)
    assert np.sum(signals["jolt"] > 0) == pytest.approx(C.JOLT_WIDTH_S * C.SAMPLE_RATE, abs=1)


def test_spring_damper_lag_matches_its_frequency_response(signals):
    """Lag from simulation = phase delay of the exact discrete (ZOH) system at 0.5 Hz, advanced one
    sample by the output convention (output[k] = y((k+1) dt))."""
    from scipy import signal

    w0, zeta = 2 * math.pi * 1.0, 0.7
    m = C.metrics(C.spring_damper(w0, zeta), signals)
    a = np.array([[-2 * zeta * w0, 1.0], [-(w0**2), 0.0]])
    b = np.array([[2 * zeta * w0], [w0**2]])
    ad, bd, cd, dd, _ = signal.cont2discrete((a, b, np.array([[1.0, 0.0]]), np.zeros((1, 1))), 1e-3, method="zoh")
    z = np.exp(1j * 2 * math.pi * C.INTENDED_HZ / C.SAMPLE_RATE)
    h = (cd @ np.linalg.solve(z * np.eye(2) - ad, bd))[0, 0] * z  # times z: the one-sample advance
    assert m["lag_ms"] == pytest.approx(-np.angle(h) / (2 * math.pi * C.INTENDED_HZ) * 1e3, abs=LAG_TOL_MS)
    assert m["gain"] == pytest.approx(abs(h), rel=1e-3)


def test_jax_spring_damper_matches_scipy_reference(signals):
    """The table's spring-damper (JAX, float32) against scipy.signal.lsim (ZOH, float64)."""
    from scipy import signal

    w0, zeta = 2 * math.pi * 0.8, 1.0
    a = np.array([[-2 * zeta * w0, 1.0], [-(w0**2), 0.0]])
    b = np.array([[2 * zeta * w0], [w0**2]])

    def ref(x):
        t = np.arange(len(x) + 1) / C.SAMPLE_RATE
        _, y, _ = signal.lsim((a, b, np.array([[1.0, 0.0]]), np.zeros((1, 1))), np.append(x, x[-1]), t, interp=False)
        return y[1:]

    got, want = C.metrics(C.spring_damper(w0, zeta), signals), C.metrics(ref, signals)
    assert got["lag_ms"] == pytest.approx(want["lag_ms"], abs=0.01)
    for key in ("gain", "tremor_rms_ratio", "jolt_peak_ratio"):
        assert got[key] == pytest.approx(want[key], rel=1e-4)
    assert got["step_overshoot_pct"] == pytest.approx(want["step_overshoot_pct"], abs=1e-3)


def test_butterworth_reference_cutoff():
    from scipy import signal

    for order in C.BUTTERWORTH_ORDERS:
        sos = signal.butter(order, 2.0, fs=C.SAMPLE_RATE, output="sos")
        _, h = signal.sosfreqz(sos, worN=[2.0], fs=C.SAMPLE_RATE)
        assert abs(h[0]) == pytest.approx(1 / math.sqrt(2), rel=1e-6)


@pytest.fixture(scope="module")
def table(signals):
    return C.compare(signals)


def test_matched_rows_hit_their_targets(table):
    for row in table["matched_cutoff"]:
        assert row["cutoff_hz"] == C.MATCHED_CUTOFF_HZ
    for row in table["matched_tremor"]:
        assert row["tremor_rms_ratio"] == pytest.approx(C.MATCHED_TREMOR_RATIO, rel=1e-4)
    for row in table["matched_tremor"] + table["matched_cutoff"]:
        if row["natural_frequency_hz"] is not None:
            p = F.SpringDamper.create(row["natural_frequency_hz"], row["param"])
            assert float(p.cutoff_frequency()) == pytest.approx(row["cutoff_hz"], rel=1e-5)


def test_headline_findings(table):
    """What the docs say about the table."""
    cut = {r["name"]: r for r in table["matched_cutoff"]}
    trem = {r["name"]: r for r in table["matched_tremor"]}
    sd = [n for n in cut if n.startswith("spring")]
    bw = [n for n in cut if n.startswith("Butter")]
    # At matched cut-off the spring-damper follows the intended motion with the least lag...
    assert max(cut[n]["lag_ms"] for n in sd) < min(cut[n]["lag_ms"] for n in bw)
    # ...but suppresses tremor less than Butterworth of order >= 2 and overshoots more.
    assert min(cut[n]["tremor_rms_ratio"] for n in sd) > max(cut[n]["tremor_rms_ratio"] for n in bw[1:])
    assert min(cut[n]["step_overshoot_pct"] for n in sd) > max(cut[n]["step_overshoot_pct"] for n in bw)
    # It amplifies the 0.5 Hz intended motion (its resonance): gain > 1.
    assert all(cut[n]["gain"] > 1.05 for n in sd)
    # At matched tremor suppression, Butterworth order 2 lags less than the well-damped spring-dampers.
    assert trem["Butterworth order 2"]["lag_ms"] < min(trem[n]["lag_ms"] for n in sd[1:])


def test_report_is_markdown(table):
    text = C.report(table)
    assert text.count("| Butterworth order") == 8 and text.count("| spring-damper") == 6
    assert "|---|" in text


def test_no_recompile_across_parameters(signals):
    C.spring_damper(3.0, 0.7)(signals["step"])
    before = C.compiled_programs()
    for w0 in (4.0, 5.0, 6.0):
        C.spring_damper(w0, 0.9)(signals["step"])
    assert C.compiled_programs() == before
    assert jax.default_backend() in ("cpu", "gpu", "tpu")

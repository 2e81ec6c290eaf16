"""Check 1 of issue 3: Phase I features on synthetic signals of known content match the analytical
values within 1 %; segmentation by speed; Fisher selection."""

from types import SimpleNamespace

import numpy as np
import pytest

from analysis.phase1.features import (
    FEATURE_NAMES,
    band_energy,
    kurtosis,
    line_amplitude,
    sample_features,
    skewness,
    summarise_capture,
    transient_templates,
    welch_psd,
)
from analysis.phase1.segmentation import segment_capture
from analysis.phase1.selection import fisher_scores, select_cumulative

FS = 10_000.0
TOL = 0.01  # 1 %


def _tones(amps, freqs, n, noise, rng, phases=None):
    t = np.arange(n) / FS
    x = sum(a * np.sin(2 * np.pi * f * t + (0 if phases is None else p))
            for a, f, p in zip(amps, freqs, phases or [0] * len(amps), strict=True))
    return x + noise * rng.standard_normal(n)


@pytest.mark.parametrize("f0", [40.0, 41.3])  # on a bin and between bins (5 Hz resolution)
def test_line_amplitudes_and_band_energy(f0):
    rng = np.random.default_rng(0)
    amps = [0.5, 0.3, 0.2]
    noise = 0.01
    x = _tones(amps, [f0, 2 * f0, 3 * f0], 40_000, noise, rng, phases=[0.3, 1.1, 2.0])
    f, p = welch_psd(x, FS)
    got = [float(line_amplitude(f, p, k * f0)) for k in (1, 2, 3)]
    # Band 0 .. 10 f0: the three tones' mean squares + the white noise in the band.
    expected_band = sum(a ** 2 / 2 for a in amps) + noise ** 2 * (10 * f0) / (FS / 2)
    band = float(band_energy(f, p, 10 * f0))
    print(f"f0 = {f0} Hz: amplitudes {np.round(got, 5)} (expected {amps}); band {band:.6f} "
          f"(expected {expected_band:.6f})")
    np.testing.assert_allclose(got, amps, rtol=TOL)
    assert band == pytest.approx(expected_band, rel=TOL)


def test_skewness_and_kurtosis_of_known_distributions():
    rng = np.random.default_rng(1)
    n = 400_000
    t = np.arange(n) / FS
    sine = np.sin(2 * np.pi * 40.0 * t)  # whole periods: kurtosis 3/2, skewness 0
    uni = rng.uniform(-1, 1, n)  # kurtosis 9/5
    gauss = rng.standard_normal(n)  # kurtosis 3
    expo = rng.exponential(1.0, n)  # skewness 2, kurtosis 9
    k = [float(kurtosis(v)) for v in (sine, uni, gauss)]
    print(f"kurtosis sine/uniform/gauss {np.round(k, 4)} (expected 1.5, 1.8, 3); "
          f"skew/kurt exponential {float(skewness(expo)):.4f} {float(kurtosis(expo)):.4f} (2, 9)")
    np.testing.assert_allclose(k, [1.5, 1.8, 3.0], rtol=TOL)
    assert abs(float(skewness(sine))) < 1e-6
    # The exponential's higher moments converge slowly: 3 % is ~5 standard errors at this n.
    assert float(skewness(expo)) == pytest.approx(2.0, rel=0.03)


def test_moments_equal_scipy_and_a_flat_column_is_nan_without_warning():
    """The numpy moments give scipy.stats' skew and kurtosis (bias=True, Pearson) to the last bit
    on ordinary columns; a flat column (a clipped channel, a constant offset with rounding
    noise) is NaN without the warning scipy prints."""
    import warnings

    from scipy import stats

    rng = np.random.default_rng(7)
    for x in (rng.standard_normal((2000, 7)) * [1, 2, 3, 1e-3, 1e3, 5, 0.1] + [0, 1, -4, 9, 0, 1e3, -2],
              rng.exponential(1.0, 513), rng.uniform(-1, 1, (64, 3))):
        np.testing.assert_array_equal(skewness(x), stats.skew(x, axis=0, bias=True))
        np.testing.assert_array_equal(kurtosis(x), stats.kurtosis(x, axis=0, fisher=False, bias=True))
    flat = np.column_stack([np.full(100, 3.0), 3.0 + 1e-16 * rng.standard_normal(100), np.zeros(100),
                            rng.standard_normal(100)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sk, ku = skewness(flat), kurtosis(flat)
    assert np.isnan(sk[:3]).all() and np.isnan(ku[:3]).all(), (sk, ku)
    assert np.isfinite(sk[3]) and np.isfinite(ku[3])
    assert np.ndim(skewness(flat[:, 3])) == 0


def _profile(n_moves=3, plateau=251.327, fs=FS, rng=None):
    """Reciprocating speed profile: dwell 1 s, ramp 0.1 s, steady 0.45 s, ramp down 0.1 s."""
    parts = [np.zeros(int(0.5 * fs))]
    d = 1
    for _ in range(n_moves):
        ramp = np.linspace(0, 1, int(0.1 * fs), endpoint=False)
        parts += [d * plateau * ramp, d * plateau * np.ones(int(0.45 * fs)), d * plateau * ramp[::-1],
                  np.zeros(int(1.0 * fs))]
        d = -d
    return np.concatenate(parts)


def test_segmentation_finds_steady_and_transient_segments():
    v = _profile()
    seg = segment_capture(v, FS)
    print(f"plateau {seg.plateau_rad_s:.3f} rad/s, f_rot {seg.f_rot_hz:.3f} Hz, steady "
          f"{[(s.start, s.stop, s.direction) for s in seg.steady]}, transient "
          f"{[(s.start, s.stop, s.direction) for s in seg.transient]}")
    assert seg.f_rot_hz == pytest.approx(40.0, rel=1e-3)
    assert [s.direction for s in seg.steady] == [1, -1, 1]
    assert [s.direction for s in seg.transient] == [1, -1, 1]
    for s in seg.steady:  # 0.45 s plateau minus 2 x 20 ms trim (and the 2 % ramp tail)
        assert 0.40 * FS <= len(s) <= 0.45 * FS
    for t in seg.transient:
        assert 0.09 * FS <= len(t) <= 0.1 * FS


def test_a_plateau_broken_up_by_ripple_is_segmented_on_its_mean_over_a_revolution():
    # cogging or torque ripple at 6 per revolution, ±4 % of the plateau: the raw speed leaves
    # 0.98 of its 99th percentile many times a revolution, and no piece is long enough for the PSD
    from analysis.phase1.segmentation import _segment

    def raw(speed):
        return _segment(speed, np.abs(speed), FS, 0.02, 0.02, 0.02, 0.1)

    v = _profile()
    angle = np.cumsum(v) / FS
    rippled = v * (1.0 + 0.04 * np.sin(6.0 * angle))
    assert all(len(s) < 0.2 * FS for s in raw(rippled).steady)
    seg = segment_capture(rippled, FS)
    assert [s.direction for s in seg.steady] == [1, -1, 1]
    for s in seg.steady:  # the 0.45 s plateau, less the trims and the half revolution the mean takes
        assert 0.35 * FS <= len(s) <= 0.45 * FS, len(s)
    # without ripple the segments are the raw speed's, sample for sample
    assert ([(s.start, s.stop) for s in segment_capture(v, FS).steady]
            == [(s.start, s.stop) for s in raw(v).steady])


def test_capture_features_end_to_end_on_a_synthetic_capture():
    """A synthetic capture with 40/80/120 Hz lines on acc1_x during motion: the sample features
    read them back within 1 %; torque statistics use the oriented torque."""
    rng = np.random.default_rng(2)
    v = _profile(4)
    n = len(v)
    moving = np.abs(v) > 0
    acc = np.zeros((n, 3))
    acc[:, 0] = _tones([0.2, 0.1, 0.05], [40.0, 80.0, 120.0], n, 0.0, rng) * moving
    acc += 1e-4 * rng.standard_normal((n, 3))
    # Oriented torque rises with speed during the ramps: every transient has the same shape.
    torque = np.sign(v) * (0.4 + 0.5 * np.abs(v) / np.abs(v).max()) + 0.01 * rng.standard_normal(n)
    cap = SimpleNamespace(name="c0", hours=1.0, sample=0, fs_hz=FS, speed=v, torque=torque,
                          acc1=acc, acc2=acc.copy())
    s = summarise_capture(cap)
    x = sample_features([s], transient_templates([s]))
    feat = dict(zip(FEATURE_NAMES, x, strict=True))
    got = [feat[f"amp{k}x_acc1_x"] for k in (1, 2, 3)]
    print(f"synthetic capture: amp 1x/2x/3x acc1_x {np.round(got, 5)}; corr fwd/rev "
          f"{feat['corr_tr_torque_fwd']:.4f} {feat['corr_tr_torque_rev']:.4f}; steady torque kurt "
          f"{feat['kurt_torque']:.3f}")
    np.testing.assert_allclose(got, [0.2, 0.1, 0.05], rtol=TOL)
    assert feat["corr_tr_torque_fwd"] == pytest.approx(1.0, abs=0.01)
    assert feat["corr_tr_torque_rev"] == pytest.approx(1.0, abs=0.01)
    assert feat["kurt_torque"] == pytest.approx(3.0, rel=0.05)  # Gaussian noise on a constant
    assert len(FEATURE_NAMES) == 46 and len(set(FEATURE_NAMES)) == 46


def test_fisher_score_and_cumulative_selection():
    X = np.array([[0.0, 1.0, 5.0], [0.2, 1.2, 5.5], [1.0, 1.1, 4.5], [1.2, 0.9, 5.0]])
    y = np.array([0, 0, 1, 1])
    s = fisher_scores(X, y)
    # Feature 0: means 0.1 vs 1.1, variances 0.01 and 0.01 -> 1 / 0.02 = 50.
    assert s[0] == pytest.approx(50.0)
    assert s[1] == pytest.approx(0.5)  # means 1.1 vs 1.0: 0.01 / 0.02
    sel = select_cumulative(np.array([5.0, 1.0, 3.0, 0.5, 0.5]), 0.9)
    # Sorted 5, 3, 1, .5, .5 of 10: cumulative .5, .8, .9 -> three features.
    assert list(sel) == [0, 2, 1]

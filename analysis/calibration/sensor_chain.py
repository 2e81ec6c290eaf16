"""The instruments of a recording from the axis at rest: noise floors, bandwidths, the IMU's
sensitivity and the torque signal's noise and resolution.

At rest (the dwells between moves) an instrument's output is its own noise shaped by its
low-pass: one-sided density N·|H(f)|, with |H(f)|² = 1/(1 + (f/f_c)^(2n)) for an n-th order
Butterworth response (the instrument models of the twin; S. Butterworth, "On the theory of filter
amplifiers", Wireless Engineer 7, 1930). So the floor N is the mean density well below f_c, and
f_c the frequency where the density has fallen by √2. The densities are Welch estimates
(P. D. Welch, IEEE Trans. Audio Electroacoust. 15(2), 1967) with a Hann window; bins more than
four times the band's median (a line of the machine, not noise) are left out of the mean.

The IMU accelerometer at rest reads gravity: |ā| / g₀ − 1 is its sensitivity error along the
axis that carries gravity (g₀ = 9.80665 m/s², the standard gravity of the CGPM, 1901; the local
gravity differs by up to 0.3 %, which bounds what this can say).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize, signal

G0 = 9.80665
#: Left out at each end of a rest before its spectrum is taken (the move's settling), s.
REST_MARGIN_S = 0.05
#: Left out at each end of a Phase II rest: the carriage rings on its trucks after a move of the
#: IMU routine's acceleration for longer than after the Phase I routine's, s.
PHASE2_REST_MARGIN_S = 0.2
#: Shortest rest whose spectrum is used, s.
REST_MIN_S = 0.1
#: Share of a Phase I rest, at its end, whose nut-accelerometer spectrum gives the floor: after a
#: move the carriage rings on its trucks (the suspension modes, inside the floor's band) and the
#: ringing decays over tens of milliseconds, longer than REST_MARGIN_S in a short dwell.
SETTLED_SHARE = 0.5


@dataclass(frozen=True)
class Measured:
    """One value measured from the recording: ``value`` in ``unit`` (the scenario key's unit),
    ``rel_se`` its relative standard error (NaN when unknown), ``note`` how it was measured."""

    value: float
    unit: str
    rel_se: float
    note: str


def rest_segments(moving: np.ndarray, fs: float, margin_s: float = REST_MARGIN_S,
                  min_s: float = REST_MIN_S) -> list[tuple[int, int]]:
    """[start, end) index ranges of the rests (``moving`` (n,) false), each shortened by
    ``margin_s`` at both ends, at least ``min_s`` long after that."""
    d = np.diff(np.concatenate(([0], (~moving).astype(np.int8), [0])))
    m = int(round(margin_s * fs))
    out = []
    for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
        a2, b2 = a + m, b - m
        if b2 - a2 >= min_s * fs:
            out.append((int(a2), int(b2)))
    return out


def settled(segments: list[tuple[int, int]], share: float = SETTLED_SHARE) -> list[tuple[int, int]]:
    """The last ``share`` of each [start, end) rest in ``segments``: where what the move left
    ringing has decayed, so a mode's decaying power is not taken for the floor."""
    return [(b - max(1, int(round(share * (b - a)))), b) for a, b in segments]


def rest_spectrum(x: np.ndarray, fs: float, segments: list[tuple[int, int]],
                  seg_s: float = 0.1) -> tuple[np.ndarray, np.ndarray, int]:
    """(f (m,) Hz, one-sided PSD (m, k) in x's unit²/Hz averaged over the rests, Welch
    segments averaged) of ``x`` (n, k) or (n,) over ``segments``; each rest's mean is removed."""
    x = np.asarray(x, float)
    x = x[:, None] if x.ndim == 1 else x
    nper = max(16, int(round(seg_s * fs)))
    nper = min(nper, min(b - a for a, b in segments))
    psds, count = [], 0
    for a, b in segments:
        f, p = signal.welch(x[a:b] - x[a:b].mean(axis=0), fs, window="hann", nperseg=nper, axis=0)
        k = 1 + 2 * ((b - a - nper) // nper)  # 50 % overlap
        psds.append(p * k)
        count += k
    return f, np.sum(psds, axis=0) / count, count


def floor_density(f: np.ndarray, psd: np.ndarray, band: tuple[float, float], n_avg: int) -> tuple[np.ndarray, float]:
    """(density (k,) in x's unit/√Hz, relative standard error) of the white floor in ``band``
    (Hz): the mean PSD over the band's bins, lines (bins above 4× the median) left out. The
    relative error of a density from ``n_avg`` averaged Welch segments and b bins is about
    1/(2·√(n_avg·b))."""
    sel = (f >= band[0]) & (f <= band[1])
    p = psd[sel]
    med = np.median(p, axis=0)
    keep = p <= 4 * med
    mean = np.array([p[keep[:, j], j].mean() for j in range(p.shape[1])])
    b = int(keep.sum(axis=0).min())
    return np.sqrt(mean), 0.5 / math.sqrt(max(n_avg * b, 1))


def butterworth_cutoff(f: np.ndarray, psd: np.ndarray, floor: float, order: int, fs: float,
                       guess_hz: float) -> float:
    """The half-power frequency f_c (Hz) of an ``order``-th order digital Butterworth low-pass
    at ``fs`` (bilinear transform, as the twin's instrument models; an analog filter sampled at
    ``fs`` matches it well below the Nyquist frequency) fitted to a rest PSD (m,) whose white
    floor is ``floor`` (density, unit/√Hz): least squares of the log PSD against
    log(floor²·|H(f)|²) on the bins from 0.3·``guess_hz`` to 0.4·``fs``. NaN when that band has
    fewer than 5 bins."""
    sel = (f >= 0.3 * guess_hz) & (f <= 0.4 * fs) & (psd > 0)
    if sel.sum() < 5:
        return float("nan")
    fb, lp = f[sel], np.log(psd[sel])

    def cost(log_fc: float) -> float:
        sos = signal.butter(order, math.exp(log_fc), fs=fs, output="sos")
        _, h = signal.sosfreqz(sos, worN=fb, fs=fs)
        model = 2 * math.log(floor) + np.log(np.abs(h) ** 2 + 1e-300)
        return float(np.sum((lp - model) ** 2))

    r = optimize.minimize_scalar(cost, bounds=(math.log(0.1 * guess_hz), math.log(0.49 * fs)), method="bounded")
    return float(math.exp(r.x))


def torque_resolution(torque: np.ndarray) -> float:
    """The torque signal's resolution (N·m): the smallest step between distinct values of
    ``torque`` (n,) when the values lie on a grid of it (every difference a whole multiple
    within 1 %), else 0 (not quantised as far as this shows)."""
    v = np.unique(np.round(np.asarray(torque, float), 12))
    if v.size < 3:
        return 0.0
    steps = np.diff(v)
    q = float(steps.min())
    if q <= 0:
        return 0.0
    ratio = steps / q
    return q if np.all(np.abs(ratio - np.round(ratio)) < 0.01) else 0.0


#: The instruments' low-pass orders (the twin's instrument models: second-order IMU accelerometer
#: and gyroscope).
IMU_ORDER = 2


def _phase2_rests(run, fs: float) -> list[tuple[int, int]]:
    """The rests of a Phase II run on the IMU's clock: where the commanded position holds
    (``position_cmd``), else the 0.1-s windows whose accelerometer variance is within 4× the
    quietest window's (an IMU-only recording)."""
    n = len(run.imu_acc)
    if getattr(run, "position_cmd", None) is not None:
        x = np.asarray(run.position_cmd, float)
        fs_x = float(run.position_cmd_fs_hz)
        still = np.concatenate(([True], np.diff(x) == 0))
        idx = np.minimum((np.arange(n) / fs * fs_x).astype(int), x.size - 1)
        return rest_segments(~still[idx], fs, margin_s=PHASE2_REST_MARGIN_S)
    w = max(8, int(0.1 * fs))
    k = n // w
    var = np.var(np.asarray(run.imu_acc, float)[:k * w].reshape(k, w, 3)[:, :, 0], axis=1)
    quiet = np.repeat(var <= 4 * var.min(), w)
    quiet = np.concatenate([quiet, np.zeros(n - quiet.size, bool)])
    return rest_segments(~quiet, fs, margin_s=0.0)


def measure_instruments(m, phase1_captures: list[str], phase2_runs: list[tuple[str, str]],
                        imu_acc_bandwidth_hz: float, imu_gyro_bandwidth_hz: float) -> dict[str, Measured]:
    """The instruments of the open recording ``m`` measured from its rests, by scenario key
    (``sensors.imu_acc_noise_ug_per_rthz``, ...; the unit of each key) plus
    ``torque_resolution_Nm`` and ``imu_gravity_scale`` (which are not scenario keys). The
    bandwidths given are the first guesses of the fits (the axis description's or the twin's).
    A key is missing when the recording has no rest long enough for it."""
    out: dict[str, Measured] = {}
    if phase2_runs:
        acc_ps, gyro_ps, n_acc, n_gyro, grav = [], [], 0, 0, []
        f_acc = f_gyro = None
        fs_acc = fs_gyro = None
        for s, r in phase2_runs:
            run = m.phase2(s, r)
            fs_acc, fs_gyro = float(run.imu_acc_fs_hz), float(run.imu_gyro_fs_hz)
            segs = _phase2_rests(run, fs_acc)
            if not segs:
                continue
            f_acc, p, k = rest_spectrum(run.imu_acc, fs_acc, segs)
            acc_ps.append(p * k)
            n_acc += k
            grav += [float(np.linalg.norm(np.mean(run.imu_acc[a:b], axis=0))) for a, b in segs]
            gsegs = [(int(a * fs_gyro / fs_acc), int(b * fs_gyro / fs_acc)) for a, b in segs]
            f_gyro, p, k = rest_spectrum(run.imu_gyro, fs_gyro, gsegs)
            gyro_ps.append(p * k)
            n_gyro += k
        if acc_ps:
            for (name, f, ps, n, bw, scale, unit, fs) in (
                    ("imu_acc", f_acc, acc_ps, n_acc, imu_acc_bandwidth_hz, 1e6 / G0, "µg/√Hz", fs_acc),
                    ("imu_gyro", f_gyro, gyro_ps, n_gyro, imu_gyro_bandwidth_hz, 1e6, "µrad/s/√Hz", fs_gyro)):
                psd = np.sum(ps, axis=0) / n
                band = (0.1 * bw, 0.3 * min(bw, 0.5 * fs))
                dens, rel = floor_density(f, psd, band, n)
                floor = float(np.mean(dens))
                key = "imu_acc_noise_ug_per_rthz" if name == "imu_acc" else "imu_gyro_noise_urad_s_per_rthz"
                how = f"mean density of the three axes at rest, {band[0]:.3g}–{band[1]:.3g} Hz"
                out[f"sensors.{key}"] = Measured(floor * scale, unit, rel / math.sqrt(3), how)
                fc = np.array([butterworth_cutoff(f, psd[:, j], dens[j], IMU_ORDER, fs, bw) for j in range(3)])
                if np.all(np.isfinite(fc)):
                    out[f"sensors.{name}_bandwidth_hz"] = Measured(
                        float(np.median(fc)), "Hz", float(np.std(fc) / np.median(fc) / math.sqrt(3)),
                        f"half-power frequency of a Butterworth of order {IMU_ORDER} fitted to the rest spectrum")
            g = float(np.median(grav)) / G0
            out["imu_gravity_scale"] = Measured(g, "", float(np.std(grav) / G0 / math.sqrt(len(grav))),
                                                "|mean specific force| at rest / 9.80665 m/s²")
    if phase1_captures:
        ps, n_avg, diffs, tq_all = [], 0, [], []
        f1 = fs1 = None
        for name in phase1_captures:
            c = m.phase1(name)
            fs1 = float(c.fs_hz)
            sp = np.asarray(c.speed, float)
            plateau = float(np.percentile(np.abs(sp), 99))
            segs = rest_segments(np.abs(sp) > 0.02 * plateau, fs1)
            if not segs:
                continue
            f1, p, k = rest_spectrum(np.column_stack([c.acc1, c.acc2]), fs1, settled(segs), seg_s=0.02)
            ps.append(p * k)
            n_avg += k
            tq = np.asarray(c.torque, float)
            diffs += [np.diff(tq[a:b]) for a, b in segs]
            tq_all.append(tq)
        if ps:
            psd = np.sum(ps, axis=0) / n_avg
            band = (200.0, 0.15 * fs1)
            dens, rel = floor_density(f1, psd, band, n_avg)
            out["sensors.nut_acc_noise_ug_per_rthz"] = Measured(
                float(np.mean(dens)) * 1e6 / G0, "µg/√Hz", rel / math.sqrt(6),
                f"mean density of the six nut axes over the last half of each rest, {band[0]:.3g}–{band[1]:.3g} Hz")
            d = np.concatenate(diffs)
            q = torque_resolution(np.concatenate(tq_all))
            # white noise per sample: a difference has variance 2σ²; the quantisation's q²/12 removed.
            # Successive differences of white noise correlate -1/2: the relative error of σ from N of
            # them is sqrt(3/(4N)), not the independent sqrt(1/(2N)) (Bartlett's formula for the
            # variance of a sample variance of a correlated series: M. S. Bartlett, J. R. Stat. Soc.
            # Suppl. 8, 1946; relative error of σ = half that of σ²: sqrt(3/N)/2)
            var = max(float(np.var(d)) / 2 - q * q / 12, 0.0)
            out["sensors.torque_noise_Nm"] = Measured(
                math.sqrt(var), "N·m", math.sqrt(0.75 / max(d.size, 1)),
                "rms of the sample-to-sample changes at rest / √2, the resolution's share removed")
            out["torque_resolution_Nm"] = Measured(q, "N·m", 0.0, "smallest step between the torque's values")
    return out

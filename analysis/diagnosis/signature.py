"""The signature of a recording: the statistics the sim-to-real gap is judged on.

One vector of named statistics per part of a recording (``"cal"``: the even-numbered Phase I
captures of each sample and Phase II runs of each session, used to fit; ``"heldout"``: the
odd-numbered ones, used only to measure). The same function reads a real ``measurements.h5`` and
a simulated one, so twin and machine are compared statistic by statistic.

Each statistic belongs to a region: (domain, channel, family, bin) and the operating hours of the
Phase I sample or Phase II session it comes from. Families:

- ``band``: log10 of the power in a frequency band (Welch PSD; Phase I over the whole capture,
  Phase II over the constant-velocity cruises at each speed), channel × band;
- ``phase``: log10 RMS of the signal high-passed at 20 Hz (Phase I) or 2 Hz (Phase II) within one
  operating phase: steady (cruise), transient (acceleration/deceleration), reversal (±20 ms
  around a stop or start), dwell (standstill; in Phase I no nearer than 0.15 s to a start, a
  stop or the capture's ends, where the high-pass spreads the ramps);
- ``level``: mean |torque| in each Phase I operating phase (N·m); the constant drag (N·m) and
  the viscous drag coefficient (N·m·s/rad) of the motor torque over the motion of each Phase I
  capture (:func:`drag_fit`: with the ramps in, a constant and a viscous drag that give the same
  cruise torque differ); and the dwell mean of each IMU channel (m/s², rad/s: gravity
  projection and bias);
- ``feature``: the 46 Phase I features of the paper (section IV), per sample (line amplitudes
  and band energies as log10);
- ``position``: log10 RMS of each error motion (mean of forward and reverse, detrended) in four
  segments of the stroke, per session;
- ``timing``: how late each nut accelerometer's axial column is against the motor speed's
  derivative in each Phase I capture, ms (:func:`analysis.diagnosis.timing.acceleration_lag_ms`:
  a clock offset between the acquisition's channels);
- ``lag``: log10 of the RMS over the sessions after the first of the shift (µm) of E_XX (the only
  profile that repeats from session to session in a few runs: lead harmonics and ball pass,
  band-passed to 1.5–6 mm) in each stroke segment against the first session, found by
  cross-correlation; an origin that moves between sessions shifts every segment alike.

Logs of powers and RMS values make the statistics closer to Gaussian from seed to seed, which the
gap test (:mod:`analysis.diagnosis.gap`) assumes.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from analysis.calibration.drive import near_edges, rigid_body_fit
from analysis.dataset import DOFS, DatasetError, Measurements, open_measurements
from analysis.diagnosis.timing import acceleration_lag_ms
from analysis.phase1.features import FEATURE_NAMES, sample_features, summarise_capture, transient_templates
from analysis.phase2.error_motions import sensor_model, session_error_motions
from analysis.phase2.imu_runs import segment_run
from analysis.phase2.strokes import imu_run_segments

PARTS = ("cal", "heldout")
PHASE1_CHANNELS = ("speed", "torque", "acc1_x", "acc1_y", "acc1_z", "acc2_x", "acc2_y", "acc2_z")
PHASE1_BANDS_HZ = (10, 30, 60, 100, 150, 200, 300, 400, 500, 700, 1000, 1500, 2000, 3000, 4500)
PHASE2_CHANNELS = ("acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z")
PHASE2_BANDS_HZ = (2, 5, 10, 20, 40, 80, 150, 250, 400, 700)
OPERATING_PHASES = ("steady", "transient", "reversal", "dwell")
#: Phase I's phase statistics are read on the signals high-passed at this frequency, Hz.
PHASE1_HIGHPASS_HZ = 20.0
#: Phase I's dwell is read no nearer than this to a start, a stop or a capture's end, s: the
#: zero-phase high-pass spreads a ramp of the speed about 3/PHASE1_HIGHPASS_HZ either side (to
#: 0.3 % of its peak), far above the standstill's own content; a capture that begins just
#: before a move would otherwise read that spread as its dwell.
PHASE1_DWELL_GUARD_S = 3.0 / PHASE1_HIGHPASS_HZ
TIMING_CHANNELS = ("acc1_x", "acc2_x")  # the nut accelerometers' axial columns, timed against the speed
TIMING_BIN = "lag behind the speed (ms)"
DRAG_TERMS = ("constant drag", "viscous drag")  # the torque's drags over the motion (drag_fit)
POSITION_SEGMENTS = 4
LAG_SEARCH_M = 7e-3  # largest shift between sessions searched for, m (origins within ±3 mm)
SIGNATURE_VERSION = 7  # bump when a statistic (or what the cache holds) changes: caches are keyed on it
LAG_DOFS = ("E_XX",)  # the only motion whose profile repeats between sessions of a few runs
LAG_BAND_M = (1.5e-3, 6e-3)  # wavelengths correlated for the shift, m: lead harmonics 2-4
_TINY = 1e-30


class SignatureError(DatasetError):
    """A recording whose signature cannot be computed; the message names file, item and value."""


@dataclass(frozen=True)
class Region:
    """Where a statistic lives. domain: "phase1" | "phase2"; channel: e.g. "torque", "acc_x",
    "E_BX"; family: band | phase | level | feature | position | lag; bin: e.g. "300-400 Hz",
    "steady", "50-125 mm"; hours: operating hours of its sample/session (NaN: all sessions)."""

    domain: str
    channel: str
    family: str
    bin: str
    hours: float = float("nan")

    @property
    def key(self) -> tuple[str, str, str, str]:
        """The region without its hours: the unit the gap maps and the localisation report."""
        return (self.domain, self.channel, self.family, self.bin)

    @property
    def pool_key(self) -> tuple[str, ...]:
        """The statistics whose seed-to-seed variances are pooled: the same region at every
        hour; for the between-session shifts, every stroke segment too (one statistic per
        segment and none per hour, so that the variance has more than K − 1 degrees of freedom)."""
        return self.key[:3] if self.family == "lag" else self.key

    def label(self) -> str:
        return f"{self.domain} {self.channel} {self.family} {self.bin}"


@dataclass
class Signature:
    """values (n,) statistics of one part of a recording; regions (n,) where each lives."""

    values: np.ndarray
    regions: list[Region] = field(default_factory=list)


class _Builder:
    def __init__(self) -> None:
        self.values: list[float] = []
        self.regions: list[Region] = []

    def add(self, value: float, region: Region) -> None:
        self.values.append(float(value))
        self.regions.append(region)

    def build(self) -> Signature:
        return Signature(np.asarray(self.values, dtype=float), self.regions)


def _part_of(names: list[str], part: str) -> list[str]:
    """Even-indexed names for "cal", odd for "heldout"."""
    if part not in PARTS:
        raise ValueError(f"part is {part!r}; expected one of {PARTS}")
    return names[0::2] if part == "cal" else names[1::2]


def _band_labels(edges) -> list[str]:
    return [f"{a:g}-{b:g} Hz" for a, b in zip(edges[:-1], edges[1:], strict=True)]


def _band_powers(x: np.ndarray, fs: float, edges, nperseg: int) -> np.ndarray:
    """log10 power (unit²) in each band of ``edges`` Hz of the columns of x (n, c) → (c, nb)."""
    nper = min(nperseg, x.shape[0])
    f, p = signal.welch(x, fs=fs, nperseg=nper, axis=0, detrend="constant")
    df = f[1] - f[0]
    out = np.empty((x.shape[1], len(edges) - 1))
    for i, (a, b) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
        sel = (f >= a) & (f < b)
        out[:, i] = np.log10(p[sel].sum(axis=0) * df + _TINY) if sel.any() else np.nan
    return out


def _highpass(x: np.ndarray, fs: float, fc: float) -> np.ndarray:
    sos = signal.butter(4, fc, "highpass", fs=fs, output="sos")
    return signal.sosfiltfilt(sos, x, axis=0)


def _phase_masks(moving: np.ndarray, steady: np.ndarray, fs: float, window_s: float = 0.02,
                 dwell_guard_s: float = 0.0) -> dict[str, np.ndarray]:
    """Boolean (n,) masks of the four operating phases from moving/steady masks (n,): reversal
    within ``window_s`` s of a start or stop; dwell standing still, and with ``dwell_guard_s`` no
    nearer than that to a start, a stop or either end of the signal."""
    reversal = near_edges(moving, fs, window_s)
    dwell = ~moving & ~reversal
    if dwell_guard_s > 0:
        dwell &= ~near_edges(moving, fs, dwell_guard_s, ends=True)
    return {"steady": steady & ~reversal, "transient": moving & ~steady & ~reversal,
            "reversal": reversal, "dwell": dwell}


def _log_rms(x: np.ndarray) -> np.ndarray:
    return np.log10(np.sqrt(np.mean(x ** 2, axis=0)) + 1e-15)


# ---------------------------------------------------------------------------------------------
# Phase I


def drag_fit(speed: np.ndarray, torque: np.ndarray, fs: float) -> np.ndarray:
    """(2,) the constant drag T_c (N·m) and the viscous drag coefficient c_v (N·m·s/rad) of a
    motor torque over the motion: the last two terms of the rigid-body fit
    torque = J·dω/dt + T_c·sign(ω) + c_v·ω (:func:`analysis.calibration.drive.rigid_body_fit`:
    the ramps separate the two, since a constant drag adds alike at every speed and a viscous one
    in proportion). NaN for both when the capture has no ramp."""
    return rigid_body_fit(speed, torque, fs)[1:]


def _phase1_capture_stats(c) -> np.ndarray:
    """(n_stats,) statistics of one capture in the order of :func:`_phase1_regions`."""
    fs = float(c.fs_hz)
    x = np.column_stack([c.speed, c.torque, c.acc1, c.acc2])  # (n, 8)
    bands = _band_powers(x, fs, PHASE1_BANDS_HZ, int(round(0.1 * fs)))
    plateau = float(np.percentile(np.abs(c.speed), 99))
    moving = np.abs(c.speed) > 0.02 * plateau
    steady = np.abs(c.speed) >= 0.98 * plateau
    masks = _phase_masks(moving, steady, fs, dwell_guard_s=PHASE1_DWELL_GUARD_S)
    hp = _highpass(x, fs, PHASE1_HIGHPASS_HZ)
    phase = np.full((8, len(OPERATING_PHASES)), np.nan)
    level = np.full(len(OPERATING_PHASES), np.nan)
    for j, name in enumerate(OPERATING_PHASES):
        m = masks[name]
        if m.sum() >= 8:
            phase[:, j] = _log_rms(hp[m])
            level[j] = float(np.mean(np.abs(c.torque[m])))
    timing = [acceleration_lag_ms(c.speed, np.asarray(acc, float)[:, 0], fs) for acc in (c.acc1, c.acc2)]
    return np.concatenate([bands.ravel(), phase.ravel(), level, drag_fit(c.speed, c.torque, fs), timing])


def _phase1_regions(hours: float) -> list[Region]:
    out = [Region("phase1", ch, "band", b, hours) for ch in PHASE1_CHANNELS
           for b in _band_labels(PHASE1_BANDS_HZ)]
    out += [Region("phase1", ch, "phase", ph, hours) for ch in PHASE1_CHANNELS for ph in OPERATING_PHASES]
    out += [Region("phase1", "torque", "level", ph, hours) for ph in OPERATING_PHASES]
    out += [Region("phase1", "torque", "level", term, hours) for term in DRAG_TERMS]
    out += [Region("phase1", ch, "timing", TIMING_BIN, hours) for ch in TIMING_CHANNELS]
    return out


def _phase1(m: Measurements, part: str, b: _Builder) -> None:
    names = m.phase1_captures()
    if not names:
        return
    by_sample: dict[int, list[str]] = {}
    for n in names:
        by_sample.setdefault(m.phase1_header(n)[1], []).append(n)
    templates = None
    for sample in sorted(by_sample):
        chosen = _part_of(by_sample[sample], part)
        if not chosen:
            raise SignatureError(
                f"{m.label}: Phase I sample {sample} has {len(by_sample[sample])} capture(s); the "
                "diagnosis needs at least 2 per sample (even ones to fit, odd ones held out)")
        caps = [m.phase1(n) for n in chosen]
        hours = float(np.mean([c.hours for c in caps]))
        per_capture = np.array([_phase1_capture_stats(c) for c in caps])
        # a statistic no capture of the sample has (NaN in all) stays NaN, without numpy's warning
        seen = ~np.isnan(per_capture).all(axis=0)
        stats = np.full(per_capture.shape[1], np.nan)
        stats[seen] = np.nanmean(per_capture[:, seen], axis=0)
        for v, r in zip(stats, _phase1_regions(hours), strict=True):
            b.add(v, r)
        summaries = [summarise_capture(c, m.label) for c in caps]
        if templates is None:
            templates = transient_templates(summaries)
        feats = sample_features(summaries, templates)
        for name, v in zip(FEATURE_NAMES, feats, strict=True):
            # Line amplitudes and band energies are positive and skewed: log10 makes them
            # closer to Gaussian from seed to seed.
            if name.startswith(("amp", "band")):
                v = np.log10(v + 1e-15)
            b.add(v, Region("phase1", "features", "feature", name, hours))


# ---------------------------------------------------------------------------------------------
# Phase II


def speed_key(speed_m_s: float) -> float:
    """The label of a cruise speed (m/s) in the statistics' names, mm/s to 0.1. Rounded to 4
    decimals first: a routine's speed with two decimals (85.95 mm/s) measured as 85.949999999 in
    one recording and 85.950000001 in another (a lab's file, the twin) must get one label, not
    85.9 and 86."""
    return round(round(speed_m_s * 1e3, 4), 1)


def _phase2_run_stats(run, acc_bandwidth_hz: float = 300.0) -> tuple[dict, np.ndarray]:
    """Band powers per speed {speed_mm_s: (6, nb)} (acc x y z, gyro x y z) and the (6·4 + 6,)
    phase statistics (log RMS per channel and phase, then the dwell mean per channel)."""
    if run.position_cmd is not None:
        seg = segment_run(run.position_cmd, run.position_cmd_fs_hz)
        pos_t = np.arange(run.position_cmd.size) / run.position_cmd_fs_hz
        v = np.abs(np.gradient(run.position_cmd, pos_t)) > 1e-9
    else:  # a stand-alone IMU: strokes from the accelerometer and the routine metadata
        seg, moves = imu_run_segments(run, acc_bandwidth_hz, label=f"session {run.session}, run {run.run}, imu_acc")
    bands: list[dict[float, np.ndarray]] = []
    phase_stats, levels = [], []
    for arr, fs in ((run.imu_acc, run.imu_acc_fs_hz), (run.imu_gyro, run.imu_gyro_fs_hz)):
        t = np.arange(arr.shape[0]) / fs
        cruise = np.zeros(t.size, bool)
        per_speed: dict[float, list[np.ndarray]] = {}
        for mo in seg.motions:
            sel = (t >= mo.t0_s + 0.1) & (t <= mo.t1_s - 0.005)
            cruise |= sel
            if sel.sum() >= 64:
                per_speed.setdefault(speed_key(mo.speed_m_s), []).append(
                    _band_powers(arr[sel], fs, PHASE2_BANDS_HZ, 256))
        bands.append({k: np.mean(p, axis=0) for k, p in per_speed.items()})
        if run.position_cmd is not None:
            moving = np.interp(t, pos_t, v.astype(float)) > 0.5
        else:
            moving = np.zeros(t.size, bool)
            for t0, t1 in moves:
                moving |= (t >= t0) & (t < t1)
        still = np.zeros(t.size, bool)
        for t0, t1 in seg.still:
            still |= (t >= t0) & (t <= t1)
        masks = _phase_masks(moving, cruise, fs)
        masks["dwell"] &= still
        hp = _highpass(arr, fs, 2.0)
        for name in OPERATING_PHASES:
            mk = masks[name]
            phase_stats.append(_log_rms(hp[mk]) if mk.sum() >= 8 else np.full(3, np.nan))
        levels.append(arr[still].mean(axis=0) if still.any() else np.full(3, np.nan))
    speeds = sorted(set(bands[0]) & set(bands[1]))
    by_speed = {sp: np.vstack([bands[0][sp], bands[1][sp]]) for sp in speeds}
    # phase_stats: acc (steady, transient, reversal, dwell), then gyro, each (3,) over x y z
    ph = np.stack(phase_stats).reshape(2, len(OPERATING_PHASES), 3).transpose(0, 2, 1).reshape(6, -1)
    return by_speed, np.concatenate([ph.ravel(), np.concatenate(levels)])


def _segments(x: np.ndarray, margin: float) -> list[tuple[float, float]]:
    """The POSITION_SEGMENTS equal spans (lo, hi) in m of the grid ``x`` (n,) less ``margin`` at
    each end; none when the profile is too short to leave each of them 4 grid steps (a short
    stroke: the trimmed cruise of the slow pass leaves a few mm)."""
    lo, hi = x[0] + margin, x[-1] - margin
    if x.size < 2 or hi - lo < POSITION_SEGMENTS * 4 * (x[1] - x[0]):
        return []
    edges = np.linspace(lo, hi, POSITION_SEGMENTS + 1)
    return list(zip(edges[:-1], edges[1:], strict=True))


def _profile(em) -> tuple[np.ndarray, np.ndarray]:
    """Mean of forward and reverse of the combined error motions: x (n,) m, (6, n)."""
    c = em.combined
    return c.x_m, 0.5 * (c.forward + c.reverse)


def _bandpass_profile(x: np.ndarray, prof: np.ndarray) -> np.ndarray:
    """The profiles (6, n) band-passed to the wavelengths LAG_BAND_M (zero phase)."""
    fs = 1.0 / (x[1] - x[0])
    sos = signal.butter(4, [1.0 / LAG_BAND_M[1], 1.0 / LAG_BAND_M[0]], "bandpass", fs=fs, output="sos")
    return signal.sosfiltfilt(sos, prof, axis=1)


def _lag(ref_x: np.ndarray, ref: np.ndarray, x: np.ndarray, y: np.ndarray, lo: float, hi: float) -> float:
    """Shift d (m) such that y(u) ≈ ref(u + d) on [lo, hi]: cross-correlation peak with a
    parabolic sub-sample refinement. Both on the same uniform grid step."""
    dx = ref_x[1] - ref_x[0]
    sel = (x >= lo) & (x < hi)
    if np.count_nonzero(sel) < 2:  # this session's profile does not reach the span
        return np.nan
    seg = y[sel] - y[sel].mean()
    n_lag = int(round(LAG_SEARCH_M / dx))
    i0 = int(round((x[sel][0] - ref_x[0]) / dx))
    a, bnd = i0 - n_lag, i0 + seg.size + n_lag
    if a < 0 or bnd > ref.size:
        return np.nan
    win = ref[a:bnd] - ref[a:bnd].mean()
    cc = signal.correlate(win, seg, mode="valid")  # (2·n_lag + 1,)
    k = int(np.argmax(cc))
    frac = 0.0
    if 0 < k < cc.size - 1:
        c0, c1, c2 = cc[k - 1], cc[k], cc[k + 1]
        den = c0 - 2 * c1 + c2
        frac = 0.5 * (c0 - c2) / den if den != 0 else 0.0
    return float((k - n_lag + frac) * dx)


def _phase2(m: Measurements, part: str, b: _Builder) -> None:
    sessions = m.phase2_sessions()
    if not sessions:
        return
    profiles = []
    for s in sessions:
        runs = _part_of(m.phase2_runs(s), part)
        if not runs:
            raise SignatureError(
                f"{m.label}: Phase II session {s} has {len(m.phase2_runs(s))} run(s); the "
                "diagnosis needs at least 2 per session (even ones to fit, odd ones held out)")
        hours = m.session_hours(s)
        acc_bw = sensor_model(m).acc_bandwidth_hz
        stats = [_phase2_run_stats(m.phase2(s, r), acc_bw) for r in runs]
        speeds = sorted(stats[0][0])
        for sp in speeds:
            p = np.mean([st[0][sp] for st in stats if sp in st[0]], axis=0)  # (6, nb)
            for ci, ch in enumerate(PHASE2_CHANNELS):
                for bi, lab in enumerate(_band_labels(PHASE2_BANDS_HZ)):
                    b.add(p[ci, bi], Region("phase2", ch, "band", f"{lab} @{sp:g} mm/s", hours))
        rest = np.nanmean([st[1] for st in stats], axis=0)
        k = 0
        for ch in PHASE2_CHANNELS:
            for ph in OPERATING_PHASES:
                b.add(rest[k], Region("phase2", ch, "phase", ph, hours))
                k += 1
        for ch in PHASE2_CHANNELS:
            b.add(rest[k], Region("phase2", ch, "level", "dwell mean", hours))
            k += 1
        # The fine `slow` layer (10 µm grid) is not used here: computed on the coarse grid.
        em = session_error_motions(m, s, runs=runs, slow_dx_m=0.5e-3)
        x, prof = _profile(em)
        profiles.append((x, _bandpass_profile(x, prof)))
        for lo, hi in _segments(x, LAG_SEARCH_M):
            sel = (x >= lo) & (x < hi)
            lab = f"{lo * 1e3:.0f}-{hi * 1e3:.0f} mm"
            for j, dof in enumerate(DOFS):
                seg = signal.detrend(prof[j, sel])
                b.add(np.log10(np.sqrt(np.mean(seg ** 2)) + 1e-15),
                      Region("phase2", dof, "position", lab, hours))
    if len(profiles) < 2:
        return
    ref_x, ref = profiles[0]
    segs = _segments(ref_x, LAG_SEARCH_M + 4e-3)
    if not segs:
        return
    lags = np.full((len(profiles) - 1, len(segs), len(LAG_DOFS)), np.nan)
    for i, (x, prof) in enumerate(profiles[1:]):
        for k, (lo, hi) in enumerate(segs):
            for j, dof in enumerate(LAG_DOFS):
                r = DOFS.index(dof)
                lags[i, k, j] = _lag(ref_x, ref[r], x, prof[r], lo, hi)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a span no session reaches: NaN, left out
        rms = np.sqrt(np.nanmean(lags ** 2, axis=0))
    for k, (lo, hi) in enumerate(segs):
        for j, dof in enumerate(LAG_DOFS):
            # log10 of the RMS shift in µm plus 10 µm (about the shift's scatter in a few runs)
            b.add(np.log10(rms[k, j] * 1e6 + 10.0),
                  Region("phase2", dof, "lag", f"{lo * 1e3:.0f}-{hi * 1e3:.0f} mm"))


def signature(path, part: str, domains: tuple[str, ...] = ("phase1", "phase2")) -> Signature:
    """The signature of one part ("cal" or "heldout") of the recording ``path`` (a
    ``measurements.h5``); ``domains`` limits it to the statistics of "phase1" and/or "phase2"
    (the others left out, e.g. to recompute only what an artefact on one domain changes). Raises
    :class:`SignatureError` / :class:`analysis.dataset.DatasetError` naming the file and item
    when the recording cannot be used."""
    b = _Builder()
    with open_measurements(path) as m:
        if "phase1" in domains:
            _phase1(m, part, b)
        if "phase2" in domains:
            _phase2(m, part, b)
    if not b.values:
        raise SignatureError(f"{path}: no Phase I capture and no Phase II session; expected at least one")
    return b.build()


def update_signature(base: Signature, path, part: str, domains: tuple[str, ...]) -> Signature:
    """The signature of ``path`` computed only for ``domains``, the other statistics taken from
    ``base`` (the signature of a recording ``path`` differs from only in those domains, e.g. the
    same recording with an artefact on Phase I channels)."""
    new = signature(path, part, domains)
    mask = np.array([r.domain in domains for r in base.regions])
    if int(mask.sum()) != new.values.size or any(
            a.key != b.key for a, b in zip([r for r, k in zip(base.regions, mask, strict=True) if k],
                                           new.regions, strict=True)):
        raise SignatureError(f"{path}: its {'/'.join(domains)} statistics are laid out unlike "
                             "those of the recording it was derived from")
    values = base.values.copy()
    values[mask] = new.values
    return Signature(values, base.regions)

"""The chain every triaxial instrument shares, from the true signal to filtered, noisy samples:
what an ideal accelerometer senses, the sensor's response (a cached Butterworth design at the
simulation rate) and its group delay, white noise at the datasheet density, and the sampling at
the instrument's rate, for one recording or for many at once (blocks of runs, bit for bit the
single-recording outputs).

SI units (m/s², rad/s, s, Hz). Every random draw comes from the generators the caller passes in.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy import signal

from twin.sim.sensors.sampling import _sample_rows, _sampling_plan
from twin.sim.sensors.specs import STANDARD_GRAVITY

try:  # the in-place filter behind scipy.signal.sosfilt (see _sosfilt_rows)
    from scipy.signal._sosfilt import _sosfilt
except ImportError:  # pragma: no cover
    _sosfilt = None


def specific_force_in_sensor_frame(acceleration_world: np.ndarray,
                                   rotation_world_from_sensor: np.ndarray,
                                   gravity: float = STANDARD_GRAVITY) -> np.ndarray:
    """What an ideal accelerometer senses: ``R^T (a - g_vec)`` with ``g_vec = (0, 0, -gravity)``.

    Exactly kinematic (no modelling shortcut): an accelerometer at rest and level reads +g on z;
    a sensor rotated by a small angle θ about +y (right-hand rule) reads ``-g·sin θ`` on x, which is
    the ``f_x = ... - g·E_BX`` term of the IMU measurement model (:mod:`analysis.phase2.fusion`).

    Args:
        acceleration_world: (n, 3) or (3,) acceleration of the sensor point in the world frame
            (z up), m/s².
        rotation_world_from_sensor: (n, 3, 3) or (3, 3) rotation matrices whose columns are the
            sensor axes in world coordinates.
        gravity: magnitude of gravity, m/s².

    Returns:
        (n, 3) (or (3,)) specific force in the sensor frame, m/s².
    """
    acc = np.asarray(acceleration_world, dtype=float)
    rot = np.asarray(rotation_world_from_sensor, dtype=float)
    f_world = acc - np.array([0.0, 0.0, -gravity])
    return np.einsum("...ji,...j->...i", rot, f_world)


def butterworth_group_delay(order: int, cutoff_hz: float) -> float:
    """Group delay at low frequency of an analog Butterworth low-pass, s.

    ``tau(0) = 1 / (2π·f_c·sin(π / (2·order)))``: the sum of ``-Re(p)/|p|²`` over its poles on the
    circle of radius ``2π·f_c``. Second order at 300 Hz: 0.75 ms; at 200 Hz: 1.13 ms. The digital
    filters used here (bilinear, prewarped at the cutoff) match it within 1 % for the IMU
    defaults at fs_sim >= 5 kHz; when the cutoff nears fs_sim/2 they do not (the nut's 4 kHz
    anti-alias at 10 kHz: 42 µs digital against 104 µs analog); use :func:`sensor_group_delay`
    for the filter actually applied.
    """
    return 1.0 / (2.0 * math.pi * cutoff_hz * math.sin(math.pi / (2 * order)))


def sensor_group_delay(spec, fs_sim: float) -> float:
    """Group delay of the response a measurement function applies for ``spec`` at ``fs_sim``, s.

    Evaluated on the digital filter itself at 0.1·bandwidth_hz (flat to well under 1 % below
    that for the IMU defaults; there the AC-coupling high-pass of the nut accelerometer adds
    under 1 µs). The measurement functions leave this delay in their output, as a real sensor
    does; an estimator that aligns IMU data with position may subtract it.
    """
    sos = _sensor_filter(spec, fs_sim)
    b, a = signal.sos2tf(sos)
    _, delay = signal.group_delay((b, a), w=[0.1 * spec.bandwidth_hz], fs=fs_sim)
    return float(delay[0]) / fs_sim


def _validate_triaxial(values, name: str) -> np.ndarray:
    values = np.asarray(values, dtype=float)
    if values.ndim != 2 or values.shape[1] != 3 or values.shape[0] < 2:
        raise ValueError(f"{name} must have shape (n, 3) with n >= 2, got {values.shape}")
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{name} contains NaN or inf")
    return values


def _validate_fs(fs_sim: float) -> None:
    if not (np.isfinite(fs_sim) and fs_sim > 0):
        raise ValueError(f"fs_sim must be a positive sampling rate in Hz, got {fs_sim!r}")


def _sensor_filter(spec, fs_sim: float) -> np.ndarray:
    """Second-order sections of the sensor's response designed at ``fs_sim``: the Butterworth
    low-pass (half-power at ``spec.bandwidth_hz``), plus the AC-coupling high-pass if the spec has
    a nonzero ``highpass_hz``. A fresh copy of the cached design (:func:`_filter_design`)."""
    return _filter_design(spec, float(fs_sim))[0].copy()


@functools.lru_cache(maxsize=64)
def _filter_design(spec, fs_sim: float) -> tuple[np.ndarray, np.ndarray]:
    """(sos (s, 6), zi (s, 2)) of the sensor's response at ``fs_sim``: designed once per
    (spec, rate), since specs are frozen (hashable) dataclasses; ``zi`` is ``sosfilt_zi`` (the
    steady state for a unit input). Read-only arrays shared by every caller."""
    nyquist = fs_sim / 2.0
    if spec.bandwidth_hz >= 0.9 * nyquist:
        raise ValueError(
            f"{type(spec).__name__}: bandwidth {spec.bandwidth_hz} Hz needs a simulation rate "
            f"above {spec.bandwidth_hz / 0.45:.0f} Hz, got fs_sim={fs_sim} Hz"
        )
    order = int(spec.filter_order)
    sections = [signal.butter(order, spec.bandwidth_hz, btype="low", fs=fs_sim, output="sos")]
    highpass_hz = getattr(spec, "highpass_hz", 0.0)
    if highpass_hz > 0:
        sections.append(signal.butter(1, highpass_hz, btype="high", fs=fs_sim, output="sos"))
    sos = np.vstack(sections)
    zi = signal.sosfilt_zi(sos)
    sos.flags.writeable = False
    zi.flags.writeable = False
    return sos, zi


#: Upper bound on the float64 working array of one block of runs in :func:`_instrument_chains`
#: (samples × columns × 8 bytes); a block's transient memory is a few times this.
_BLOCK_BYTES = 4 * 2**20


def _noise_rate(spec, fs_sim: float) -> float:
    """Rate at which the instrument's noise is drawn and filtered, Hz: its output rate
    ``spec.fs_hz`` when it decimates (``fs_hz < fs_sim``) and its response can be designed there
    (``bandwidth_hz < 0.45·fs_hz``), else ``fs_sim``. Noise drawn at the output rate has the same
    in-band density ``noise_density·|H(f)|`` and needs no resampling (the IMU channels of Phase II);
    what it lacks is the small share of noise above ``fs_hz/2`` that would alias into the band."""
    fs_out = float(spec.fs_hz)
    if fs_out < fs_sim and spec.bandwidth_hz < 0.45 * fs_out:
        return fs_out
    return float(fs_sim)


def _sosfilt_rows(sos: np.ndarray, rows: np.ndarray, zi: np.ndarray) -> None:
    """``scipy.signal.sosfilt`` of each row of ``rows`` (r, n) float64 C-contiguous, in place,
    from the states ``zi`` (r, s, 2) (s sections of ``sos`` (s, 6)). Scipy's own routine without
    the copy ``sosfilt`` makes of its input (the same arithmetic: bit for bit its output)."""
    if _sosfilt is None:  # a scipy without the private routine
        rows[...] = signal.sosfilt(sos, rows, axis=-1, zi=np.moveaxis(zi, 1, 0))[0]
        return
    _sosfilt(np.array(sos, dtype=float, order="C"), rows, np.ascontiguousarray(zi, dtype=float))


def _instrument_chain(true_values: np.ndarray, fs_sim: float, spec, rng: np.random.Generator,
                      t0: float) -> tuple[np.ndarray, np.ndarray]:
    """The chain shared by all triaxial instruments, before their output quantisation.

    1. error model on the true signal (bias, scale, misalignment);
    2. the sensor's causal response (``sosfilt``, Butterworth low-pass of ``spec.filter_order``
       with half-power at ``spec.bandwidth_hz``, plus the high-pass when the spec has one) on that
       signal at ``fs_sim``, started in the steady state of its first value, so a constant input
       gives a constant output from the first sample;
    3. sampling at ``t0 + k / spec.fs_hz`` (:func:`decimate_to`: an exact pick when ``fs_hz``
       divides ``fs_sim``, else the not-a-knot cubic spline);
    4. white noise of one-sided density ``spec.noise_density``, drawn at the rate of
       :func:`_noise_rate` (std ``noise_density·sqrt(rate / 2)`` per sample), run through the same
       response designed at that rate (a warm-up of ``10 / bandwidth_hz`` seconds discarded, so it
       is stationary from the first sample) and added; at ``fs_sim`` the noise is added before the
       response and sampled with the signal (the instrument's aliasing of it included).

    The response is linear, so filtering signal and noise apart equals filtering their sum; the
    filter's group delay (:func:`sensor_group_delay`) is left in, as in the real sensor. In band
    the output noise density is ``noise_density·|H(f)|`` either way.

    Returns:
        t_out: (m,) sample instants, s.
        samples: (m, 3) filtered, noisy signal at those instants, unit of the input.
    """
    t_out, out = _instrument_chains([true_values], fs_sim, spec, [rng], t0)
    return t_out, out[0]


def _instrument_chains(true_values: list[np.ndarray], fs_sim: float, spec,
                       rngs: list[np.random.Generator], t0: float, finish=None, dtype=None
                       ) -> tuple[np.ndarray, list[np.ndarray]]:
    """:func:`_instrument_chain` for several recordings of one instrument at once.

    Recording j is ``true_values[j]`` (n, 3) measured with noise drawn from ``rngs[j]`` (the
    same array object may appear several times: the runs of a Phase II session share their
    motion; its error model, response and sampling are then computed once). Noise is processed in
    blocks of recordings: one filter design (cached per spec and rate) and one ``sosfilt`` per
    block. Each recording's noise is drawn from its own generator in list order, one
    ``(n_warm + n_noise, 3)`` block per recording, so the draws and every output array are bit
    for bit those of one :func:`_instrument_chain` call per recording in the same order
    (``sosfilt``, the banded solve and the spline evaluation act on each row alone; checked by
    tests/test_sensors.py). ``finish``, if given, is an elementwise map (the output
    quantisation) applied to a block's samples as soon as they are filtered, and ``dtype`` the
    type each recording's samples are then cast to, so that only one block's float64 samples
    are held at a time.

    Returns:
        t_out: (m,) sample instants, s.
        samples: list of (m, 3) arrays, one per recording, unit of the input (or what
        ``finish`` and ``dtype`` make of them).
    """
    if len(true_values) != len(rngs):
        raise ValueError(f"{len(true_values)} recordings but {len(rngs)} generators")
    sos, zi_unit = _filter_design(spec, float(fs_sim))
    n = true_values[0].shape[0]
    if any(v.shape != (n, 3) for v in true_values):
        raise ValueError("recordings of one call must share their shape (n, 3)")
    t_out = _sampling_plan(n, fs_sim, spec.fs_hz, t0)[0]
    fs_noise = _noise_rate(spec, fs_sim)
    separate = fs_noise != fs_sim
    if separate:
        n_noise = t_out.size
        sos_noise = _filter_design(spec, fs_noise)[0]
    else:
        n_noise = n
        sos_noise = sos
    n_warm = int(math.ceil(10.0 / spec.bandwidth_hz * fs_noise))
    noise_std = spec.noise_density * math.sqrt(fs_noise / 2.0)
    # Deterministic part (the signal with its sensor errors), once per distinct true signal: at
    # fs_sim with a warm-up at its first value when the noise joins it before the response, else
    # already filtered and sampled.
    prepared: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for v in true_values:
        if id(v) not in prepared:
            det = spec.error.apply(v)
            zi = zi_unit[:, None, :] * det[0][None, :, None]
            if separate:
                filtered, _ = signal.sosfilt(sos.copy(), np.ascontiguousarray(det.T), axis=-1, zi=zi)
                prepared[id(v)] = (_sample_rows(filtered, fs_sim, spec.fs_hz, t0), zi)
            else:
                driven = np.concatenate([np.broadcast_to(det[0], (n_warm, 3)), det])
                prepared[id(v)] = (driven.T, zi)
    per_block = max(1, _BLOCK_BYTES // ((n_warm + n_noise) * 3 * 8))
    outputs = []
    noise = np.empty((n_warm + n_noise, 3))  # reused: standard_normal(out=) fills it as a new one
    for start in range(0, len(rngs), per_block):
        block = range(start, min(start + per_block, len(rngs)))
        # One row per channel (3 per recording): the layout sosfilt and the spline work in.
        driven = np.empty((3 * len(block), n_warm + n_noise))
        zi = np.zeros((3 * len(block), sos_noise.shape[0], 2))
        for j, i in enumerate(block):
            rngs[i].standard_normal(out=noise)
            if separate:
                np.multiply(noise.T, noise_std, out=driven[3 * j:3 * j + 3])
            else:
                noise *= noise_std
                det, zi_det = prepared[id(true_values[i])]
                zi[3 * j:3 * j + 3] = np.moveaxis(zi_det, 1, 0)
                np.add(det, noise.T, out=driven[3 * j:3 * j + 3])
        _sosfilt_rows(sos_noise, driven, zi)
        samples = driven[:, n_warm:]
        if separate:
            for j, i in enumerate(block):
                samples[3 * j:3 * j + 3] += prepared[id(true_values[i])][0]
        else:
            samples = _sample_rows(samples, fs_sim, spec.fs_hz, t0)
        del driven
        if finish is not None:
            samples = finish(samples)
        for j in range(len(block)):
            rows = samples[3 * j:3 * j + 3].T
            outputs.append(rows if dtype is None else rows.astype(dtype))
    return t_out, outputs

"""Signal artefacts: the third kind of candidate of the gap diagnosis, applied to the channels of
a recording in the dataset format without simulating.

A real recording differs from its twin first by what the sensors and the acquisition did to it:
a sensitivity error, a noisier channel, mains pickup, a bias that drifts over the months, a
clock offset between channels, a converter that clips. Each artefact here is a pure transform of
arrays (:func:`gain`, :func:`white_noise`, :func:`fixed_line`, :func:`order_line`,
:func:`bias_drift`, :func:`delay`, :func:`clip`) and :func:`apply` writes a copy of a
``measurements.h5`` with one of them applied to the channels of a :class:`Target`; the diagnosis
takes the response of an artefact as the change of every statistic between the twin's first seed
and that seed post-processed (common random numbers, as for the physical effects), fits and ranks
it with them.

The candidates (:data:`ARTEFACTS`, one per artefact and target; name ``artefact:target``):

- ``gain``: every column of the target times (1 + error): a sensitivity error, %;
- ``noise``: white Gaussian noise of a given RMS added to every column (a noisier channel), drawn
  from the scenario's seed;
- ``mains_line``: a sine of fixed frequency (50/60 Hz and harmonics) on every column, its phase
  drawn for each capture or run (an acquisition does not start in step with the mains), the same Hz
  at every speed and at standstill: electrical pickup;
- ``order_line``: a sine locked to the motor angle (the integral of the Phase I ``speed``
  channel, rad): its frequency is the order times the rotational frequency and follows the
  speed, absent as a line at standstill: a mechanical source (unbalance, misalignment);
- ``bias_drift``: an offset growing linearly with the operating hours of each capture or run
  (zero at 0 h), per 1000 h;
- ``time_offset``: the target's channels delayed (positive) or advanced against the others of
  their capture or run by a whole number of samples (the offset in ms rounded at each channel's
  rate; the first or last value held at the edge, or the signal mirrored there: :func:`delay`);
- ``clipping``: every column clipped at ± the converter's range (0: no clipping; discrete).

Each parameter has a prior range (where the blind benchmark draws a present artefact), a fit
grid, and how a person reads it (label, unit, significant digits). Physical sources: IEEE Std
1451.4 / ISO 16063-21 (accelerometer sensitivity and its calibration), IEC 61000-4-16 (mains
frequency common-mode pickup on signal lines), Randall, "Vibration-based Condition Monitoring"
(Wiley 2011), ch. 3 (order tracking: lines locked to the shaft angle), IEEE Std 1554 (inertial
sensor bias instability and drift).
"""

from __future__ import annotations

import shutil
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from analysis.diagnosis.candidate import CandidateParam

KIND_EFFECT = "physical effect"
KIND_ARTEFACT = "signal artefact"
KIND_PARAMETER = "parameter"  # a twin parameter set wrong (twin/harness/diagnosis/candidates/parameters.py)
#: Bump when a transform or a candidate's grid changes: the harness caches artefact signatures
#: on it (2: the mains line's phase drawn per capture or run).
ARTEFACT_VERSION = 2


class ArtefactError(ValueError):
    """An artefact that cannot be applied (an unknown candidate or parameter, a missing channel)."""


# ---------------------------------------------------------------------------------------------
# The transforms: arrays (n,) or (n, c) in, same shape out (float64)


def gain(x: np.ndarray, error_pct: float) -> np.ndarray:
    """The channel with a sensitivity error: x · (1 + error_pct/100)."""
    return np.asarray(x, float) * (1.0 + error_pct / 100.0)


def white_noise(x: np.ndarray, rms: float, rng: np.random.Generator) -> np.ndarray:
    """x plus independent Gaussian noise of standard deviation ``rms`` (x's unit) per sample."""
    x = np.asarray(x, float)
    return x + rng.normal(0.0, rms, x.shape) if rms > 0 else x.copy()


def fixed_line(x: np.ndarray, fs_hz: float, amplitude: float, frequency_hz: float,
               phase_rad: float = 0.0) -> np.ndarray:
    """x plus A·sin(2π f t + φ) on every column, t = i/fs (s): a line at ``frequency_hz``
    whatever the machine does."""
    x = np.asarray(x, float)
    t = np.arange(x.shape[0]) / fs_hz
    line = amplitude * np.sin(2 * np.pi * frequency_hz * t + phase_rad)
    return x + (line[:, None] if x.ndim == 2 else line)


def shaft_angle(speed_rad_s: np.ndarray, fs_hz: float) -> np.ndarray:
    """The motor angle (rad, from 0) of a speed record (n,) rad/s: trapezoidal integral."""
    w = np.asarray(speed_rad_s, float)
    out = np.zeros_like(w)
    out[1:] = np.cumsum(0.5 * (w[1:] + w[:-1])) / fs_hz
    return out


def order_line(x: np.ndarray, angle_rad: np.ndarray, amplitude: float, order: float) -> np.ndarray:
    """x plus A·sin(order · θ) on every column, θ (n,) the shaft angle (rad): a line at
    order × the rotational frequency, moving with the speed."""
    x = np.asarray(x, float)
    line = amplitude * np.sin(order * np.asarray(angle_rad, float))
    return x + (line[:, None] if x.ndim == 2 else line)


def bias_drift(x: np.ndarray, hours: float, rate_per_kh: float) -> np.ndarray:
    """x plus rate · hours/1000: an offset grown linearly since 0 operating hours."""
    return np.asarray(x, float) + rate_per_kh * hours / 1000.0


def delay(x: np.ndarray, samples: int, edge: str = "hold") -> np.ndarray:
    """x shifted later by ``samples`` (earlier when negative): y[i] = x[i − samples]. Where the
    shift leaves no sample, ``edge`` "hold" holds the first (last) value; "mirror" continues the
    signal mirrored about its first (last) sample, as a recording made with a clock offset shows
    the motion just before (after) its window rather than one value held (which ``twin check``
    calls a dropout)."""
    if edge not in ("hold", "mirror"):
        raise ValueError(f"delay: edge {edge!r}; expected 'hold' or 'mirror'")
    x = np.asarray(x, float)
    n = int(samples)
    if n == 0 or x.shape[0] == 0:
        return x.copy()
    y = np.empty_like(x)
    if abs(n) >= x.shape[0]:
        y[:] = x[0] if n > 0 else x[-1]
    elif n > 0:
        y[n:] = x[:-n]
        y[:n] = x[n:0:-1] if edge == "mirror" else x[0]
    else:
        y[:n] = x[-n:]
        y[n:] = x[-2:n - 2:-1] if edge == "mirror" else x[-1]
    return y


def clip(x: np.ndarray, limit: float) -> np.ndarray:
    """x clipped at ± ``limit`` (a converter's range); 0 leaves it unchanged."""
    x = np.asarray(x, float)
    return np.clip(x, -limit, limit) if limit > 0 else x.copy()


def spikes(x: np.ndarray, fs_hz: float, rate_hz: float, amplitude: float,
           rng: np.random.Generator) -> np.ndarray:
    """x plus one-sample impulses of ± ``amplitude`` at random instants, ``rate_hz`` per second
    on average (Poisson), each column its own sign: an intermittent contact, an electrostatic
    discharge."""
    x = np.asarray(x, float).copy()
    k = int(rng.poisson(rate_hz * x.shape[0] / fs_hz))
    at = rng.integers(0, x.shape[0], k)
    np.add.at(x, at, amplitude * rng.choice([-1.0, 1.0], size=(k, *x.shape[1:])))
    return x


def dropouts(x: np.ndarray, fs_hz: float, rate_hz: float, length_ms: float,
             rng: np.random.Generator) -> np.ndarray:
    """x with gaps where the acquisition lost samples and held the last good value: ``rate_hz``
    gaps per second on average (Poisson), each ``length_ms`` long."""
    x = np.asarray(x, float).copy()
    n, m = x.shape[0], max(1, int(round(length_ms * 1e-3 * fs_hz)))
    for start in np.sort(rng.integers(1, max(n - 1, 2), int(rng.poisson(rate_hz * n / fs_hz)))):
        x[start:start + m] = x[start - 1]
    return x


def lowpass(x: np.ndarray, fs_hz: float, cutoff_hz: float) -> np.ndarray:
    """x through a causal 4th-order Butterworth low-pass at ``cutoff_hz`` (scipy.signal.butter,
    sosfilt along the samples): an anti-alias filter set too low, a long cable's capacitance."""
    from scipy import signal

    sos = signal.butter(4, min(cutoff_hz, 0.45 * fs_hz), fs=fs_hz, output="sos")
    return signal.sosfilt(sos, np.asarray(x, float), axis=0)


# ---------------------------------------------------------------------------------------------
# Candidates


@dataclass(frozen=True)
class Target:
    """The channels an artefact acts on: name, ((domain, dataset), ...) with domain "phase1" |
    "phase2" and dataset a channel of the format (``acc1``, ``imu_acc``, ...), and the words
    ("acc1 and acc2")."""

    name: str
    channels: tuple[tuple[str, str], ...]
    words: str

    @property
    def domains(self) -> tuple[str, ...]:
        return tuple(sorted({d for d, _ in self.channels}))


TARGETS = {t.name: t for t in (
    Target("speed", (("phase1", "speed"),), "the Phase I motor speed"),
    Target("torque", (("phase1", "torque"),), "the Phase I motor torque"),
    Target("acc1", (("phase1", "acc1"),), "acc1"),
    Target("acc2", (("phase1", "acc2"),), "acc2"),
    Target("acc", (("phase1", "acc1"), ("phase1", "acc2")), "acc1 and acc2"),
    Target("imu_acc", (("phase2", "imu_acc"),), "the IMU accelerometer"),
    Target("imu_gyro", (("phase2", "imu_gyro"),), "the IMU gyroscope"),
    Target("imu", (("phase2", "imu_acc"), ("phase2", "imu_gyro")), "the IMU (accelerometer and gyroscope)"),
)}

#: The transform of one dataset: (x (n,) or (n, c), context) -> same shape; context: fs_hz,
#: hours, angle (the capture's shaft angle, Phase I only), rng, and the parameter values.
Transform = Callable[[np.ndarray, dict], np.ndarray]


@dataclass(frozen=True)
class Artefact:
    """One candidate: an artefact on one target. ``phrase`` says it in the owner's words, with
    ``{param}`` placeholders the report fills with the fitted values ("a {frequency_hz} line of
    {amplitude} on acc1 and acc2 at every speed: electrical pickup"); ``amplitude``: the
    parameter whose off value removes it whatever the others are."""

    artefact: str
    target: Target
    title: str
    params: tuple[CandidateParam, ...]
    transform: Transform
    phrase: str
    source: str
    amplitude: str | None = None
    seed_dependent: bool = False

    @property
    def name(self) -> str:
        return f"{self.artefact}:{self.target.name}"

    def is_off(self, values: dict[str, float]) -> bool:
        if self.amplitude is not None:
            p = next(p for p in self.params if p.name == self.amplitude)
            return values[p.name] == p.off
        return all(p.off is not None and values[p.name] == p.off for p in self.params)

    def draw(self, rng: np.random.Generator, magnitude: str) -> dict[str, float]:
        """Values inside the prior range ("low": lower half of each continuous range, "high":
        upper half; log halves for log parameters; discrete ones among the grid's present
        values)."""
        out = {}
        for p in self.params:
            if p.discrete:
                out[p.name] = float(rng.choice([v for v in p.grid if v != p.off]))
                continue
            lo, hi = (np.log(p.low), np.log(p.high)) if p.log else (p.low, p.high)
            mid = 0.5 * (lo + hi)
            v = float(rng.uniform(*((lo, mid) if magnitude == "low" else (mid, hi))))
            v = float(np.exp(v)) if p.log else v
            if p.signed:
                v *= float(rng.choice([-1.0, 1.0]))
            out[p.name] = v
        return out


def _amp(name: str, unit: str, grid: tuple[float, ...], low: float, high: float,
         label: str, digits: int = 2) -> CandidateParam:
    return CandidateParam(name, low=low, high=high, grid=grid, log=True, label=label, unit=unit, digits=digits)


def _line_position(name: str, grid: tuple[float, ...], label: str, unit: str,
                   digits: int) -> CandidateParam:
    """Where a line stands (its frequency, its order): one of ``grid``, which lists every
    value it can take (closed, discrete), and never off (the amplitude removes the line)."""
    return CandidateParam(name, low=grid[0], high=grid[-1], grid=grid, off=None, discrete=True, closed=True,
                          label=label, unit=unit, digits=digits)


_GAIN = CandidateParam("error_pct", low=4.0, high=20.0, grid=(-20.0, -8.0, 0.0, 8.0, 20.0), signed=True,
                       label="sensitivity error", unit="%", digits=2)
_NOISE_GRID = {  # RMS of the added noise, channel units: about 2, 5, 10, 25× the twin's floor
    "torque": ("N·m", (0.0, 0.01, 0.02, 0.05, 0.1)),
    "acc1": ("m/s²", (0.0, 0.005, 0.01, 0.02, 0.05)),
    "acc2": ("m/s²", (0.0, 0.005, 0.01, 0.02, 0.05)),
    "imu_acc": ("m/s²", (0.0, 0.001, 0.002, 0.005, 0.01)),
    "imu_gyro": ("rad/s", (0.0, 0.0005, 0.001, 0.002, 0.005)),
}
_LINE_AMPS = (0.0, 0.005, 0.01, 0.02, 0.04, 0.08)
_LINE_UNITS = {"acc": "m/s²", "torque": "N·m"}
_MAINS_HZ = (50.0, 60.0, 100.0, 120.0, 150.0, 180.0)
_ORDERS = (1.0, 2.0, 3.0, 5.0)  # not the cogging orders of the physical library
_DRIFT = {  # bias drift per 1000 h, channel units
    "torque": ("N·m per 1000 h", (-0.2, -0.1, 0.0, 0.1, 0.2), 0.05, 0.2),
    "imu_acc": ("m/s² per 1000 h", (-0.2, -0.1, 0.0, 0.1, 0.2), 0.05, 0.2),
    "imu_gyro": ("rad/s per 1000 h", (-0.004, -0.002, 0.0, 0.002, 0.004), 0.001, 0.004),
}
_CLIP = {  # converter ranges tried (0: none), channel units
    "torque": ("N·m", (0.0, 1.6, 2.0, 2.3)),
    "acc1": ("m/s²", (0.0, 2.0, 3.0, 4.0, 5.0)),
    "acc2": ("m/s²", (0.0, 2.0, 3.0, 4.0, 5.0)),
    "imu_acc": ("m/s²", (0.0, 15.0, 20.0, 25.0, 30.0)),
}


def _candidates() -> list[Artefact]:
    out: list[Artefact] = []
    for t in ("speed", "torque", "acc1", "acc2", "imu_acc", "imu_gyro"):
        out.append(Artefact("gain", TARGETS[t], f"sensitivity error of {TARGETS[t].words}", (_GAIN,),
                            lambda x, c: gain(x, c["error_pct"]),
                            f"a sensitivity error of {{error_pct}} on {TARGETS[t].words}: "
                            "a calibration or a scale factor to check",
                            "sensor sensitivity (ISO 16063-21 calibration)", amplitude="error_pct"))
    for t, (unit, grid) in _NOISE_GRID.items():
        out.append(Artefact("noise", TARGETS[t], f"added white noise on {TARGETS[t].words}",
                            (_amp("rms", unit, grid, grid[2], grid[-1], "noise RMS"),),
                            lambda x, c: white_noise(x, c["rms"], c["rng"]),
                            f"white noise of {{rms}} RMS on {TARGETS[t].words}: a noisier channel "
                            "(cable, connector, amplifier)",
                            "acquisition noise floor", amplitude="rms"))
    for t, unit in _LINE_UNITS.items():
        amp = _amp("amplitude", unit, tuple(_LINE_AMPS), 0.01, 0.08, "line amplitude (peak)")
        out.append(Artefact(
            "mains_line", TARGETS[t], f"fixed-frequency line on {TARGETS[t].words}",
            (amp, _line_position("frequency_hz", _MAINS_HZ, "line frequency", "Hz", digits=3)),
            lambda x, c: fixed_line(x, c["fs_hz"], c["amplitude"], c["frequency_hz"],
                                    float(c["rng"].uniform(0.0, 2.0 * np.pi))),
            f"a {{frequency_hz}} line of {{amplitude}} on {TARGETS[t].words} at every speed: "
            "electrical pickup", "mains pickup on signal lines (IEC 61000-4-16)", amplitude="amplitude"))
        out.append(Artefact(
            "order_line", TARGETS[t], f"speed-locked line on {TARGETS[t].words}",
            (amp, _line_position("order", _ORDERS, "line order", "per revolution", digits=2)),
            lambda x, c: order_line(x, c["angle"], c["amplitude"], c["order"]),
            f"a line of {{amplitude}} at {{order}} of the motor on {TARGETS[t].words}, "
            "following the speed: a mechanical source (unbalance, misalignment)",
            "order-locked vibration (Randall 2011, ch. 3)", amplitude="amplitude",
            seed_dependent=True))
    for t, (unit, grid, lo, hi) in _DRIFT.items():
        out.append(Artefact(
            "bias_drift", TARGETS[t], f"bias drifting with the hours on {TARGETS[t].words}",
            (CandidateParam("rate_per_kh", low=lo, high=hi, grid=grid, signed=True, label="bias drift",
                            unit=unit, digits=2),),
            lambda x, c: bias_drift(x, c["hours"], c["rate_per_kh"]),
            f"a bias on {TARGETS[t].words} drifting by {{rate_per_kh}} of operation: "
            "a sensor offset to re-zero", "sensor bias drift (IEEE Std 1554)", amplitude="rate_per_kh"))
    for t in ("acc", "imu"):
        other = "speed and torque" if t == "acc" else "the position command"
        out.append(Artefact(
            "time_offset", TARGETS[t], f"time offset of {TARGETS[t].words} against {other}",
            (CandidateParam("offset_ms", low=2.0, high=10.0, grid=(-10.0, -5.0, -2.0, 0.0, 2.0, 5.0, 10.0),
                            signed=True, label="time offset (late when positive)", unit="ms",
                            digits=2),),
            lambda x, c: delay(x, int(round(c["offset_ms"] * 1e-3 * c["fs_hz"])), c.get("edge", "hold")),
            f"{TARGETS[t].words} recorded {{offset_ms}} late against {other}: a clock offset "
            "between the acquisition's channels", "acquisition clock offset", amplitude="offset_ms"))
    for t, (unit, grid) in _CLIP.items():
        out.append(Artefact(
            "clipping", TARGETS[t], f"clipping of {TARGETS[t].words}",
            (CandidateParam("range", low=grid[1], high=grid[-1], grid=grid, discrete=True,
                            label="converter range (±)", unit=unit, digits=2),),
            lambda x, c: clip(x, c["range"]),
            f"{TARGETS[t].words} clipped at ±{{range}}: a converter range too small",
            "converter saturation", amplitude="range"))
    return out


#: Every artefact candidate by name (``artefact:target``).
ARTEFACTS: dict[str, Artefact] = {a.name: a for a in _candidates()}


def _edits() -> list[Artefact]:
    out: list[Artefact] = []
    spike_amp = {"acc": ("m/s²", 2.0, 10.0), "torque": ("N·m", 0.2, 1.0)}
    for t, (unit, lo, hi) in spike_amp.items():
        out.append(Artefact(
            "spikes", TARGETS[t], f"impulses on {TARGETS[t].words}",
            (CandidateParam("rate_hz", low=2.0, high=20.0, grid=(2.0, 20.0), log=True, label="impulse rate",
                            unit="per s", digits=2),
             _amp("amplitude", unit, (lo, hi), lo, hi, "impulse amplitude")),
            lambda x, c: spikes(x, c["fs_hz"], c["rate_hz"], c["amplitude"], c["rng"]),
            f"impulses of {{amplitude}} on {TARGETS[t].words}", "intermittent contact"))
    for t in ("acc", "torque", "imu_acc"):
        out.append(Artefact(
            "dropouts", TARGETS[t], f"lost samples held on {TARGETS[t].words}",
            (CandidateParam("rate_hz", low=0.5, high=4.0, grid=(0.5, 4.0), log=True, label="gap rate",
                            unit="per s", digits=2),
             CandidateParam("length_ms", low=5.0, high=50.0, grid=(5.0, 50.0), log=True, label="gap length",
                            unit="ms", digits=2)),
            lambda x, c: dropouts(x, c["fs_hz"], c["rate_hz"], c["length_ms"], c["rng"]),
            f"gaps of {{length_ms}} on {TARGETS[t].words}", "acquisition buffer overrun"))
    for t, (lo, hi) in {"acc": (200.0, 800.0), "imu_acc": (20.0, 80.0)}.items():
        out.append(Artefact(
            "lowpass", TARGETS[t], f"low-pass filter on {TARGETS[t].words}",
            (CandidateParam("cutoff_hz", low=lo, high=hi, grid=(lo, hi), log=True, label="cut-off",
                            unit="Hz", digits=3),),
            lambda x, c: lowpass(x, c["fs_hz"], c["cutoff_hz"]),
            f"{TARGETS[t].words} low-passed at {{cutoff_hz}}", "anti-alias filter set too low"))
    return out


#: Edits of a recording that no candidate models (impulses, lost samples, a low-pass filter),
#: by name (``edit:target``): the blind benchmark's out-of-everything recordings. Never a
#: candidate of the diagnosis; :func:`apply` applies them as it applies the artefacts.
EDITS: dict[str, Artefact] = {a.name: a for a in _edits()}


def rng_for(seed: int, name: str) -> np.random.Generator:
    """The generator of an artefact's random draws: the scenario's seed and the candidate's
    name (the same draws for the same seed and candidate, whatever else is applied)."""
    return np.random.default_rng([int(seed) % 2**32, zlib.crc32(name.encode())])


def lookup(name: str) -> Artefact:
    """The artefact candidate or the recording edit (:data:`EDITS`) called ``name``."""
    if name in ARTEFACTS:
        return ARTEFACTS[name]
    if name in EDITS:
        return EDITS[name]
    raise ArtefactError(f"unknown signal artefact {name!r}; the candidates are {', '.join(ARTEFACTS)}")


def _check(name: str, values: dict[str, float]) -> Artefact:
    a = lookup(name)
    want = {p.name for p in a.params}
    if set(values) != want:
        raise ArtefactError(f"artefact {name}: parameters {sorted(values)}; expected {sorted(want)}")
    return a


def apply(src: Path, dst: Path, artefacts: dict[str, dict[str, float]], seed: int, edge: str = "hold") -> Path:
    """Copy the recording ``src`` (a ``measurements.h5``) to ``dst`` with the artefacts
    {candidate name: {param: value}} applied in the given order to their targets' channels
    (float32 stored as float32); random draws from ``seed`` (:func:`rng_for`); ``edge``: how a
    time offset fills the samples its shift leaves (:func:`delay`: "hold", as the candidates'
    responses, or "mirror", as a machine's recording). Returns ``dst``."""
    src, dst = Path(src), Path(dst)
    checked = [(_check(n, v), v) for n, v in artefacts.items()]
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src, dst)
    with h5py.File(dst, "r+") as f:
        for art, values in checked:
            if art.is_off(values):
                continue
            rng = rng_for(seed, art.name)
            for domain, channel in art.target.channels:
                groups = _groups(f, domain)
                if not groups:
                    continue
                for g in groups:
                    if channel not in g:
                        raise ArtefactError(f"{src}: /{g.name.strip('/')}/{channel} is missing; "
                                            f"artefact {art.name} acts on it")
                    ds = g[channel]
                    fs = float(ds.attrs.get("fs_hz", g.attrs.get("fs_hz", np.nan)))
                    ctx = {**values, "fs_hz": fs, "rng": rng, "edge": edge,
                           "hours": float(g.attrs.get("hours", g.parent.attrs.get("hours", 0.0)))}
                    if domain == "phase1":
                        ctx["angle"] = shaft_angle(g["speed"][...], fs)
                    elif art.artefact == "order_line":
                        raise ArtefactError(f"artefact {art.name}: an order-locked line needs the "
                                            "Phase I motor speed")
                    ds[...] = art.transform(ds[...].astype(float), ctx).astype(ds.dtype)
    return dst


def changes(src: Path, dst: Path, name: str) -> bool:
    """Whether the recording ``dst`` differs from ``src`` on any channel of the target of the
    artefact ``name`` (an artefact that acts: a converter range above every peak clips nothing)."""
    art = lookup(name)
    with h5py.File(src, "r") as a, h5py.File(dst, "r") as b:
        for domain, channel in art.target.channels:
            for g in _groups(a, domain):
                if channel in g and not np.array_equal(g[channel][...], b[g.name][channel][...]):
                    return True
    return False


def _groups(f: h5py.File, domain: str) -> list[h5py.Group]:
    """Phase I captures or Phase II runs, in name order."""
    if domain not in f:
        return []
    if domain == "phase1":
        return [f["phase1"][n] for n in sorted(f["phase1"])]
    return [f["phase2"][s][r] for s in sorted(f["phase2"]) for r in sorted(f["phase2"][s])]


def library_entry(a: Artefact) -> dict:
    """The artefact's entry of ``diagnosis.json``'s ``library``: kind, title, source, phrase and
    per parameter its prior range and display."""
    return {"kind": KIND_ARTEFACT, "title": a.title, "source": a.source, "phrase": a.phrase,
            "params": {p.name: {"low": p.low, "high": p.high, **p.display()} for p in a.params}}

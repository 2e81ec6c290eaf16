"""The calibration's uncertainty, carried into the twin: the joint distribution of the calibrated
values in log space, and a draw of them for each of the twin's seeds.

``twin calibrate`` writes ``covariance`` into the scenario's ``[calibration]`` table: ``keys``
(scenario keys) and ``log`` (the covariance of their natural logarithms): the fitted parameters'
delta-method covariance (scaled so a Gaussian's 90 % range is the stated interval), the
parameters kept at the twin's default with their prior span and the fitted ones' dependence on
them (:mod:`twin.harness.calibration.physical`), and the sensor chain's measured values,
independent of the rest, from their intervals. ``twin diagnose`` simulates each twin seed with
the calibrated values drawn from that distribution (:func:`draw_calibrated`): the seed-to-seed
spread the gap is judged against then holds the calibration's uncertainty beside the machine's
random geometry, and a statistic that a calibrated value moves within its interval is not
called a gap (a multivariate normal in log space: the values stay positive; J. E. Gentle,
"Random Number Generation and Monte Carlo Methods", 2003, the Cholesky method).
"""

from __future__ import annotations

import math

import numpy as np

from twin.harness.calibration.values import Z90, Value
from twin.sim.config import get_dotted, set_dotted

#: Stream of the draws, beside the twin seed's own streams.
DRAW_STREAM = 0xCA1B


def joint_covariance(fitted: dict | None, sensors: list[Value], excluded: set[str]) -> dict | None:
    """The ``covariance`` entry of the calibration record: the fitted and kept parameters'
    (``fitted``: {keys, log}) without the ``excluded`` keys (a channel ``twin check`` flags),
    and each measured sensor value with an interval as independent, its log standard deviation
    log(high/low)/(2·Z90). None when there is nothing with an uncertainty."""
    keys: list[str] = []
    blocks: list[np.ndarray] = []
    if fitted:
        keep = [i for i, k in enumerate(fitted["keys"]) if k not in excluded]
        keys += [fitted["keys"][i] for i in keep]
        blocks.append(np.asarray(fitted["log"], float)[np.ix_(keep, keep)])
    sens = [v for v in sensors if v.low and v.high and v.high > v.low and v.key not in excluded]
    keys += [v.key for v in sens]
    if sens:
        blocks.append(np.diag([(math.log(v.high / v.low) / (2 * Z90)) ** 2 for v in sens]))
    if not keys:
        return None
    n = len(keys)
    cov = np.zeros((n, n))
    at = 0
    for b in blocks:
        cov[at:at + len(b), at:at + len(b)] = b
        at += len(b)
    return {"keys": keys, "log": cov.tolist()}


#: Largest factor either side of its value (at 90 %) a calibrated value may be drawn from: the
#: layer (c) fit searches within a factor 10 of its start, and a draw beyond it (a velocity loop
#: many times the servo's rate) can make the twin's servo unstable.
MAX_DRAW_FACTOR = 10.0


def check_drawable(calibration: dict | None, where: str) -> None:
    """Raise ValueError naming ``where`` (the scenario), the key and its factor when
    ``calibration``'s covariance would draw a value from more than :data:`MAX_DRAW_FACTOR`
    either side of it at 90 % (a calibration written before such values were kept at their
    default); nothing is drawn from a scenario without a covariance."""
    cov = (calibration or {}).get("covariance")
    if not cov:
        return
    half = Z90 * np.sqrt(np.clip(np.diag(np.asarray(cov["log"], float)), 0.0, None))  # 90 % half-range, log
    wide = [(k, float(np.exp(min(h, 700.0)))) for k, h in zip(cov["keys"], half, strict=True)
            if not h <= math.log(MAX_DRAW_FACTOR)]
    if wide:
        named = ", ".join(f"{k} a factor {f:.3g}" for k, f in wide)
        raise ValueError(
            f"{where}: the [calibration] covariance would draw {named} either side of the calibrated value "
            f"(90 % range; expected at most {MAX_DRAW_FACTOR:g}): a twin drawn that far from the machine can run "
            "away; calibrate the recording again (`twin calibrate` keeps a value it cannot tell apart at the "
            "twin's default) or remove the covariance entry")


#: Draws of one seed before :func:`draw_calibrated` gives up on a twin its integrator can carry.
MAX_DRAWS = 100


def suspension_step_product(data: dict) -> float:
    """ω·Δt of the carriage's stiffest suspension mode in scenario ``data`` (a scenario's JSON
    dict): ω its carriage's :attr:`twin.sim.axis.Carriage.suspension_omega`, Δt the larger of the
    Phase I and Phase II simulation steps. MuJoCo's implicitfast integrator takes the springs
    explicitly, and the semi-implicit (symplectic) Euler step is stable for an undamped oscillator
    only while ω·Δt < 2 (E. Hairer, C. Lubich, G. Wanner, "Geometric Numerical Integration", 2nd
    ed., 2006, ch. I.5): beyond it the simulation diverges in a few steps."""
    from twin.sim.scenario import from_dict, to_axis

    s = from_dict(data)
    return to_axis(s).carriage.suspension_omega * max(s.phase1.timestep_s, s.phase2.timestep_s)


def draw_calibrated(data: dict, calibration: dict | None, seed: int) -> dict:
    """Scenario ``data`` (a scenario's JSON dict, changed in place and returned) with every key
    of ``calibration``'s ``covariance`` (the scenario's ``[calibration]`` table) drawn from the
    joint log-normal centred on the scenario's value, from the stream [``seed``,
    :data:`DRAW_STREAM`]; unchanged without a covariance. A draw whose carriage the integrator
    cannot carry (:func:`suspension_step_product` ≥ 2: a light carriage drawn on stiff trucks)
    is drawn again, from the streams [``seed``, :data:`DRAW_STREAM`, 1], [..., 2], ...: the
    distribution is truncated to the twins that can be simulated. Raises ValueError, naming the
    keys, when none of :data:`MAX_DRAWS` draws is."""
    cov = (calibration or {}).get("covariance")
    if not cov:
        return data
    keys = list(cov["keys"])
    c = np.asarray(cov["log"], float)
    # a covariance that rounding left slightly indefinite: its eigenvalues clipped at 0
    w, v = np.linalg.eigh((c + c.T) / 2)
    root = v * np.sqrt(np.clip(w, 0.0, None))
    centre = {key: float(get_dotted(data, key)) for key in keys}
    for attempt in range(MAX_DRAWS):
        stream = [int(seed) % 2**32, DRAW_STREAM] + ([attempt] if attempt else [])
        z = root @ np.random.default_rng(stream).standard_normal(len(keys))
        for key, dz in zip(keys, z, strict=True):
            set_dotted(data, key, centre[key] * math.exp(float(dz)), source="calibration draw")
        if suspension_step_product(data) < 2.0:
            return data
    raise ValueError(f"seed {seed}: none of {MAX_DRAWS} draws of the calibrated values ({', '.join(keys)}) "
                     "gives a carriage the simulation can carry (the suspension's omega * timestep below 2); "
                     "the [calibration] covariance spans too far: calibrate again")


__all__ = ["DRAW_STREAM", "MAX_DRAWS", "MAX_DRAW_FACTOR", "check_drawable", "draw_calibrated", "joint_covariance",
           "suspension_step_product"]

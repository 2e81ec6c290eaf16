"""The timing statistic of the gap diagnosis (analysis/diagnosis/timing.py): how late the nut
accelerometers are against the motor speed, on synthetic moves and on a twin recording with a
clock offset written into it."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.diagnosis import artefacts
from analysis.diagnosis.signature import TIMING_BIN, TIMING_CHANNELS, signature
from analysis.diagnosis.timing import acceleration_lag_ms, lag_s
from twin.sim.drive import command_profile, reciprocating

FS = 10_000.0
LEAD_M = 0.016


def _moves(fs: float = FS, seconds: float = 2.0) -> np.ndarray:
    """A motor speed (rad/s) of back-and-forth trapezoidal moves from rest to rest, as a
    capture records them (the twin's command, :func:`twin.sim.drive.command_profile`, through a
    16-mm lead): 30-ms ramps to ±150 rad/s, 0.4-s cruises, 0.2-s rests, the first move 0.1 s
    after the start."""
    speed = 150.0 * LEAD_M / (2 * np.pi)  # m/s
    stroke = speed * (0.4 + 0.03)
    moves = reciprocating(0.0, stroke, speed, speed / 0.03, 0.2, 2)
    return command_profile(moves, fs, lead_in=0.1, duration=seconds).v * 2 * np.pi / LEAD_M


@pytest.mark.parametrize("offset_ms", [-10.0, -2.0, 0.0, 0.35, 5.0])
def test_the_lag_of_an_accelerometer_is_its_clock_offset(offset_ms):
    """The axial acceleration (the speed's derivative times a lead, plus a noise of 0.05 m/s²,
    as the nut accelerometers read it) shifted by ``offset_ms`` with the benchmark's mirrored
    edge: the lag recovers the shift within 0.05 ms (half a sample; the Welch segments see a
    little less of the shifted motion at their ends), whole or fractional samples (0.35 ms is
    3.5 samples, rounded to 4 by the artefact's transform: 0.4 ms)."""
    speed = _moves()
    acc = np.gradient(speed) * FS * LEAD_M / (2 * np.pi)
    acc = acc + np.random.default_rng(3).normal(0.0, 0.05, acc.size)
    shift = int(round(offset_ms * 1e-3 * FS))
    late = artefacts.delay(acc, shift, "mirror")
    assert acceleration_lag_ms(speed, late, FS) == pytest.approx(shift / FS * 1e3, abs=0.05)
    # an accelerometer mounted the other way round: the same delay
    assert acceleration_lag_ms(speed, -late, FS) == pytest.approx(shift / FS * 1e3, abs=0.05)


def test_no_motion_no_common_motion_or_too_short_is_nan():
    noise = np.random.default_rng(0).normal(size=int(FS))
    assert np.isnan(acceleration_lag_ms(np.zeros(noise.size), noise, FS))  # a capture at rest
    speed = _moves()
    unrelated = np.random.default_rng(1).normal(size=speed.size)
    assert np.isnan(acceleration_lag_ms(speed, unrelated, FS))  # coherence below TIMING_MIN_COHERENCE
    acc = np.gradient(speed) * FS
    assert np.isnan(lag_s(acc[:100], acc[:100], FS))  # 10 ms: no bin of 2-40 Hz


def test_a_clock_offset_on_the_nut_accelerometers_moves_their_timing_by_the_offset(small_campaign, tmp_path):
    """A twin recording (scenarios/quick.toml) with the accelerometers 6 ms late (the artefact
    ``time_offset:acc``): each sample's timing statistic of both accelerometers moves by 6 ms
    within 0.15 ms (the delay of the cross-spectrum of Welch segments: a little of the shifted
    motion falls outside each segment)."""
    src = small_campaign / "measurements.h5"
    late = artefacts.apply(src, tmp_path / "late.h5", {"time_offset:acc": {"offset_ms": 6.0}}, 0, edge="mirror")
    for part in ("cal", "heldout"):
        a, b = signature(src, part, ("phase1",)), signature(late, part, ("phase1",))
        timing = [i for i, r in enumerate(a.regions) if r.family == "timing"]
        assert {a.regions[i].channel for i in timing} == set(TIMING_CHANNELS)
        assert {a.regions[i].bin for i in timing} == {TIMING_BIN}
        assert np.all(np.isfinite(a.values[timing])), a.values[timing]
        np.testing.assert_allclose(b.values[timing] - a.values[timing], 6.0, atol=0.15)

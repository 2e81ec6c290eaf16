"""The strokes of a Phase II run from the IMU alone (issue 13, step 1 of the IMU-based position):
the acceleration pulses of the carriage found and timed from the accelerometer's x axis."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import REPO

from analysis.phase2.strokes import StrokeError, centroid_delay, find_pulses, half_velocity_delay
from twin.sim import campaign as cp
from twin.sim.scenario import load
from twin.sim.simulate import Simulator, phase2_command, phase2_measure

SPEEDS = (0.02, 0.1, 0.5)  # m/s: the paper's three speeds


@pytest.fixture(scope="module")
def runs():
    """One run of the paper's routine (20, 100, 500 mm/s at 19.6 m/s², 450 mm) simulated with no
    backlash and with 20 µm, and its IMU recording (the paper's accelerometer, 1613 Hz)."""
    s = load(REPO / "scenarios/backlash-steps.toml", ["phase2.speeds_mm_s=[20.0, 100.0, 500.0]"])
    world = cp.make_world(s)
    sim = Simulator(world, s.phase2.timestep_s)
    base = cp.condition_at(s, 0.0)
    cmd = phase2_command(sim, s.phase2)
    out = []
    for b in (0.0, 20e-6):
        cond = dataclasses.replace(base, mech=dataclasses.replace(base.mech, backlash=b))
        traj = sim.run(cond, cmd, passes=2)
        meas = phase2_measure(sim, traj, np.random.default_rng(1))
        out.append((b, sim.fs, traj.sens[:, traj.index.imu_acc][:, 0], meas))
    return s.phase2.accel_mm_s2 * 1e-3, s.phase2.dwell_s, out


@pytest.mark.quoted
def test_pulses_are_timed_within_a_tenth_of_a_sample(runs, quote):
    """Every pulse found in the IMU's samples starts within 0.1 IMU sample (62 µs) of the same
    pulse in the carriage's true specific force at the simulation rate, at all three speeds
    (the 1-ms pulses of 20 mm/s included), with and without backlash; its velocity change is
    the speed within 30 % (the carriage's axial mode rings through the window)."""
    accel, dwell, out = runs
    worst, worst_fast = 0.0, 0.0
    for b, fs_sim, true_fx, meas in out:
        truth = find_pulses(true_fx, fs_sim, 0.0, SPEEDS, accel, 0.45, dwell)
        fs = meas["imu_acc_fs_hz"]
        found = []
        for v in SPEEDS:
            delay = half_velocity_delay(v / accel, 300.0)
            found += [p for p in find_pulses(meas["imu_acc"][:, 0], fs, delay, SPEEDS, accel, 0.45, dwell)
                      if p.speed_m_s == v]
        found.sort(key=lambda p: p.start_s)
        assert [p.sign for p in found] == [1, -1, -1, 1] * 3
        err = np.array([p.start_s - q.start_s for p, q in zip(found, truth, strict=True)])
        ratio = np.array([p.area_m_s / (p.sign * p.speed_m_s) for p in found])
        print(f"\n[strokes] b = {b * 1e6:g} µm: IMU − true start, µs: {np.round(err * 1e6, 1).tolist()}; "
              f"velocity change / speed {np.round(ratio, 3).tolist()}")
        assert np.max(np.abs(err)) < 0.1 / fs
        assert np.all((ratio > 0.7) & (ratio < 1.3))
        fast = np.array([p.speed_m_s >= 0.1 for p in found])
        worst, worst_fast = max(worst, np.max(np.abs(err))), max(worst_fast, np.max(np.abs(err[fast])))
    quote("pulse_timing_ms", worst * 1e3, f"{worst * 1e3:.2f} ms ({worst * fs:.2f} IMU sample)")
    quote("pulse_timing_fast_ms", worst_fast * 1e3, f"{worst_fast * 1e3:.2f} ms")


def test_half_velocity_delay_tends_to_the_group_delay():
    """For pulses much longer than the filter's response the delay is the DC group delay of a
    second-order Butterworth, √2/(2π·f_c), within 0.1 %; a 1-ms pulse is shown 4 % later."""
    dc = math.sqrt(2.0) / (2.0 * math.pi * 300.0)
    assert half_velocity_delay(0.05, 300.0) == pytest.approx(dc, rel=1e-3)
    assert half_velocity_delay(0.001, 300.0) == pytest.approx(1.04 * dc, rel=0.01)


def test_a_run_cut_before_its_last_pulse_names_the_channel_and_the_time(runs):
    accel, dwell, out = runs
    _, _, _, meas = out[0]
    acc = meas["imu_acc"][:, 0]
    fs = meas["imu_acc_fs_hz"]
    with pytest.raises(StrokeError, match=r"^imu_acc: pulse 1[12] of 12 \([+−]19\.6 m/s² at 500 mm/s\) "
                                          r"(expected at|not found in) [0-9.]+–[0-9.]+ s"):
        find_pulses(acc[: acc.size - int(1.5 * fs)], fs, 0.00075, SPEEDS, accel, 0.45, dwell)
    with pytest.raises(StrokeError, match=r"pulse 1 of 12 .* not found in 0\.000–[0-9.]+ s: the largest "
                                          r"velocity change there is"):
        find_pulses(np.zeros(5000), fs, 0.00075, SPEEDS, accel, 0.45, dwell)


def slow_routine(b: float, fs_sim: float = 16130.0, ripple: float = 2e-3):
    """The accelerometer's x axis (1613 Hz, 300 Hz 2nd-order Butterworth) for a forward and a
    reverse move of 450 mm at 20 mm/s with 50 mm/s² ramps and a 1 s dwell, where the carriage first
    crosses a clearance ``b`` at each start (it rests until the screw has moved b, then takes up
    the screw's speed within 5 ms, a Hann pulse centred on the contact, about the axial mode's
    half period: the same travel as a jump) and stops with the screw; plus a 16 Hz vibration of
    ``ripple`` m/s² while moving (the torque ripple of 8 per revolution at 20 mm/s)."""
    from scipy import signal

    a, v, L, dwell = 0.05, 0.02, 0.45, 1.0
    T = v / a
    cruise = (L - v * T) / v
    t = np.arange(int(50.0 * fs_sim)) / fs_sim
    acc = np.zeros_like(t)
    t_s = 0.5
    for sign in (1, -1):
        t_c = t_s + math.sqrt(2.0 * b / a)  # the screw has crossed the clearance
        ramp = (t >= t_c) & (t < t_s + T)
        acc[ramp] = sign * a
        catch = np.abs(t - t_c) < 2.5e-3  # taking up the screw's speed
        acc[catch] += sign * a * (t_c - t_s) / 2.5e-3 * np.cos(math.pi * (t[catch] - t_c) / 5e-3) ** 2
        t_d = t_s + T + cruise
        acc[(t >= t_d) & (t < t_d + T)] = -sign * a
        moving = (t >= t_s) & (t < t_d + T)
        acc[moving] += ripple * np.sin(2 * math.pi * 16.0 * t[moving] + 0.3)
        t_s = t_d + T + dwell
    b_f, a_f = signal.butter(2, 300.0, fs=fs_sim)
    return signal.lfilter(b_f, a_f, acc)[::10], fs_sim / 10, (v,), a, L, dwell


def test_slow_ramps_are_timed_by_the_travel_the_carriage_makes():
    """On a 50 mm/s² ramp the carriage that first crosses a clearance b starts its cruise b/v
    later on the IMU axis (so that a travel D = L − b stretches the axis by L/(L − b), the paper's
    Eq. 9): with the travel timing within 10 µs (0.5 µm at 20 mm/s) for 5 and 20 µm, with the
    half-velocity instant by less than half of it; the cruise's end does not move."""
    found = {}
    for b in (0.0, 5e-6, 20e-6):
        acc, fs, speeds, a, L, dwell = slow_routine(b)
        for timing, delay in (("travel", centroid_delay(300.0)),
                              ("half_velocity", half_velocity_delay(speeds[0] / a, 300.0))):
            p = find_pulses(acc, fs, delay, speeds, a, L, dwell, timing=timing, bandwidth_hz=300.0)
            found[(b, timing)] = np.array([p[0].end_s, p[1].start_s, p[2].end_s, p[3].start_s])
    for b in (5e-6, 20e-6):
        d_travel = found[(b, "travel")] - found[(0.0, "travel")]
        d_half = found[(b, "half_velocity")] - found[(0.0, "half_velocity")]
        print(f"\n[slow ramps] b = {b * 1e6:g} µm: cruise start/end moved by (µs) travel "
              f"{np.round(d_travel * 1e6, 1).tolist()}, half-velocity {np.round(d_half * 1e6, 1).tolist()}; "
              f"b/v = {b / 0.02 * 1e6:g} µs")
        assert np.all(np.abs(d_travel[[0, 2]] - b / 0.02) < 10e-6)
        assert np.all(np.abs(d_travel[[1, 3]]) < 10e-6)
        assert np.all(np.abs(d_half[[0, 2]]) < 0.5 * b / 0.02)


def test_find_pulses_needs_the_bandwidth_for_slow_ramps():
    acc, fs, speeds, a, L, dwell = slow_routine(0.0)
    with pytest.raises(ValueError, match="needs the sensor's bandwidth_hz"):
        find_pulses(acc, fs, centroid_delay(300.0), speeds, a, L, dwell)

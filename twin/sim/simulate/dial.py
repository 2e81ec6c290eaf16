"""The paper's dial-indicator procedure (section III.C), simulated: the screw stepped through the
contact point with a lever tip fixed against the load, first contact forward, last contact in
reverse, read by eye (:func:`dial_indicator`). Readings in µm, everything else SI.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.sim.drive import Profile
from twin.sim.model import (
    stiffness_of,
)
from twin.sim.simulate.simulator import Condition, Simulator


@dataclass(frozen=True)
class DialResult:
    """backlash_um: the reading a technician reports (mean over repeats), µm; elastic_um: the
    largest elastic part of the lost motion, 2·F_rail/K_axial, µm (the rail friction fully
    loading the nut in both directions). In the simulation the reading lands slightly *below*
    the clearance (docs/validation.md) rather than up to elastic_um above it: MuJoCo's Coulomb
    friction is a soft constraint, so the settled carriage slowly relaxes the nut's load at each
    30 ms step.
    repeats_um: the single readings, µm."""

    backlash_um: float
    elastic_um: float
    repeats_um: tuple[float, ...]


def dial_indicator(sim: Simulator, cfg, cond: Condition, rng: np.random.Generator,
                   position: float = 0.225, settle: float = 0.03) -> DialResult:
    """The paper's dial-indicator procedure (section III.C), simulated.

    The lever tip is fixed against the steel load at rail coordinate ``position``. The screw is
    commanded in steps of ``cfg.step_um`` (held ``settle`` s each, quasi-static) through the
    contact point forward, then back. The technician reads the dial by eye: reading = true tip
    deflection + N(0, reading_noise), rounded to a tenth of the gradation, and takes the first
    step with a non-zero reading forward and the last one in reverse. The difference of the two
    displayed (encoder) positions, averaged over ``cfg.repeats`` repetitions (each from a random sub-step
    starting point), is the "experimental" backlash. ``cfg`` is a DialConfig."""
    step = cfg.step_um * 1e-6
    margin = 8e-6 + 4.0 * cfg.reading_noise_um * 1e-6
    b = cond.mech.backlash
    # Steps through the clearance and a margin on each side, then back (2·(b + margin) of
    # travel); the tip is set where the carriage will touch it half-way up.
    nsteps = int(math.ceil(2.0 * (b + margin) / step)) + 1
    per = max(int(round(settle * sim.fs)), 2)
    k_axial = stiffness_of(sim.world.axis, cond.mech)["axial"]
    elastic = 2.0 * sim.world.axis.carriage.rail_friction / k_axial
    resolution = cfg.gradation_um * 1e-6 / 10.0
    stretch = 1.0 + sim.lead_stretch(cond)
    results = []
    for _ in range(cfg.repeats):
        base = position - cond.origin_offset + float(rng.uniform(0.0, step))
        # The technician brings the lever to the load with the carriage parked on its forward
        # flank at ``base``; the tip ends up b + margin ahead of the load.
        tip = stretch * (base + cond.origin_offset) - b / 2.0 + b + margin
        up = base + step * np.arange(nsteps)
        stair = np.concatenate([up, up[::-1]])
        x_cmd = np.concatenate([np.full(per * 4, base), np.repeat(stair, per)])
        t = np.arange(x_cmd.size) / sim.fs
        # A vanishing first velocity tells the simulator which flank the carriage starts on.
        v = np.zeros_like(x_cmd)
        v[0] = 1e-12
        cmd_start = Profile(t=t, x=x_cmd, v=v, a=np.zeros_like(x_cmd))
        traj = sim.run(cond, cmd_start, passes=1)
        ends = per * 4 + per * (np.arange(2 * nsteps) + 1) - 1
        x_true = traj.x[ends]
        deflection = np.maximum(x_true - tip, 0.0)
        # A needle at rest reads exactly zero; once the tip is pushed, the by-eye estimate of
        # the sub-gradation deflection carries the reading error.
        noise = rng.normal(0.0, cfg.reading_noise_um * 1e-6, size=deflection.size)
        reading = np.where(deflection > 0.0, np.maximum(deflection + noise, 0.0), 0.0)
        reading = np.round(reading / resolution) * resolution
        touched = reading > 0.0
        fwd, rev = touched[:nsteps], touched[nsteps:]
        # The technician notes the position display: the encoder's actual position (nominal
        # lead), not the command, which the stiction of the drive leaves a fraction of a µm away.
        shown = traj.qpos[ends, traj.index.screw] * sim.world.axis.screw.radius_per_rad - cond.origin_offset
        cmd_steps_fwd, cmd_steps_rev = shown[:nsteps], shown[nsteps:]
        if not fwd.any() or not rev.any():
            raise RuntimeError("dial indicator: no contact within the stepped range")
        first_fwd = cmd_steps_fwd[np.argmax(fwd)]
        # Reverse: the last step (in time) at which the tip is still touched.
        last_rev = cmd_steps_rev[len(rev) - 1 - np.argmax(rev[::-1])]
        results.append((first_fwd - last_rev) * 1e6)
    return DialResult(backlash_um=float(np.mean(results)), elastic_um=elastic * 1e6,
                      repeats_um=tuple(results))

"""D − L at the stops: the carriage's true rest-to-rest travel D against the commanded stroke L,
for a backlash b and a deceleration a (Eq. 9 of the paper assumes D = L − b).

One run per case of a 20 mm stroke at 5 mm/s (quick scenario, dwell 1 s), simulated directly;
prints D − L forward and reverse in µm. Options: ``--damping-ratio Z`` (the nut contact's,
default the scenario's), ``--friction-timeconst S`` (the rail friction constraint's MuJoCo
solref time constant only; default MuJoCo's 0.02 s), ``--set KEY=VALUE`` (scenario overrides
on top of the case's, repeatable: e.g. ``axis.friction_timeconst_ms=0.4``,
``axis.friction_impedance=0.999``, ``phase2.start_flank="last"``, ``phase2.speeds_mm_s=[20.0]``),
``--accel A...`` (the decelerations, m/s²), ``--backlash B...`` (µm), ``--trace`` (for the first
deceleration and backlash only: every 5 ms from 50 ms before the first stop to 150 ms after, the
screw's lag behind the command, its speed, the carriage's place in the gap and the servo torque).
Usage:
``python benchmarks/bench_stop_travel.py [--damping-ratio 0.0003] [--friction-timeconst 0.0004]``.
``--record`` runs the cases docs/error-motions.md quotes (:data:`RECORDED`) and stores their
tables in docs/validation.json (:mod:`record`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from twin.sim.campaign import condition_at, make_world
from twin.sim.scenario import load
from twin.sim.simulate import Simulator, phase2_trajectory, stroke_travels

sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import record, text  # noqa: E402

ACCELS = (19.6, 2.0, 0.5, 0.1, 0.05)
STICKING = ("axis.friction_timeconst_ms=0.4", "axis.friction_impedance=0.999")
LAST_FLANK = ('phase2.start_flank="last"',)
#: The tables docs/error-motions.md quotes: name -> (settings, backlashes µm, decelerations m/s²).
RECORDED = {
    "default_friction": ((), (0.0, 10.0, 20.0), ACCELS),
    "sticking_last_flank": ((*STICKING, *LAST_FLANK), (0.0, 5.0, 10.0, 20.0), ACCELS),
    "sticking_20mm_s": ((*STICKING, *LAST_FLANK, "phase2.speeds_mm_s=[20.0]"), (0.0, 5.0, 10.0, 20.0), (0.05,)),
}
#: One setting at a time at 0.05 m/s² (reverse D − L): either friction key alone, or the time
#: constant with the velocity loop's integral action removed.
ALONE = {"`axis.friction_timeconst_ms=0.4`": (STICKING[0],),
         "`axis.friction_impedance=0.999`": (STICKING[1],),
         "`axis.friction_timeconst_ms=0.4`, `axis.velocity_integral_time_s=10`":
             (STICKING[0], "axis.velocity_integral_time_s=10")}


def _cell(d: np.ndarray) -> str:
    return " \\| ".join(text(v, "{:+.2f}") for v in d[:2])


def recorded_tables() -> dict[str, str]:
    """The Markdown tables of :data:`RECORDED` and :data:`ALONE` (D − L, µm)."""
    tables = {}
    for name, (sets, backlashes, accels) in RECORDED.items():
        rows = ["| deceleration | " + " | ".join(f"b = {b:g} µm" for b in backlashes) + " |",
                "|---" * (1 + len(backlashes)) + "|"]
        for acc in accels:
            rows.append(f"| {acc:g} m/s² | " + " | ".join(_cell(d_minus_l_um(acc, b, None, None, sets))
                                                       for b in backlashes) + " |")
        tables[name] = "\n".join(rows) + "\n"
    rows = ["| setting (0.05 m/s², reverse) | b = 0 | b = 10 µm | b = 20 µm |", "|---|---|---|---|"]
    for label, sets in ALONE.items():
        rows.append(f"| {label} | " + " | ".join(text(d_minus_l_um(0.05, b, None, None, sets)[1], "{:+.2f}")
                                               for b in (0.0, 10.0, 20.0)) + " |")
    tables["alone"] = "\n".join(rows) + "\n"
    return tables


def d_minus_l_um(accel_m_s2: float, backlash_um: float, damping_ratio: float | None,
                 friction_timeconst_s: float | None, extra: tuple[str, ...] = (),
                 trace: bool = False) -> np.ndarray:
    sets = ["campaign.phase1=false", "phase2.runs_per_session=1", "phase2.session_hours=[100.0]",
            "phase2.speeds_mm_s=[5.0]", f"phase2.accel_mm_s2={accel_m_s2 * 1e3}", "phase2.start_mm=100.0",
            "phase2.end_mm=120.0", "phase2.dwell_s=1.0", "degradation.law=table",
            "degradation.table_hours=[0.0, 1000.0]", "degradation.table_preload_fraction=[1.0, 1.0]",
            f"degradation.table_backlash_um=[{backlash_um}, {backlash_um}]"]
    if damping_ratio is not None:
        sets.append(f"axis.contact_damping_ratio={damping_ratio}")
    s = load("quick", [*sets, *extra])
    sim = Simulator(make_world(s), s.phase2.timestep_s)
    if friction_timeconst_s is not None:
        sim.model.dof_solref[sim.model.joint("carriage_x").dofadr[0]] = [friction_timeconst_s, 1.0]
    traj = phase2_trajectory(sim, s.phase2, condition_at(s, 100.0))
    st = stroke_travels(sim.world, traj)
    if trace:
        print_stop(sim, traj, condition_at(s, 100.0).origin_offset)
    return (np.abs(st["carriage_m"]) - np.abs(st["command_m"])) * 1e6


def print_stop(sim: Simulator, traj, origin: float) -> None:
    """The first stop of ``traj``, every 5 ms (see the module docstring)."""
    r = sim.world.axis.screw.radius_per_rad
    ix, t = traj.index, traj.t
    screw = traj.qpos[:, ix.screw] * r - origin
    cmd_x, cmd_v = np.interp(t, traj.cmd.t, traj.cmd.x), np.interp(t, traj.cmd.t, traj.cmd.v)
    moving = np.abs(cmd_v) > 1e-12
    stop = int(np.flatnonzero(moving[:-1] & ~moving[1:])[0])
    step = int(round(0.005 / sim.timestep))
    print("t − t_stop (ms)  command − screw (µm)  screw speed (mm/s)  carriage − screw (µm)  servo torque (N·m)")
    for k in range(stop - 10 * step, stop + 30 * step + 1, step):
        print(f"{(t[k] - t[stop]) * 1e3:+8.0f}  {(cmd_x[k] - screw[k]) * 1e6:+8.3f}  "
              f"{traj.qvel[k, ix.screw] * r * 1e3:+8.4f}  {(traj.x[k] - origin - screw[k]) * 1e6:+8.3f}  "
              f"{traj.sens[k, ix.servo_torque]:+8.4f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--damping-ratio", type=float, default=None)
    p.add_argument("--friction-timeconst", type=float, default=None)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--accel", type=float, nargs="+", default=[19.6, 2.0, 0.5, 0.1, 0.05])
    p.add_argument("--backlash", type=float, nargs="+", default=[0.0, 10.0, 20.0])
    p.add_argument("--trace", action="store_true")
    p.add_argument("--record", action="store_true", help="run the documented cases, store their tables")
    a = p.parse_args()
    if a.record:
        tables = recorded_tables()
        for v in tables.values():
            print(v)
        record("bench_stop_travel", command=".venv/bin/python benchmarks/bench_stop_travel.py --record",
               scale="one run per case of a 20 mm stroke at 5 mm/s (quick scenario, dwell 1 s)", figures={},
               tables=tables)
        return
    if a.trace:
        d = d_minus_l_um(a.accel[0], a.backlash[0], a.damping_ratio, a.friction_timeconst,
                         tuple(a.set), trace=True)
        print(f"D − L (µm): {d[0]:+.2f} | {d[1]:+.2f}")
        return
    print(f"D − L (µm), forward | reverse; 5 mm/s, 20 mm stroke; damping ratio "
          f"{a.damping_ratio or 'scenario'}, friction time constant {a.friction_timeconst or 'MuJoCo default'}"
          + (f"; {' '.join(a.set)}" if a.set else ""))
    for acc in a.accel:
        cells = [f"b {b:g} µm: {d[0]:+6.2f} | {d[1]:+6.2f}"
                 for b in a.backlash
                 for d in [d_minus_l_um(acc, b, a.damping_ratio, a.friction_timeconst, tuple(a.set))]]
        print(f"a {acc:5.2f} m/s²  " + "   ".join(cells), flush=True)


if __name__ == "__main__":
    main()

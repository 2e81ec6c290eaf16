"""Does Phase II need its second rollout pass? (prints figures; not a test)

One pass looks the rails up where the nut's flank contact puts the carriage
(``twin.sim.simulate.flank_contact_position``: what ``phase2.rail_passes = 1`` does); two passes
look them up, in the second, at the true carriage position of a first pass (the fixed point;
its first pass looks them up at the command shifted by the clearance's lag). For one session of
the paper's routine (``scenarios/paper-rtf.toml``, which does one pass) early (50 h, no
backlash), mid-wear (5000 h) and late (8000 h, about 10 µm), and of ``backlash-steps`` (a
preloaded nut with a 10 and a 20 µm clearance, two passes), it prints how far the carriage's x
of the two differ, how far the rail input (the trucks' vertical displacements at that x) and
the true rest-to-rest travels. What the estimators make of the difference:
``tests/test_campaign.py::test_one_rail_pass_keeps_the_paper_figures``.

Run: .venv/bin/python benchmarks/bench_rail_passes.py   (about two minutes on one core);
``--record`` stores the figures docs/validation.md quotes ("Simulation speed") in
docs/validation.json (benchmarks/record.py).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from record import record, text  # noqa: E402

from twin.sim import geometry as geo
from twin.sim.campaign import condition_at, make_world, origin_offset
from twin.sim.scenario import load
from twin.sim.simulate import Simulator, phase2_command, stroke_travels


def listed(values: list[float], fmt: str) -> str:
    """``values`` as the docs list them: "a, b and c"."""
    out = [text(v, fmt) for v in values]
    return out[0] if len(out) == 1 else f"{', '.join(out[:-1])} and {out[-1]}"


def main() -> None:
    rows: dict[str, list[tuple[float, ...]]] = {"paper-rtf": [], "backlash-steps": []}
    for name, hours in (("paper-rtf", 50.0), ("paper-rtf", 5000.0), ("paper-rtf", 8000.0),
                        ("backlash-steps", 500.0), ("backlash-steps", 600.0)):
        s = load(name, ["campaign.phase1=false", f"phase2.session_hours=[{hours}]"])
        sim = Simulator(make_world(s), s.phase2.timestep_s)
        cond = condition_at(s, hours, origin_offset(s, 0))
        cmd = phase2_command(sim, s.phase2)
        one = sim.run(cond, cmd, passes=1, contact_guess=True)
        two = sim.run(cond, cmd, passes=2)
        w = sim.world
        rails = [geo.truck_displacements(w.rails, w.carriage, t.x)["vertical"] for t in (one, two)]
        dx = one.x - two.x
        travel = stroke_travels(w, one)["carriage_m"] - stroke_travels(w, two)["carriage_m"]
        print(f"{name} ({s.phase2.rail_passes} pass{'es' if s.phase2.rail_passes > 1 else ''}), "
              f"{hours:6.0f} h, backlash {cond.mech.backlash * 1e6:5.2f} µm: x of one pass − two "
              f"max {np.abs(dx).max() * 1e9:.1f} nm, rms {np.sqrt(np.mean(dx ** 2)) * 1e9:.2f} nm; "
              f"rail input max {np.abs(rails[0] - rails[1]).max() * 1e12:.1f} pm; rest-to-rest "
              f"travels max {np.abs(travel).max() * 1e9:.1f} nm apart", flush=True)
        rows[name].append((cond.mech.backlash * 1e6, np.abs(dx).max() * 1e9, np.sqrt(np.mean(dx ** 2)) * 1e9,
                           np.abs(rails[0] - rails[1]).max() * 1e12, np.abs(travel).max() * 1e9))
    if "--record" in sys.argv[1:]:
        paper, steps = np.array(rows["paper-rtf"]), np.array(rows["backlash-steps"])
        figures = {"paper_backlash_um": (paper[:, 0], "{:.2f}"), "paper_x_max_nm": (paper[:, 1], "{:.0f}"),
                   "paper_x_rms_nm": (paper[:, 2], "{:.1f}"), "paper_rail_max_pm": (paper[:, 3], "{:.0f}"),
                   "paper_travel_max_nm": (paper[:, 4], "{:.0f}"),
                   "steps_travel_max_um": (steps[:, 4] * 1e-3, "{:.1f}")}
        record("bench_rail_passes", command=".venv/bin/python benchmarks/bench_rail_passes.py --record",
               scale="one session of scenarios/paper-rtf.toml at 50, 5000 and 8000 h, of backlash-steps at "
                     "500 and 600 h", figures={k: (round(float(v.max()), 4), listed(v.tolist(), f))
                                             for k, (v, f) in figures.items()})


if __name__ == "__main__":
    main()

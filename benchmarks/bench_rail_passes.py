"""Does Phase II need its second rollout pass? (prints figures; not a test)

Pass 1 looks the rails up at the commanded position shifted by the known backlash lag; pass 2
at the true carriage position of pass 1 (``twin.simulate`` module docstring). For one session
of the paper's routine early (50 h, no backlash) and late (8000 h, about 10 µm) it prints how
far the carriage's x of the two passes differ and how far the rail input (the trucks' vertical
displacements at that x) differs.

Run: .venv/bin/python benchmarks/bench_rail_passes.py   (about a minute on one core)
"""

from __future__ import annotations

import numpy as np

from twin import geometry as geo
from twin.campaign import condition_at, make_world, origin_offset
from twin.scenario import load
from twin.simulate import Simulator, phase2_command


def main() -> None:
    for hours in (50.0, 8000.0):
        s = load("paper-rtf", ["campaign.phase1=false", f"phase2.session_hours=[{hours}]"])
        sim = Simulator(make_world(s), s.phase2.timestep_s)
        cond = condition_at(s, hours, origin_offset(s, 0))
        cmd = phase2_command(sim, s.phase2)
        one, two = sim.run(cond, cmd, passes=1), sim.run(cond, cmd, passes=2)
        w = sim.world
        rails = [geo.truck_displacements(w.rails, w.carriage, t.x)["vertical"] for t in (one, two)]
        dx = one.x - two.x
        print(f"{hours:6.0f} h, backlash {cond.mech.backlash * 1e6:5.2f} µm: x of pass 1 − pass 2 "
              f"max {np.abs(dx).max() * 1e9:.1f} nm, rms {np.sqrt(np.mean(dx ** 2)) * 1e9:.2f} nm; "
              f"rail input max {np.abs(rails[0] - rails[1]).max() * 1e12:.1f} pm")


if __name__ == "__main__":
    main()

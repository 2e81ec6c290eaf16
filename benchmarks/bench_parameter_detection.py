"""Benchmark: the smallest mis-setting of each twin parameter the gap diagnosis sees.

A twin parameter set wrong by a factor close to 1 moves the statistics less than the twin's own
seed-to-seed spread, and the diagnosis rightly answers "no significant gap": there is nothing to
name (issue 15, item 4: four of the thirty parameter cases of the blind benchmark were such, until
it drew its mis-settings beyond these limits, ``TwinParameter.least_seen``). This measures
where that limit lies, per parameter and side: for each factor of a ladder (1.1, 1.2, 1.4, 2, and
their inverses, those inside the parameter's prior range), the twin of the scenario with that
factor is simulated with ``--case-seeds`` recording seeds (other than the twin's), and the gap
test of the diagnosis (Holm at α = 0.01 on the calibration part, the held-out gap against its
χ² quantile, :func:`analysis.diagnosis.attribution.diagnose` with no candidate) says whether it
differs from the twin. The limit of a side is the smallest deviation seen with every seed from
there outwards.

Prints a table (parameter, side, the gap at each factor, the limit) and writes it as JSON.

Usage: .venv/bin/python benchmarks/bench_parameter_detection.py [--scenario S] [--cache DIR]
       [--case-seeds N] [--workers N] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from analysis.diagnosis import attribution  # noqa: E402
from twin.harness.diagnosis.cache import DEFAULT_SEEDS, evaluate_all, with_seed  # noqa: E402
from twin.harness.diagnosis.candidates.parameters import PARAMETERS  # noqa: E402
from twin.harness.diagnosis.ensemble import build_ensemble  # noqa: E402
from twin.harness.diagnosis.library import with_effects  # noqa: E402
from twin.sim.scenario import load  # noqa: E402

LADDER = (1.1, 1.2, 1.4, 2.0)  # deviations tried on each side (factor and 1/factor)
CASE_SEED0 = 30_000  # recording seeds: not the twin's nor the blind benchmark's


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", type=Path, default=REPO / "scenarios" / "diagnose-bench.toml")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/bench-parameter-detection"))
    ap.add_argument("--case-seeds", type=int, default=2)
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    nominal = load(args.scenario)
    t0 = time.perf_counter()
    # The twin's spread only: no candidate is fitted, the question is whether the gap is seen.
    ens = build_ensemble(nominal, args.cache, DEFAULT_SEEDS, args.workers, library=[], response_seeds=1)
    plan = []
    for name, par in PARAMETERS.items():
        p = par.factor
        for side, sign in (("down", -1), ("up", 1)):
            for dev in LADDER:
                f = dev ** sign
                if p.low - 1e-12 <= f <= p.high + 1e-12:
                    for k in range(args.case_seeds):
                        plan.append((name, side, dev, f, CASE_SEED0 + k))
    scen = [with_seed(with_effects(nominal, {name: {"factor": f}}), seed) for name, _, _, f, seed in plan]
    sigs = evaluate_all(scen, args.cache, args.workers)
    rows = []
    for (name, side, dev, f, seed), sig in zip(plan, sigs, strict=True):
        res, _ = attribution.diagnose(sig, ens.twin, [])
        rows.append({"parameter": name, "side": side, "deviation": dev, "factor": f, "seed": seed,
                     "seen": res["verdict"] != attribution.NO_GAP,
                     "heldout_gap": res["heldout_gap_before"], "critical": res["heldout_gap_critical"],
                     "n_significant": res["n_significant_calibration"]})
    wall = time.perf_counter() - t0
    limits = []
    print(f"{'parameter':42s} {'side':5s} " + " ".join(f"{'x' + format(d, 'g'):>12s}" for d in LADDER) + "  limit")
    for name in PARAMETERS:
        for side in ("down", "up"):
            mine = [r for r in rows if r["parameter"] == name and r["side"] == side]
            if not mine:
                continue
            cells, seen_from = [], None
            for dev in LADDER:
                at = [r for r in mine if r["deviation"] == dev]
                if not at:
                    cells.append(f"{'–':>12s}")
                    continue
                n_seen = sum(r["seen"] for r in at)
                cells.append(f"{n_seen}/{len(at)} {min(r['n_significant'] for r in at):>5d}s")
            devs = sorted({r["deviation"] for r in mine})
            for dev in devs:
                if all(r["seen"] for r in mine if r["deviation"] >= dev):
                    seen_from = dev
                    break
            limit = (f"{'÷' if side == 'down' else '×'}{seen_from:g}" if seen_from is not None
                     else f"not seen within the prior (to {'÷' if side == 'down' else '×'}{max(devs):g})")
            limits.append({"parameter": name, "side": side, "limit": seen_from,
                           "largest_tried": max(devs)})
            print(f"{name:42s} {side:5s} " + " ".join(cells) + f"  {limit}")
    print(f"{len(plan)} recordings ({args.case_seeds} seeds per factor) simulated and tested in {wall:.0f} s "
          f"(cells: seeds in which the gap is seen / seeds, least significant statistics)")
    if args.out:
        args.out.write_text(json.dumps({"scenario": nominal.name, "ladder": LADDER,
                                        "case_seeds": args.case_seeds, "limits": limits, "rows": rows,
                                        "wall_s": wall}, indent=1))


if __name__ == "__main__":
    main()

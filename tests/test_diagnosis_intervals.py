"""The stated interval of a fitted candidate (issue 15, item 5): each source of error it holds,
checked on responses whose answer is known, and the responses on several twin seeds it needs.

The benchmark's coverage itself (the injected value inside the stated interval, per kind) is
asserted in tests/test_diagnosis.py on the default benchmark.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import REPO, run_twin
from scipy import stats

from analysis.diagnosis import attribution as at
from analysis.diagnosis.signature import Region, Signature

N = 400  # statistics of the synthetic responses


def linear_candidate(grid=(-20.0, -8.0, 0.0, 8.0, 20.0), slopes=(1.0,), scale=0.1):
    """A one-parameter candidate whose response is slope · p · ``scale`` sd on every statistic
    (times x, between 0.5 and 1.5), one per seed in ``slopes`` (the first is the fitted one)."""
    x = np.linspace(0.5, 1.5, N)  # the statistics respond unequally
    per_seed = np.stack([np.stack([scale * s * v * x for v in grid]) for s in slopes])
    delta = {"cal": per_seed[0], "heldout": per_seed[0]}
    seeds = {"cal": per_seed, "heldout": per_seed} if len(slopes) > 1 else None
    return at.CandidateResponse("c", [at.ParamAxis("p", tuple(grid))], delta, per_seed=seeds), x


def test_a_fitted_value_is_not_rounded_to_the_fine_grid():
    """A gain of 10.35 % on a grid −20 … 20 %: the fine grid (61 values, 0.67 % apart) rounds it
    to 10.67 %; the zoomed search of the added candidate returns it within its own step."""
    cand, x = linear_candidate()
    z = 0.1 * 10.35 * x
    sd = {"cal": np.ones(N), "heldout": np.ones(N)}
    sel = np.ones(N, bool)
    coarse = at.fit_candidate(cand, z, z, sd, sel, 0.01)
    zoomed = at.fit_candidate(cand, z, z, sd, sel, 0.01, zoom=True)
    step = at.search_step(cand.params[0])
    assert step == pytest.approx(40.0 / 60 / 10)
    assert coarse.params["p"] == pytest.approx(10.0 + 2.0 / 3.0)
    assert abs(zoomed.params["p"] - 10.35) <= step / 2 + 1e-9
    assert zoomed.heldout_after < coarse.heldout_after


def test_the_interpolation_shift_moves_a_curved_response_toward_its_value():
    """A response growing with the square of its parameter, simulated at 0, 5, 10, 20: between
    10 and 20 the straight line overestimates it, and the linear fit of a recording at 15 lands at
    14.2; the shape-preserving cubic lands within 0.1 of 15, and the stated interval holds 15."""
    grid = (0.0, 5.0, 10.0, 20.0)
    x = np.linspace(0.5, 1.5, N)
    delta = np.stack([1e-2 * v ** 2 * x for v in grid])
    cand = at.CandidateResponse("c", [at.ParamAxis("p", grid)], {"cal": delta, "heldout": delta})
    z = 1e-2 * 15.0 ** 2 * x
    sd = np.ones(N)
    fit = at.fit_candidate(cand, z, z, {"cal": sd, "heldout": sd}, np.ones(N, bool), 0.01, zoom=True)
    down, up = at.interpolation_shift(cand, z, sd)["p"]
    assert fit.params["p"] == pytest.approx(10.0 + 10.0 * 125.0 / 300.0, abs=0.02)
    assert down == 0.0 and abs(fit.params["p"] + up - 15.0) < 0.1
    regions = [Region("phase1", "a", "band", "x", float(i)) for i in range(N)]
    lo, hi = at.stated_interval(fit, cand, z, sd, regions)["p"]
    assert lo <= 15.0 <= hi and hi - lo < 1.5


def test_a_log_scaled_factor_is_also_interpolated_in_log():
    """A noise floor's factor (log-uniform prior, grid 0.5 … 4) whose response is a log power,
    linear in log p: a recording at 0.644 is fitted at 0.69 between the grid values 0.5 and 1.0
    by the straight line in p; linear in log p it is exact, and the interval reaches down to it.
    A factor without the log prior is not interpolated in log (PCHIP alone goes part of the way)."""
    grid = (0.5, 1.0, 2.0, 3.0, 4.0)
    x = np.linspace(0.5, 1.5, N)
    delta = np.stack([3.0 * np.log(v) * x for v in grid])
    cand = at.CandidateResponse("c", [at.ParamAxis("factor", grid, log=True)], {"cal": delta, "heldout": delta})
    z = 3.0 * np.log(0.644) * x
    sd = np.ones(N)
    fit = at.fit_candidate(cand, z, z, {"cal": sd, "heldout": sd}, np.ones(N, bool), 0.01, zoom=True)
    down, up = at.interpolation_shift(cand, z, sd)["factor"]
    line = 0.5 + 0.5 * (np.log(0.644) - np.log(0.5)) / (0.0 - np.log(0.5))  # where the line in p gives it
    assert fit.params["factor"] == pytest.approx(line, abs=0.002)
    assert fit.params["factor"] + down == pytest.approx(0.644, abs=0.002)
    regions = [Region("phase1", "a", "band", "x", float(i)) for i in range(N)]
    lo, hi = at.stated_interval(fit, cand, z, sd, regions)["factor"]
    assert lo <= 0.644 < line <= hi
    plain = at.CandidateResponse("c", [at.ParamAxis("factor", grid)], {"cal": delta, "heldout": delta})
    assert down < at.interpolation_shift(plain, z, sd)["factor"][0] < 0.0  # PCHIP alone: part of the way


def test_the_seed_interval_is_the_prediction_interval_of_the_seeds_fits():
    """Responses on three seeds with slopes 1.0, 1.1 and 0.9, a recording whose machine responds
    with 1.05 at p = 2: the fit with the first seed's response says 2.1 (outside a Δχ² interval
    of a noiseless fit); refitted with each seed's response, 2.1, 1.91 and 2.33, and the 90 %
    prediction interval of a fourth draw, mean ± t₂(0.95)·s·√(4/3), holds 2."""
    cand, x = linear_candidate(grid=(0.0, 1.0, 2.0, 4.0), slopes=(1.0, 1.1, 0.9), scale=1.0)
    z = 1.05 * 2.0 * x
    sd = np.ones(N)
    fit = at.fit_candidate(cand, z, z, {"cal": sd, "heldout": sd}, np.ones(N, bool), 0.01, zoom=True)
    assert fit.params["p"] == pytest.approx(2.1, abs=0.01)
    assert not fit.interval["p"][0] <= 2.0 <= fit.interval["p"][1]
    fits = np.array([2.1, 2.1 / 1.1, 2.1 / 0.9])
    half = stats.t.ppf(0.95, 2) * fits.std(ddof=1) * np.sqrt(4.0 / 3.0)
    lo, hi = at.seed_interval(cand, z, sd)["p"]
    assert lo == pytest.approx(fits.mean() - half, abs=0.01)
    assert hi == pytest.approx(fits.mean() + half, abs=0.01)
    assert lo <= 2.0 <= hi
    one_seed, _ = linear_candidate(grid=(0.0, 1.0, 2.0, 4.0))
    assert at.seed_interval(one_seed, z, sd) == {}


def test_the_noise_interval_follows_what_the_twins_seeds_share_with_the_response():
    """The twin's seeds deviate along the response (a machine that vibrates a little more or
    less on the channel a gain acts on): the refits move with them and the interval is
    t₇(0.95)·s·√(9/8) wide on each side; deviations that do not lean like the response (signs
    alternating from statistic to statistic) leave it within a hundredth."""
    cand, x = linear_candidate()
    z = 0.1 * 10.0 * x
    sd = np.ones(N)
    common = np.array([-0.5, -0.3, -0.1, 0.0, 0.1, 0.2, 0.3, 0.4])  # in units of the 0.1 sd step
    noise = 0.1 * common[:, None] * x[None, :]
    lo, hi = at.noise_interval(cand, z, sd, noise)["p"]
    half = stats.t.ppf(0.95, 7) * common.std(ddof=1) * np.sqrt(9.0 / 8.0)
    assert (lo, hi) == pytest.approx((10.0 - half, 10.0 + half), abs=0.05)  # refits to the search step
    alternating = 0.5 * np.where(np.arange(N) % 2 == 0, 1.0, -1.0)[None, :] * np.linspace(-1, 1, 8)[:, None]
    lo2, hi2 = at.noise_interval(cand, z, sd, alternating)["p"]
    assert hi2 - lo2 < 0.01


def test_candidate_scenarios_and_artefact_plans_use_the_response_seeds():
    """A deterministic effect is simulated on the first ``response_seeds`` twin seeds, a random
    one (origins drawn per session) on all of them; an artefact is post-processed on the first
    ``response_seeds`` campaigns, an order line on all (its response is their mean)."""
    from twin.harness import diagnosis as gr
    from twin.harness.diagnosis.candidates import candidates
    from twin.sim.scenario import load

    nominal = load(REPO / "scenarios" / "diagnose-bench.toml")
    seeded = [gr.with_seed(nominal, s) for s in gr.twin_seeds(nominal, 5)]
    lib = {k: v for k, v in candidates().items() if k in ("thermal_growth", "origin_variability")}
    scen, points = gr.candidate_scenarios(seeded, lib, 3)
    for gp, idx in points:
        if not idx:
            continue
        want = [s.seed for s in (seeded if gp.effect == "origin_variability" else seeded[:3])]
        assert [scen[i].seed for i in idx] == want
    plans = gr.artefact_plans(["gain:acc1"], 5, 3)
    assert len(plans) == 3 and all(len(specs) == 4 for specs, _ in plans)
    plans = gr.artefact_plans(["gain:acc1", "order_line:acc"], 5, 3)
    assert len(plans) == 5 and [len(specs) for specs, _ in plans] == [4 + 20] * 3 + [20] * 2
    with pytest.raises(ValueError, match=r"--response-seeds 6: expected 1 to --seeds \(5\)"):
        gr.check_response_seeds(6, 5)


def test_responses_keep_every_seed_and_fit_the_first_or_the_mean():
    """The response fitted is the first seed's for a deterministic effect (common random numbers)
    and the mean over the seeds for a random one; every seed's change is kept for the interval."""
    from twin.harness import diagnosis as gr
    from twin.harness.diagnosis.candidates import candidates

    lib = {k: v for k, v in candidates().items() if k in ("thermal_growth", "origin_variability")}
    rng = np.random.default_rng(3)
    n = 6

    def sig(v):
        return {p: Signature(np.asarray(v, float)) for p in ("cal", "heldout")}

    nominal = [sig(rng.normal(size=n)) for _ in range(3)]
    points, grid_sigs = [], []
    for eff in lib.values():
        for gp in gr.grid_points(eff):
            idx = []
            if not eff.is_off(gp.values):
                for k in range(3):  # 3 response seeds; the random effect on the 3 seeds of this spread
                    idx.append(len(grid_sigs))
                    grid_sigs.append(sig(nominal[k]["cal"].values + (k + 1) * gp.index[0]))
            points.append((gp, idx))
    out = {c.name: c for c in gr.responses(lib, points, grid_sigs, nominal)}
    tg, ov = out["thermal_growth"], out["origin_variability"]
    assert tg.per_seed["cal"].shape == (3, 4, n)
    assert np.allclose(tg.per_seed["cal"][:, 2], np.array([2.0, 4.0, 6.0])[:, None])
    assert np.allclose(tg.delta["cal"], tg.per_seed["cal"][0])
    assert np.allclose(ov.delta["cal"], ov.per_seed["cal"].mean(axis=0))


@pytest.mark.parametrize("verb", ["diagnose", "diagnose-benchmark"])
def test_more_response_seeds_than_twin_seeds_is_refused(verb, tmp_path):
    """The responses are simulated with the twin's own seeds: asking for more is refused before
    anything is simulated, naming the option, the value and the limit."""
    args = (["diagnose", str(tmp_path), "--scenario", str(REPO / "scenarios" / "diagnose-bench.toml")]
            if verb == "diagnose" else ["diagnose-benchmark", "-o", str(tmp_path / "b")])
    proc = run_twin(*args, "--seeds", "4", "--response-seeds", "5", check=False)
    assert proc.returncode == 2
    assert "--response-seeds 5: expected 1 to --seeds (4)" in " ".join(proc.stderr.split())
    assert not (tmp_path / "b").exists() and not (tmp_path / "diagnosis").exists()

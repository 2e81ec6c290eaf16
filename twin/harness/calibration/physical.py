"""Layer (c): the drive's physical parameters and the Phase I acceleration fitted jointly through
the twin (indirect inference with ``scipy.optimize.least_squares``; the package's docstring
says how and why), each with its 90 % interval.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy import optimize

from analysis.calibration.drive import VELOCITY_BAND_HZ
from analysis.calibration.sensor_chain import Measured
from analysis.dataset import open_measurements
from twin.harness.calibration.misfit import profiled_chi2
from twin.harness.calibration.sensors import corrected_sensor_values
from twin.harness.calibration.twin_statistics import _statistics, evaluate, fit_scenario, vertical_statistic
from twin.harness.calibration.values import (
    CONVERGED_CHI2,
    EXTRA_STATS,
    FIT_CAPTURES,
    FIT_CHANNELS,
    FIT_CHANNELS_PHASE1,
    FIT_RUNS,
    FIT_SEEDS,
    FITTED,
    LOG_STEP,
    MAX_JACOBIANS,
    MAX_STEPS,
    MIN_SEEN,
    PRIOR_FACTOR,
    RESTART_SE,
    RUN_CHANNELS,
    SPREAD_SEEDS,
    STAT_NAMES,
    T90,
    Z90,
    CalibrationError,
    FitResult,
    Value,
    _OutOfTime,
    _progress,
    fit_note,
    flagged_channels,
    flagged_keys,
)
from twin.sim.config import get_dotted, set_dotted
from twin.sim.scenario import Scenario, from_dict

# ---------------------------------------------------------------------------------------------
# Layer (c): the joint fit

def fit_physical(base: Scenario, recording: Path, cache: Path, budget_s: float | None,
                 workers: int, scheduler: str | None = None,
                 progress: Callable[[str], None] = _progress, spent_s: float = 0.0,
                 sensors: dict[str, Measured] | None = None, check: dict | None = None) -> FitResult:
    """Layer (c) of the module docstring on ``recording`` against ``base`` (layers a and b
    applied). Raises :class:`CalibrationError` when ``budget_s`` (the whole calibration's, of
    which ``spent_s`` is spent) cannot hold: after timing the twin's first simulations, with the
    estimate and the smallest budget that would do. ``sensors``: layer (b) as measured; the
    spread at the solution is simulated with their first correction set
    (:func:`corrected_sensor_values`), so its instruments give the second. ``check``: the record of
    ``twin check`` on the recording: nothing is fitted to a channel it flags (the parameter read
    on it keeps its start, its statistic out of the fit), and a flagged IMU or command leaves the
    Phase II runs out (the ripple, the lateral mode and the velocity loop read on Phase I:
    :data:`FIT_CHANNELS_PHASE1`)."""
    from analysis.base.executors import run_tasks

    t0 = time.perf_counter()
    with open_measurements(recording / "measurements.h5") as m:
        names = m.phase1_captures()
        if not names:
            return FitResult([], {k: "no Phase I capture: no torque to fit" for k, _, _ in FITTED}, 0,
                             0.0, [], [], {}, {})
        first = min(m.phase1_header(n)[1] for n in names)
        caps = [n for n in names if m.phase1_header(n)[1] == first][:FIT_CAPTURES]
        hours = float(m.phase1(caps[0]).hours)
        sessions = m.phase2_sessions()
        runs = [(sessions[0], r) for r in m.phase2_runs(sessions[0])[:FIT_RUNS]] if sessions else []
        if runs and getattr(m.phase2(*runs[0]), "position_cmd", None) is None:
            runs = []  # the motor angle needs the command: the ripple is read on the torque
        flags = flagged_channels(check)
        run_flag = next((c for c in RUN_CHANNELS if c in flags), None) if runs else None
        if run_flag:
            runs = []
            progress(f"layer c: the Phase II runs left out: twin check flags {run_flag} ({flags[run_flag]}); "
                     "the ripple, the lateral mode and the velocity loop read on Phase I")
        session_h = m.session_hours(sessions[0]) if runs else None
        band = vertical_statistic(m, caps, base)  # fixed for every evaluation
        real, real_se = _statistics(m, caps, runs, base, band)
    skipped: dict[str, str] = {}
    use = []
    flagged = flagged_keys(check, FIT_CHANNELS if runs else FIT_CHANNELS_PHASE1)
    for i, (key, stat, _) in enumerate(FITTED):
        if key in flagged:
            skipped[key] = flagged[key]
        elif not np.isfinite(real[i]):
            skipped[key] = (
                "the ripple's order is above half the IMU accelerometer's bandwidth at every Phase II speed, or "
                "no cruise spans 4 of its periods" if stat == "ripple" and runs else
                "the servo's gain from the command to the IMU cannot be read: it needs Phase II runs of at least "
                f"2 s with motion and an IMU rate above twice {VELOCITY_BAND_HZ[1]:g} Hz"
                if stat == "loop_response" and runs else
                f"the recording's {stat.replace('_', ' ')} cannot be measured (no ramp, or no cruise of 4 "
                "ripple periods, in its first Phase I sample)")
        else:
            use.append(i)
    data0 = fit_scenario(base, hours, len(caps), session_h, len(runs))
    keys = [FITTED[i][0] for i in use]
    start = np.array([float(get_dotted(data0, k)) for k in keys])
    if np.any(start <= 0):
        bad = [k for k, v in zip(keys, start, strict=True) if v <= 0]
        for k in bad:
            skipped[k] = "its starting value is 0: a factor cannot move it"
        use = [i for i in use if FITTED[i][0] not in bad]
        keys = [FITTED[i][0] for i in use]
        start = np.array([float(get_dotted(data0, k)) for k in keys])
    # the statistics in the fit: each fitted parameter's, then the extra ones the recording gives
    n_own = len(FITTED)
    stat_idx = np.array(use + [n_own + e for e in range(len(EXTRA_STATS)) if np.isfinite(real[n_own + e])],
                        dtype=int)
    extra_rows = np.arange(len(use), stat_idx.size)  # their positions among the fit's statistics
    cache.mkdir(parents=True, exist_ok=True)
    sims = [0]

    extra: dict[str, float] = {}  # set at every evaluation (the sensors' first correction, at the end)

    def scenario_at(logp: np.ndarray, seed: int | None = None) -> str:
        data = json.loads(json.dumps(data0))
        for k, v in extra.items():
            set_dotted(data, k, float(v), source="calibrate")
        for k, lp in zip(keys, logp, strict=True):
            set_dotted(data, k, float(np.exp(lp)), source="calibrate")
        if seed is not None:
            data["seed"] = int(seed)
        return from_dict(data).to_json()

    def run(points: list[np.ndarray], seeds: list[int]) -> list[list[list[float]]]:
        """Statistics of each point with each seed (point-major)."""
        payloads = [scenario_at(p, sd) for p in points for sd in seeds]
        n = len(payloads)
        size = max(1, -(-n // max(1, workers)))
        batches = [payloads[k:k + size] for k in range(0, n, size)]
        results = run_tasks(evaluate, [(b, str(cache), band) for b in batches], workers, scheduler)
        sims[0] += n
        return [r for res in results for r in res]

    def averaged(points: list[np.ndarray]) -> list[np.ndarray]:
        """The statistics of each point averaged over the FIT_SEEDS seeds."""
        rows = run(points, seeds[:FIT_SEEDS])
        # over the fitted statistics only: one the fit does not use may be NaN at every seed; one it
        # uses that no seed could read (a pitch lost in a ringing twin) stays NaN, without a warning
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return [np.nanmean(np.array([rows[i * FIT_SEEDS + k][0] for k in range(FIT_SEEDS)])[:, stat_idx],
                               axis=0) for i in range(len(points))]

    x0 = np.log(start)
    t_first = time.perf_counter()
    seeds = [int(data0["seed"])] + [(int(data0["seed"]) + 7919 * (i + 1)) % 2**32 for i in range(SPREAD_SEEDS - 1)]
    spread = run([x0], seeds)
    first_eval = spread[0]
    unit_s = (time.perf_counter() - t_first) / max(1.0, len(seeds) / max(1, workers))

    def cost_s(n_points: int, n_seeds: int = FIT_SEEDS) -> float:
        """Time of ``n_points`` evaluations of ``n_seeds`` seeds each on the workers."""
        return unit_s * math.ceil(n_points * n_seeds / max(1, workers))

    # at most: the first Jacobian and each parameter's factor 2 either way, MAX_STEPS steps, the
    # Jacobian at the solution, MAX_JACOBIANS more with their steps, the spread at the solution;
    # at least (what a fit with intervals needs): the same but one step and no refreshed Jacobian
    reserve_s = cost_s(1, SPREAD_SEEDS) + 2.0  # the spread at the solution, the files
    full = cost_s((MAX_JACOBIANS + 4) * (len(keys) + 1) + (MAX_JACOBIANS + 1) * MAX_STEPS) + reserve_s
    least = cost_s(4 * (len(keys) + 1) + 1) + reserve_s
    elapsed = spent_s + (time.perf_counter() - t0)
    total = elapsed + full
    deadline = None if budget_s is None else t0 + budget_s - spent_s

    def no_room_for(n_points: int) -> bool:
        """Whether ``n_points`` evaluations and the fit's end (the spread, the files) would pass
        the budget's deadline (never without a budget)."""
        return deadline is not None and time.perf_counter() + cost_s(n_points) + reserve_s > deadline
    progress(f"layer c: {len(keys)} parameters jointly; one twin evaluation {unit_s:.1f} s: the calibration "
             f"takes at most {total / 60:.1f} min, and a fit again for every parameter found not told apart "
             "and from a second start when the first ends far from the recording"
             + ("" if budget_s is None or total <= budget_s else
                                                       f"; the fit stops at the budget ({budget_s / 60:g} min)"))
    if budget_s is not None and elapsed + least > budget_s:
        raise CalibrationError(
            f"{recording}: the calibration needs at least {(elapsed + least) / 60:.1f} min on {workers} worker(s) "
            f"(about {total / 60:.1f} min to converge: one evaluation of the twin takes {unit_s:.1f} s); "
            f"--budget-minutes {budget_s / 60:g} is too small: give at least "
            f"{math.ceil((elapsed + least) / 60 * 1.1 * 10) / 10:g} ({math.ceil(total / 60 * 10) / 10:g} to converge)")
    sim_se = np.array(first_eval[1])[stat_idx] / math.sqrt(FIT_SEEDS)
    seed_sd = np.nanstd(np.array([r[0] for r in spread])[:, stat_idx], axis=0, ddof=1)
    # the recording is one machine (one draw: its seed scatter counts whole), the twin's
    # average of FIT_SEEDS draws
    se = np.sqrt(real_se[stat_idx] ** 2 + np.nan_to_num(sim_se, nan=0.0) ** 2
                 + np.nan_to_num(seed_sd) ** 2 * (1 + 1 / FIT_SEEDS))
    # a statistic whose error cannot be estimated (one capture): 1 % of its value
    se = np.where(np.isfinite(se) & (se > 0), se, 0.01 * np.abs(real[stat_idx]))
    target = real[stat_idx]
    memo: dict[bytes, np.ndarray] = {
        x0.tobytes(): np.nanmean(np.array([r[0] for r in spread[:FIT_SEEDS]])[:, stat_idx], axis=0)}

    def values_at(points: list[np.ndarray]) -> list[np.ndarray]:
        todo = [p for p in points if p.tobytes() not in memo]
        if todo:
            for p, r in zip(todo, averaged(todo), strict=True):
                memo[p.tobytes()] = r
        return [memo[p.tobytes()] for p in points]

    rows = np.arange(stat_idx.size)  # the statistics in the fit (one per parameter, then the extra ones)

    def resid(x: np.ndarray) -> np.ndarray:
        return np.nan_to_num((values_at([x])[0] - target) / se, nan=1e6)[rows]

    def jac(x: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """d(residual)/d(log p) of the parameters ``cols`` at ``x`` (all parameters), by forward
        differences of :data:`LOG_STEP`."""
        pts = [x.copy() for _ in cols]
        for p, j in zip(pts, cols, strict=True):
            p[j] += LOG_STEP
        f0 = resid(x)
        vals = values_at(pts)
        at = ", ".join(f"{k.split('.')[-1]}={np.exp(v):.4g}" for k, v in zip(keys, x, strict=True))
        progress(f"layer c: Jacobian at {at} ({sims[0]} evaluations so far)")
        return np.column_stack([(np.nan_to_num((c - target) / se, nan=1e6)[rows] - f0) / LOG_STEP for c in vals])

    # Every statistic of the fit moving by under MIN_SEEN standard errors for a factor 2 of a
    # parameter either way (simulated: the slope at the start misjudges one that turns near it):
    # not informed. One another statistic reads (the vertical trucks in the ringing) is informed;
    # whether the fit tells it apart is the intervals' test below.
    all_cols = np.arange(len(keys))
    j0 = jac(x0, all_cols)
    twice = [x0 + sign * math.log(2.0) * np.eye(len(keys))[j] for j in all_cols for sign in (1.0, -1.0)]
    for side in (0, 1):  # each side a batch the size of a Jacobian's (a batch is one rollout in memory)
        values_at(twice[side::2])
    at_start = resid(x0)

    def shift(p: np.ndarray) -> float:
        """The largest move from the start of a statistic the twin gives at both points (1e6: none)."""
        r = resid(p)
        return float(np.max(np.abs(r - at_start)[(np.abs(at_start) < 1e5) & (np.abs(r) < 1e5)], initial=0.0))
    moved = np.array([max(shift(p) for p in twice[2 * j:2 * j + 2]) for j in all_cols])
    seen = moved >= MIN_SEEN
    for j in np.flatnonzero(~seen):
        skipped[keys[j]] = (f"the recording's {FITTED[use[j]][1].replace('_', ' ')} and the fit's other "
                            f"statistics move by {moved[j]:.2g} standard errors at most for a factor 2 of it (under "
                            f"{MIN_SEEN:g}): not informed, kept at {start[j]:.6g}")
    free = np.flatnonzero(seen)
    rows = np.concatenate([free, extra_rows])

    def embed(z: np.ndarray) -> np.ndarray:
        x = x0.copy()
        x[free] = z
        return x

    lo, hi = x0 - math.log(10.0), x0 + math.log(10.0)
    xs, fun, sd = x0, np.zeros(0), np.zeros(0)
    stopped: list[str] = []

    def solve(start_at: np.ndarray, j_start: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(the solution, all parameters; its residuals; the finite-difference Jacobian of the
        parameters ``free`` there) from ``start_at``, ``j_start`` the Jacobian of ``free`` at or
        near it. ``least_squares`` steps on a Jacobian kept up to date by Broyden's rank-one
        updates between its accepted points (one simulated point a step, where a finite-difference
        Jacobian costs one a parameter); at its solution the Jacobian is differenced again, and
        while its Gauss–Newton step would still lower the squared residuals by
        :data:`CONVERGED_CHI2` or more (the updates had drifted), the fit goes on from there with
        it, :data:`MAX_JACOBIANS` times at most. At the budget's deadline: the best point
        evaluated so far."""
        tried: list[tuple[float, np.ndarray, np.ndarray]] = []

        def f(z: np.ndarray) -> np.ndarray:
            # room for this point, the Jacobian at the solution and the spread
            if tried and no_room_for(free.size + 2):
                raise _OutOfTime
            r = resid(embed(z))
            tried.append((float(r @ r), z.copy(), r))
            return r

        def broyden(j_at: np.ndarray):
            last: list = [None, None, j_at]  # the last accepted point, its residuals, the Jacobian

            def j(z: np.ndarray) -> np.ndarray:
                r = resid(embed(z))  # evaluated already (memo)
                if last[0] is not None:
                    dz, df = z - last[0], r - last[1]
                    if float(dz @ dz) > 0:
                        last[2] = last[2] + np.outer(df - last[2] @ dz, dz) / float(dz @ dz)
                last[0], last[1] = z.copy(), r
                return last[2]
            return j

        z, j_at = start_at[free], j_start
        for refreshed in range(MAX_JACOBIANS + 1):
            try:
                sol = optimize.least_squares(f, z, jac=broyden(j_at), bounds=(lo[free], hi[free]), method="trf",
                                             x_scale="jac", xtol=1e-3, ftol=1e-4, max_nfev=MAX_STEPS)
            except _OutOfTime:
                _, zb, r = min(tried, key=lambda t: t[0])  # least_squares evaluates its start first
                stopped.append(f"the fit stopped at the budget's deadline after {sims[0]} evaluations (not "
                               f"converged: the best point so far, residual {float(np.sqrt(r @ r)):.2f} standard "
                               "errors); a larger --budget-minutes lets it converge")
                progress(f"layer c: {stopped[-1]}")
                return embed(zb), r, jac(embed(zb), free)
            z, fun_z = sol.x, sol.fun
            j_at = jac(embed(z), free)
            step = np.linalg.lstsq(j_at, -fun_z, rcond=None)[0]
            gain = float(fun_z @ fun_z - np.sum((fun_z + j_at @ step) ** 2))
            if gain < CONVERGED_CHI2 or refreshed == MAX_JACOBIANS or no_room_for(free.size + 3):
                break
            progress(f"layer c: the Jacobian at the solution predicts {gain:.2g} lower squared residuals: "
                     "fitted on from there with it")
        return embed(z), fun_z, j_at

    def second_start(xs: np.ndarray, fun: np.ndarray, J: np.ndarray):
        """The fit again from where each parameter's own statistic alone would meet the recording
        (a Newton step on each, ``J``'s diagonal, from the solution ``xs``, residuals ``fun``), and
        the better of the two solutions. On a heavy axis the vertical trucks also move the tracking
        gain, the ringing and the ripple: the joint steps can settle far off the vertical mode."""
        own = np.diag(J[:free.size])
        z1 = xs[free] - np.divide(fun[:free.size], own, out=np.zeros(free.size), where=own != 0)
        x1 = embed(np.clip(z1, lo[free], hi[free]))
        progress(f"layer c: the fit ended {float(np.max(np.abs(fun))):.1f} standard errors from the recording: "
                 "fitted again from where each parameter's own statistic would meet it")
        n_stopped = len(stopped)
        x2, fun2, J2 = solve(x1, jac(x1, free))
        better = float(fun2 @ fun2) < float(fun @ fun)
        if not better:
            del stopped[n_stopped:]  # the deadline cut the second fit, not the solution kept
        progress(f"layer c: squared residuals {float(fun @ fun):.3g} from the first start, {float(fun2 @ fun2):.3g} "
                 f"from the second: the {'second' if better else 'first'} kept")
        return (x2, fun2, J2) if better else (xs, fun, J)

    if free.size:
        xs, fun, J = solve(x0, j0[np.ix_(rows, free)])
        if float(np.max(np.abs(fun))) > RESTART_SE and not no_room_for(2 * (free.size + 1) + 1):
            xs, fun, J = second_start(xs, fun, J)
        # the delta method with the statistics' full covariance: one regression gives J and
        # c_v, and a machine's draw moves them together, so their errors correlate
        J = J * se[rows][:, None]  # d(statistic)/d(log p), the statistics' units
    # the machine-to-machine scatter at the solution (it grows with the ripple, the drags, the
    # noise): the spread's seeds again, with layer (b)'s first correction set
    first: dict[str, float] = {}
    if sensors:
        inst0: dict[str, list[float]] = {}
        for r in spread:
            for k, v in r[2].items():
                inst0.setdefault(k, []).append(float(v))
        first = {v.key: v.value for v in corrected_sensor_values(
            sensors, {k: float(f"{m.value:.6g}") for k, m in sensors.items()}, inst0)}
        extra.update(first)
    final = run([xs], seeds)
    if free.size:
        spread_all = np.array([r[0] for r in final])[:, stat_idx]
        own_all = np.nan_to_num(real_se[stat_idx] ** 2 + np.nan_to_num(sim_se, nan=0.0) ** 2, nan=0.0)

        def solver(J: np.ndarray) -> np.ndarray:
            """The linear map from the statistics ``rows`` to log p of the parameters ``free``
            that the weighted least-squares fit is near its solution: (JᵀWJ)⁻¹JᵀW, W the inverse
            squared standard errors (J⁻¹ when there are no extra statistics); inf when JᵀWJ is
            singular."""
            jw = J.T / se[rows] ** 2
            try:
                return np.linalg.solve(jw @ J, jw)
            except np.linalg.LinAlgError:
                return np.full((J.shape[1], J.shape[0]), np.inf)

        def deltas(J: np.ndarray) -> np.ndarray:
            """The delta method's covariance of log p for the parameters ``free`` (inf when J
            is singular): the sandwich through :func:`solver`."""
            vals = spread_all[:, rows]
            ok = np.all(np.isfinite(vals), axis=1)
            cov_seed = np.cov(vals[ok].T, ddof=1).reshape(rows.size, rows.size) if ok.sum() > 2 else 0.0
            cov_stat = np.diag(own_all[rows]) + cov_seed * (1 + 1 / FIT_SEEDS)
            jinv = solver(J)
            if not np.all(np.isfinite(jinv)):
                return np.full((free.size, free.size), np.inf)
            return jinv @ cov_stat @ jinv.T

        def marginal(J: np.ndarray):
            """(the delta method's covariance of log p of the parameters ``free``; their standard
            deviations; the same with the span of the parameters kept at their start added, the
            intervals being marginal, not conditional on the kept values; a = -J_ff^-1 J_fk, how
            the fitted ones move with the kept ones in the linearised fit (J_fk from the first
            Jacobian); the kept ones' prior covariance (PRIOR_FACTOR); the kept indices)."""
            cov = deltas(J)
            sd = np.sqrt(np.clip(np.diag(cov), 0, None))
            kept = np.array([j for j in range(len(keys)) if j not in set(free.tolist())], dtype=int)
            prior = np.diag([(math.log(PRIOR_FACTOR[keys[j]]) / Z90) ** 2 for j in kept])
            if not kept.size:
                return cov, sd, sd, np.zeros((free.size, 0)), prior, kept
            j_fk = j0[np.ix_(rows, kept)] * se[rows][:, None]
            a = -solver(J) @ j_fk
            return cov, sd, np.sqrt(sd ** 2 + (a ** 2) @ np.diag(prior)), a, prior, kept

        cov, sd, sd_all, a, prior, kept = marginal(J)
        # Not told apart: a parameter whose 90 % interval is wider than its prior span says less
        # than the default: kept at its start, the widest against its prior first, the others
        # fitted again. The interval counts what it owes to the parameters kept at their start
        # (their prior span through -J_ff^-1 J_fk).
        def over_prior(sds: np.ndarray) -> np.ndarray:
            return T90 * sds / np.array([math.log(PRIOR_FACTOR[keys[j]]) for j in free])
        while free.size and not float(np.max(over_prior(sd_all))) <= 1.0:
            w = int(np.argmax(over_prior(sd_all)))
            j = int(free[w])
            stat_name = FITTED[use[j]][1].replace("_", " ")
            prior_says = f"wider than the factor {PRIOR_FACTOR[keys[j]]:g} of its prior span"
            if over_prior(sd)[w] <= 1.0:
                movers = [keys[k].split(".")[-1] for k in kept[np.argsort(-np.abs(a[w]))][:2]]
                skipped[keys[j]] = (f"not told apart from {', '.join(movers)} (kept at the twin's default): "
                                    f"its statistic, the recording's {stat_name}, moves with them as well, and "
                                    f"their span would put its 90 % interval at a factor "
                                    f"{math.exp(min(T90 * float(sd_all[w]), 50.0)):.3g} either side, {prior_says}: "
                                    f"kept at {start[j]:.6g}")
            else:
                others = [keys[k].split(".")[-1] for k in free if k != j]
                why = f"moves with {', '.join(others)} as well" if others else "does not pin it down"
                skipped[keys[j]] = (f"not told apart jointly: its 90 % interval would span a factor "
                                    f"{math.exp(min(T90 * float(sd[w]), 50.0)):.3g} either side, {prior_says} (its "
                                    f"statistic, the recording's {stat_name}, {why}): kept at {start[j]:.6g}")
            free = np.delete(free, w)
            rows = np.concatenate([free, extra_rows])
            if not free.size:
                xs, fun = x0.copy(), np.zeros(0)
                break
            keep = np.delete(np.arange(J.shape[1]), w)  # J's columns of the others
            keep_rows = np.delete(np.arange(J.shape[0]), w)  # its rows but the kept one's statistic
            if no_room_for(free.size + 3):  # a refit's steps and the Jacobian at its solution
                # No time left to fit the rest again before the budget's deadline: the linearised
                # fit instead. The kept parameter back at its start moves the others' statistics
                # by J[:, w]·Δ; the others move by -J_ff⁻¹·J[:, w]·Δ to answer it, and their
                # Jacobian is J without the kept one's row and column.
                step = x0[j] - xs[j]
                xs = xs.copy()
                xs[j] = x0[j]
                move = solver(J[np.ix_(keep_rows, keep)]) @ J[keep_rows, w] * step
                if np.all(np.isfinite(move)):  # else the others keep their values
                    xs[free] = np.clip(xs[free] - move, lo[free], hi[free])
                J = J[np.ix_(keep_rows, keep)]
                fun = np.delete(fun, w)
                stopped.append(f"the budget's deadline left no time to fit the others again after {keys[j]} was "
                               "kept at its default: they were moved by the linearised fit instead; a larger "
                               "--budget-minutes fits them again")
                progress(f"layer c: {keys[j]} not told apart jointly; {stopped[-1]}")
            else:
                progress(f"layer c: {keys[j]} not told apart jointly; fitted again without it")
                xs, fun, J = solve(xs, J[np.ix_(keep_rows, keep)] / se[rows][:, None])
                J = J * se[rows][:, None]
            cov, sd, sd_all, a, prior, kept = marginal(J)
        sd = sd_all
    else:
        kept = np.arange(len(keys))
    # the residuals' χ² with the kept parameters' span counted: the misfit test's (misfit.py)
    chi2 = (profiled_chi2(fun, J / se[rows][:, None], j0[np.ix_(rows, kept)], np.diag(prior))
            if free.size and fun.size else float(fun @ fun))
    widened = ""
    # The joint distribution of log p over the fitted and the kept parameters (the fitted ones'
    # part scaled so a Gaussian's 90 % range is the stated interval): what `twin diagnose` draws
    # its twin seeds' parameters from (:mod:`twin.harness.calibration.uncertainty`).
    joint = cov * (T90 / Z90) ** 2 if free.size else np.zeros((0, 0))
    if free.size and kept.size:
        joint = np.block([[joint + a @ prior @ a.T, a @ prior], [(a @ prior).T, prior]])
        widened = ("; the interval includes the span of " + ", ".join(keys[j].split(".")[-1] for j in kept)
                   + ", kept at the twin's default")
    order = [keys[j] for j in (*free, *kept)] if free.size else []
    covariance = ({"keys": order, "log": joint.tolist()} if order and np.all(np.isfinite(joint)) else None)
    values = []
    for jj, j in enumerate(free):
        k, x, i = keys[j], xs[j], use[j]
        stat = FITTED[i][1]
        note = fit_note(stat, len(caps), hours, len(runs), session_h, run_flag, band)
        w = T90 * sd[jj]
        low, high = (float(np.exp(x - w)), float(np.exp(x + w))) if np.isfinite(w) else (None, None)
        values.append(Value(k, float(np.exp(x)), "fitted", low, high, note + widened))
    progress(f"layer c: done in {sims[0]} evaluations, {time.perf_counter() - t0:.1f} s; residual "
             f"{', '.join(f'{r:+.2f}' for r in fun)} standard errors")
    inst: dict[str, list[float]] = {}
    for r in final:
        for k, v in r[2].items():
            inst.setdefault(k, []).append(float(v))
    return FitResult(values, skipped, sims[0], time.perf_counter() - t0, [float(r) for r in fun],
                     [STAT_NAMES[stat_idx[r]] for r in rows][:len(fun)], inst, first, total,
                     stopped[0] if stopped else None, covariance, chi2)



"""Backlash over a campaign: every session estimated (in this process or mapped out), re-zeroed
on the baseline sessions (:class:`CampaignBacklash`, :func:`campaign_backlash`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from analysis.phase2.backlash.estimator import BacklashEstimator
from analysis.phase2.traces import SessionErrorMotions


@dataclass
class CampaignBacklash:
    """Backlash estimates of every session of a campaign against its first usable session.

    Attributes:
        sessions: one :class:`SessionBacklash` per usable session, in hours order (the first is
            the reference, with zero change by construction).
        error_motions: the :class:`SessionErrorMotions` they came from (same order).
        skipped_runs: (session, run, reason) of every run left out.
        skipped_sessions: (session, reason) of every session left out (no usable run).
        estimator: the fitted :class:`BacklashEstimator`.
        baseline_sessions: how many leading sessions define zero change (see
            :func:`rezero_on_baseline`); 1 is the paper's single reference.
        baseline_offset_m: (by shifts, by pitch) subtracted from every raw estimate, m.
        from_cache: how many sessions' error motions came from the cache (``cache``).
    """

    sessions: list
    error_motions: list
    skipped_runs: list
    skipped_sessions: list
    estimator: BacklashEstimator
    baseline_sessions: int = 1
    baseline_offset_m: tuple = (0.0, 0.0)
    from_cache: int = 0


def rezero_on_baseline(sessions: list, k: int) -> tuple[list, tuple[float, float]]:
    """Re-zero the estimates on the mean of the first ``k`` sessions.

    Every estimate is a difference against the reference session, so that session's noise enters
    every later estimate alike (a constant offset with the standard deviation of one session's
    estimate). When the first ``k`` sessions are known to share the initial backlash (before any
    wear, as the paper's first 2500 h), subtracting the mean of their estimates takes that offset
    down by √k. ``k = 1`` leaves the paper's single reference unchanged.

    Args:
        sessions: :class:`SessionBacklash` in hours order, the first being the reference.
        k: number of leading sessions assumed to have the reference's backlash, 1 ≤ k ≤ len.
    Returns:
        The re-zeroed sessions and the (by shifts, by pitch) offsets subtracted, m.
    Raises:
        ValueError: ``k`` outside 1..len(sessions).
    """
    if not 1 <= k <= len(sessions):
        raise ValueError(f"baseline sessions = {k}; expected 1 to {len(sessions)} (the number "
                         "of usable Phase II sessions)")
    if k == 1:
        return list(sessions), (0.0, 0.0)
    base = sessions[:k]
    off_shift = float(np.mean([s.delta_backlash_shift_m for s in base]))
    pitch = [s.delta_backlash_pitch_m for s in base if math.isfinite(s.delta_backlash_pitch_m)]
    off_pitch = float(np.mean(pitch)) if pitch else 0.0
    dofs = sessions[0].delta_backlash_dof_m.keys()
    off_dof = {d: float(np.nanmean([s.delta_backlash_dof_m[d] for s in base])) for d in dofs}
    out = [replace(s, delta_backlash_shift_m=s.delta_backlash_shift_m - off_shift,
                   delta_backlash_pitch_m=s.delta_backlash_pitch_m - off_pitch,
                   delta_backlash_dof_m={d: v - off_dof.get(d, 0.0)
                                         for d, v in s.delta_backlash_dof_m.items()})
           for s in sessions]
    return out, (off_shift, off_pitch)


def estimator_for(m, spec: str | None = None, **params) -> BacklashEstimator:
    """A backlash estimator for the axis of an open ``measurements.h5``: when the estimator takes
    them, travel L and lead p of Eq. 9 from the axis contract (``/@axis.travel_mm``,
    ``/@axis.lead_mm``, required: a missing one raises
    :class:`analysis.dataset.axis.MissingAxisKey` naming it); ``spec``: a registered backlash
    estimator or ``module:Class`` (default: the registered default, the paper's); ``params``:
    further parameters (e.g. ``stationary="E_XX"``), which take precedence."""
    from analysis.base import registry
    from analysis.dataset.axis import axis_of

    kind = "backlash_estimators"
    entry = registry.get(kind, spec) if spec else registry.default(kind)
    axis = axis_of(m)
    need = "the Phase II backlash estimate (Eq. 9: travel L and lead p)"
    for key, name in (("travel_mm", "travel_m"), ("lead_mm", "lead_m")):
        if name not in params and registry.accepts(entry.factory, name):
            params[name] = axis.require(key, need) * 1e-3
    return registry.create(kind, spec or entry.name, **params)


def session_error_motions_task(path: str, session: str, on_bad_run: str,
                               error_motion_kw: dict) -> tuple[SessionErrorMotions | None, str]:
    """The error motions of one session read from the ``measurements.h5`` at ``path``: the piece
    of :func:`campaign_backlash` a worker process runs (picklable arguments, opens the file
    itself). Returns ``(error motions, "")``, or ``(None, message)`` when the session cannot be
    used (the :class:`analysis.dataset.DatasetError` it raised)."""
    from analysis.dataset import DatasetError, open_measurements
    from analysis.phase2.error_motions import session_error_motions

    with open_measurements(path) as m:
        try:
            return session_error_motions(m, session, on_bad_run=on_bad_run, **error_motion_kw), ""
        except DatasetError as exc:
            return None, str(exc)


def campaign_backlash(m, *, on_bad_run: str = "skip", estimator: BacklashEstimator | None = None,
                      progress=None, baseline_sessions: int = 1, map_sessions=None,
                      cache=None, **error_motion_kw) -> CampaignBacklash:
    """Error motions (:func:`analysis.phase2.error_motions.session_error_motions`) and backlash
    estimates for every Phase II session of an open ``measurements.h5``.

    Args:
        m: :class:`analysis.dataset.Measurements`.
        on_bad_run: "skip" (a bad run is left out and reported) or "raise" (the first bad run
            raises :class:`analysis.dataset.DatasetError` naming session, run and channel).
        estimator: default :func:`estimator_for` ``m`` (L and p from the axis contract's
            ``travel_mm`` and ``lead_mm``, required).
        progress: optional callable(done, total, session).
        baseline_sessions: leading sessions that define zero change (:func:`rezero_on_baseline`).
        map_sessions: optional ``map_sessions(fn, args)`` returning or yielding ``fn(*a)`` for
            each of ``args`` in order, that runs :func:`session_error_motions_task` for the
            sessions elsewhere (processes, a cluster: the caller's executor); None computes them
            here, one after the other. Each session is estimated as it arrives, so a generator
            lets this work overlap the next sessions'. The results are the same either way.
        cache: optional :class:`analysis.phase2.error_motion_cache.ErrorMotionCache`: sessions
            found there are not computed, the others are stored there once computed.
    Raises:
        DatasetError: a bad run with ``on_bad_run="raise"``, no Phase II session, or no usable
            run in any session.
    """
    from analysis.dataset import DatasetError

    names = m.phase2_sessions()
    if not names:
        raise DatasetError(f"{m.label}: /phase2 has no session; expected at least two sessions")
    if estimator is None:
        estimator = estimator_for(m)
    from analysis.phase2.error_motions import session_error_motions

    def outcome(name):
        try:
            return session_error_motions(m, name, on_bad_run=on_bad_run, **error_motion_kw), ""
        except DatasetError as exc:
            if on_bad_run == "raise":
                raise
            return None, str(exc)

    cached = {}
    if cache is not None:
        cache.for_recording(m.path)
        cached = {n: em for n in names if (em := cache.get(n, on_bad_run, error_motion_kw)) is not None}
    todo = [n for n in names if n not in cached]
    if map_sessions is None or not todo:
        computed = (outcome(name) for name in todo)
    else:
        computed = map_sessions(session_error_motions_task,
                                [(str(m.path.resolve()), name, on_bad_run, error_motion_kw) for name in todo])
    outcomes = _merged(names, cached, iter(computed), cache, on_bad_run, error_motion_kw)
    ems, estimates, skipped_runs, skipped_sessions = [], [], [], []
    for i, (name, (em, why)) in enumerate(zip(names, outcomes, strict=True)):
        if em is None:
            if on_bad_run == "raise":
                raise DatasetError(why)
            skipped_sessions.append((name, why))
        else:
            if not ems:
                estimator.fit(em)  # the first usable session is the reference
            # estimated as it arrives, while the executor computes the next sessions
            estimates.append(estimator.estimate(em))
            ems.append(em)
            skipped_runs.extend((name, run, why) for run, why in em.skipped)
        if progress is not None:
            progress(i + 1, len(names), name)
    if not ems:
        raise DatasetError(f"{m.label}: no Phase II session has a usable run "
                           f"({'; '.join(w for _, w in skipped_sessions)})")
    sessions, offset = rezero_on_baseline(estimates, baseline_sessions)
    return CampaignBacklash(sessions=sessions, error_motions=ems, skipped_runs=skipped_runs,
                            skipped_sessions=skipped_sessions, estimator=estimator,
                            baseline_sessions=baseline_sessions, baseline_offset_m=offset,
                            from_cache=len(cached))


def _merged(names, cached: dict, computed, cache, on_bad_run: str, options: dict):
    """(error motions, why) of every session of ``names`` in order: from ``cached`` where it is,
    else the next of ``computed`` (stored in ``cache`` when usable)."""
    for name in names:
        if name in cached:
            yield cached[name], ""
            continue
        em, why = next(computed)
        if em is not None and cache is not None:
            cache.put(em, on_bad_run, options)
        yield em, why

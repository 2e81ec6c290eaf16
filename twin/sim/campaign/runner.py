"""The resumable, parallel runner of a campaign: every unit not yet stored simulated on an executor
(this process, local processes or Dask) while the files are assembled (:func:`simulate_campaign`),
or several campaigns of one plan with batched rollouts in this process
(:func:`simulate_campaigns_batched`; :func:`simulate_campaigns_runaways` goes on past the ones
that run away); the claim of an output directory by one scenario.

Resuming: each finished unit is stored as its own part file (atomic rename, see
:class:`twin.sim.parts.PartStore`); a rerun skips the parts that exist and assembles
``measurements.h5`` and ``truth.h5`` from all parts at the end.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from analysis.base.files import write_json
from twin.sim.campaign.assembly import ASSEMBLY_ORDER, _Assembler, assemble
from twin.sim.campaign.planning import Unit, plan
from twin.sim.campaign.units import run_unit, run_unit_batch
from twin.sim.geometry import RailRangeError
from twin.sim.parts import PartStore
from twin.sim.scenario import Scenario
from twin.sim.simulate import SimulationDiverged


class CampaignDirectoryError(ValueError):
    """The output directory holds the parts of a different scenario."""


class CampaignInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`simulate_campaign`: the queued units were cancelled and the running
    ones stopped; ``done`` of ``total`` units are stored as parts (a rerun resumes from them),
    ``cancelled`` were not started or were stopped unfinished."""

    def __init__(self, done: int, total: int, cancelled: int):
        super().__init__(f"interrupted: {done} of {total} units finished")
        self.done, self.total, self.cancelled = done, total, cancelled


def _stored(store: PartStore, units: list[Unit]) -> int:
    """How many of ``units`` are stored as parts (part files appear complete, by atomic rename)."""
    names = {kind: set(store.names(kind)) for kind in {u.kind for u in units}}
    return sum(u.name in names[u.kind] for u in units)


def _claim(out: Path, s: Scenario) -> None:
    """Record the scenario in ``out/.parts/scenario.json``; refuse to mix with another one.

    Resuming reuses stored parts, which is only right for the very same scenario (all keys,
    overrides and seed)."""
    import json

    manifest = out / ".parts" / "scenario.json"
    mine = json.loads(s.to_json())
    if manifest.exists():
        theirs = json.loads(manifest.read_text())
        if theirs != mine:
            diff = sorted(_diff_keys(theirs, mine))
            raise CampaignDirectoryError(
                f"{out} holds a campaign of another scenario (differing keys: "
                f"{', '.join(diff[:8])}{' ...' if len(diff) > 8 else ''}); its finished parts "
                "cannot be reused. Choose a new output directory, or delete this one.")
        return
    write_json(manifest, mine, sort_keys=True)


def _diff_keys(a, b, prefix: str = "") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in set(a) | set(b):
            out += _diff_keys(a.get(k), b.get(k), f"{prefix}{k}.")
        return out
    return [] if a == b else [prefix.rstrip(".")]


def simulate_campaign(s: Scenario, out_dir: str | Path, workers: int | None = None,
                      on_progress: Callable[[int, int, str], None] | None = None,
                      scheduler: str | None = None) -> dict:
    """Simulate every unit of the campaign not yet stored, then assemble the two files.

    Args:
        s: the scenario. out_dir: campaign directory (created).
        workers: local processes (default: ``TWIN_WORKERS`` or all local cores,
            :func:`analysis.base.executors.default_processes`; 1 runs in this process).
        on_progress: called as (done, total, unit name) after each unit.
        scheduler: address of a running Dask scheduler to send the units to instead
            (:mod:`analysis.base.executors`); its workers must see ``out_dir`` at the same path.
    Returns:
        {"units": n, "simulated": n_new, "skipped": n_existing, "executor": where they ran}.

    Raises:
        analysis.base.executors.ExecutorError: no scheduler answers at ``scheduler``.
        CampaignInterrupted: on Ctrl-C (KeyboardInterrupt), after cancelling the queued units and
            stopping the running ones; the finished units stay stored.
    """
    from analysis.base.executors import make_executor

    out = Path(out_dir).resolve()  # the workers (possibly elsewhere) get absolute paths
    out.mkdir(parents=True, exist_ok=True)
    _claim(out, s)
    store = PartStore(out)
    store.remove_temporaries()
    units = plan(s)
    todo = [u for u in units if not store.has(u.kind, u.name)]
    done = len(units) - len(todo)
    if on_progress:
        on_progress(done, len(units), "")
    payload = s.to_json()
    # In the order the assembly reads them, which starts on the files as soon as the first parts
    # are stored (_Assembler); the tail this leaves unbalanced is at most one Phase II session.
    todo.sort(key=lambda u: ASSEMBLY_ORDER.index(u.kind))
    processes = 1 if len(todo) <= 1 and scheduler is None else workers
    assembler = _Assembler(s, out, units, stored={u.name for u in units} - {u.name for u in todo})
    with make_executor(processes, scheduler=scheduler, prefix="unit") as ex:
        try:
            futures = [ex.submit(run_unit, payload, u, str(out), key=u.name) for u in todo]
            if not ex.in_process:
                assembler.start()  # in this process's spare time while the workers simulate
            for fut in ex.completed(futures):
                name = fut.result()
                assembler.stored(name)
                done += 1
                if on_progress:
                    on_progress(done, len(units), name)
        except KeyboardInterrupt:
            assembler.abandon()
            ex.interrupt()
            kept = _stored(store, units)
            raise CampaignInterrupted(kept, len(units), len(units) - kept) from None
        except BaseException:
            assembler.abandon()
            raise
        where = ex.description
    assembler.finish()
    return {"units": len(units), "simulated": len(todo), "skipped": len(units) - len(todo),
            "executor": where}


def simulate_campaigns_batched(scenarios: list[Scenario], out_dirs: list[str | Path]) -> None:
    """Simulate several campaigns of the same plan in this process with batched rollouts
    (:func:`run_unit_batch`): the same files as :func:`simulate_campaign` of each, unit for unit
    (tests/test_campaign.py). Parts already stored are kept; a campaign whose plan differs from
    the first one's raises ValueError."""
    units = plan(scenarios[0])
    outs = [Path(d) for d in out_dirs]
    for s, out in zip(scenarios, outs, strict=True):
        if plan(s) != units:
            raise ValueError(f"simulate_campaigns_batched: scenario {s.name!r} (seed {s.seed}) has "
                             f"another plan than {scenarios[0].name!r}; batch only campaigns of "
                             "the same plan")
        out.mkdir(parents=True, exist_ok=True)
        _claim(out, s)
    payloads = [s.to_json() for s in scenarios]
    stores = [PartStore(out) for out in outs]
    for st in stores:
        st.remove_temporaries()
    for u in units:
        todo = [i for i, st in enumerate(stores) if not st.has(u.kind, u.name)]
        if todo:
            try:
                run_unit_batch([payloads[i] for i in todo], u, [str(outs[i]) for i in todo])
            except SimulationDiverged as exc:  # its items: positions in ``scenarios``
                raise SimulationDiverged(exc.args[0], [todo[i] for i in exc.items], exc.t_s) from exc
    for s, out in zip(scenarios, outs, strict=True):
        assemble(s, out, units)


def simulate_campaigns_runaways(scenarios: list[Scenario], out_dirs: list[str | Path]) -> dict[int, str]:
    """:func:`simulate_campaigns_batched`, and when a campaign of the batch runs away (a
    :class:`~twin.sim.geometry.RailRangeError`: its simulation diverged,
    :class:`~twin.sim.simulate.SimulationDiverged`, or its carriage left the rails: an unstable
    set of parameters) each campaign alone. Returns {position in ``scenarios``: why} of those
    that ran away (their directories may hold parts of the units before); the others are
    simulated."""
    try:
        simulate_campaigns_batched(scenarios, out_dirs)
        return {}
    except RailRangeError:
        pass
    ran_away: dict[int, str] = {}
    for i, (s, d) in enumerate(zip(scenarios, out_dirs, strict=True)):
        try:
            simulate_campaigns_batched([s], [d])
        except RailRangeError as exc:
            ran_away[i] = str(exc)
    return ran_away

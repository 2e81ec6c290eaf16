"""The assembly of a campaign's parts into ``measurements.h5`` and ``truth.h5`` (:func:`assemble`,
with the truth timeline of the injected state), and the thread that runs it beside the
simulation, reading each part as soon as its unit is stored (:class:`_Assembler`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from analysis import dataset as ds
from twin.sim.campaign.planning import Unit
from twin.sim.campaign.state import condition_at, onset_hours
from twin.sim.model import stiffness_of
from twin.sim.parts import PartStore
from twin.sim.scenario import Scenario, nominal_axis_description, to_axis


def _timeline(s: Scenario, units: list[Unit]) -> dict[str, np.ndarray]:
    """Truth timeline: the injected state every 12 h and at every unit's hours."""
    grid = np.arange(0.0, s.campaign.total_hours + 1e-9, 12.0)
    hours = np.unique(np.concatenate([grid, [u.hours for u in units]]))
    axis = to_axis(s)
    conds = [condition_at(s, h) for h in hours]
    return {"hours": hours,
            "preload_N": np.array([c.mech.preload for c in conds]),
            "backlash_um": np.array([c.mech.backlash * 1e6 for c in conds]),
            "axial_stiffness_N_per_m": np.array([stiffness_of(axis, c.mech)["axial"] for c in conds]),
            "drag_torque_Nm": np.array([axis.screw.drag_torque(c.mech.preload) for c in conds]),
            "temperature_rise_K": np.array([c.temperature_rise for c in conds])}


def phase2_item(s: Scenario, name: str, attrs: dict, data: dict, dattrs: dict) -> tuple:
    """A stored Phase II part as the ``(session_name, session_attrs, runs)`` item of
    :func:`analysis.dataset.assemble_measurements` (the runs with the routine's attributes)."""
    runs = sorted({k.split("/")[0] for k in data if k.startswith("r")})
    return (name, {"hours": attrs["hours"]},
            [(r, {"speeds_mm_s": list(s.phase2.speeds_mm_s), "accel_mm_s2": s.phase2.accel_mm_s2,
                  "start_mm": s.phase2.start_mm, "end_mm": s.phase2.end_mm,
                  "dwell_s": s.phase2.dwell_s},
              {k.split("/")[1]: data[k] for k in data if k.startswith(r + "/")},
              {k.split("/")[1]: dattrs.get(k, {}) for k in data if k.startswith(r + "/")})
             for r in runs])


#: The order in which :func:`assemble` reads the parts, and so the order in which
#: :func:`simulate_campaign` computes them (the assembly follows the simulation).
ASSEMBLY_ORDER = ("dial", "phase1", "phase2")


def assemble(s: Scenario, out_dir: Path, units: list[Unit],
             wait: Callable[[Unit], None] | None = None) -> None:
    """Write measurements.h5 and truth.h5 from the stored parts, reading them kind by kind in
    :data:`ASSEMBLY_ORDER` and by name within a kind. ``wait(unit)``, if given, is called before
    each part is read and returns once that part is stored (or raises to abandon the assembly:
    nothing is written then), so the assembly can run while the units are still computed."""
    store = PartStore(out_dir)
    by_kind = {k: [u for u in units if u.kind == k] for k in ASSEMBLY_ORDER}

    def read(u: Unit, prefix: str = ""):
        if wait is not None:
            wait(u)
        return store.read(u.kind, u.name, prefix)

    def phase1_items():
        for u in by_kind["phase1"]:
            attrs, data, _ = read(u)
            yield u.name, attrs, data

    def phase2_items():
        for u in by_kind["phase2"]:
            yield phase2_item(s, u.name, *read(u))

    dial_h, dial_b = [], []
    for u in by_kind["dial"]:
        attrs, _, _ = read(u)
        dial_h.append(attrs["hours"])
        dial_b.append(attrs["backlash_um"])
    ds.assemble_measurements(out_dir / "measurements.h5", nominal_axis_description(s),
                             phase1_items(), phase2_items(),
                             (np.asarray(dial_h), np.asarray(dial_b)) if dial_h else None)

    def sessions():
        for u in by_kind["phase2"]:
            attrs, data, _ = store.read("phase2", u.name, "truth/")
            strokes = {k[len("truth/stroke_"):]: v for k, v in data.items() if k.startswith("truth/stroke_")}
            yield u.name, attrs, data["truth/x_m"], data["truth/E"], strokes

    ds.assemble_truth(out_dir / "truth.h5", s.to_json(), onset_hours(s), _timeline(s, units),
                      sessions(), effects={})


class _Abandoned(Exception):
    """The simulation stopped: the assembly running beside it writes nothing."""


class _Assembler:
    """:func:`assemble` in a thread of the campaign's process, reading each part as soon as its
    unit is stored, so that writing the two files overlaps the simulation of the later units
    (the process otherwise only waits for its workers). ``finish`` runs it here if it was not
    started (one process simulating), or waits for it and re-raises what it raised."""

    def __init__(self, s: Scenario, out: Path, units: list[Unit], stored: set[str]):
        import threading

        self._args = (s, out, units)
        self._cond = threading.Condition()
        self._stored, self._abandoned = set(stored), False
        self._thread = threading.Thread(target=self._run, name="assemble", daemon=True)
        self._error: BaseException | None = None

    def _wait(self, unit: Unit) -> None:
        with self._cond:
            self._cond.wait_for(lambda: unit.name in self._stored or self._abandoned)
            if self._abandoned:
                raise _Abandoned

    def _run(self) -> None:
        try:
            assemble(*self._args, wait=self._wait)
        except BaseException as exc:  # noqa: BLE001 - handed to the caller by finish()
            self._error = exc

    def start(self) -> None:
        self._thread.start()

    def stored(self, name: str) -> None:
        with self._cond:
            self._stored.add(name)
            self._cond.notify_all()

    def abandon(self) -> None:
        with self._cond:
            self._abandoned = True
            self._cond.notify_all()
        if self._thread.is_alive():
            self._thread.join()

    def finish(self) -> None:
        if self._thread.ident is None:  # never started
            assemble(*self._args)
            return
        self._thread.join()
        if self._error is not None:
            raise self._error

"""``twin simulate SCENARIO -o DIR --live``: a growing campaign folder, the test source of
``twin monitor``.

The campaign's Phase I captures and Phase II sessions are simulated in time order (operating
hours; at equal hours a capture before a session) and each is published into ``DIR/live/`` at
its scaled time: ``(hours - first hours) * 3600 / speedup`` seconds after the first one. A unit
is published as two files, both written to a temporary name and moved into place with an atomic
rename (``os.replace``):

1. ``DIR/live/<seq>-<kind>-<name>.h5``: the unit in the dataset format (a ``measurements.h5``
   holding only that capture in ``/phase1`` or that session in ``/phase2``);
2. then ``DIR/live/<seq>-<kind>-<name>.json``, its manifest (:data:`UNIT_FORMAT`): ``seq``
   (0, 1, 2, ... in time order), ``kind`` ("phase1" or "phase2"), ``name``, ``hours``,
   ``sample`` and ``captures_in_sample`` (Phase I), ``file``, ``bytes`` and ``sha256`` of the
   data file.

**Complete unit**: its manifest exists and the data file has the manifest's size and SHA-256. A
data file without a manifest, or one that does not match it, is being written and is not read
(``twin monitor`` waits for it); any other producer (a DAQ's export, ``twin import``) follows the
same convention by writing its manifest last. ``DIR/live/source.json`` (written first) names
the scenario and the number of units to come; ``DIR/live/end.json`` (written last) says the
source is finished. Afterwards ``DIR/measurements.h5`` and ``DIR/truth.h5`` are assembled as by
``twin simulate``, so the batch verbs can be run on the same campaign. Killed, it resumes: the
published units stay, and the simulation resumes from the stored parts.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from analysis import dataset as ds
from analysis.base.files import read_json, write_json
from analysis.dataset.live import SOURCE_FORMAT, UNIT_FORMAT, UNIT_VERSION, manifest_ok, sha256_of
from twin.sim.campaign import Unit, assemble, phase2_item, plan, run_unit
from twin.sim.campaign.runner import _claim
from twin.sim.parts import PartStore
from twin.sim.scenario import Scenario, nominal_axis_description

__all__ = ["LIVE_DIR", "UNIT_FORMAT", "live_units", "manifest_ok", "publish_unit", "simulate_live",
           "sha256_of"]

LIVE_DIR = "live"


def live_units(s: Scenario) -> list[Unit]:
    """The Phase I captures and Phase II sessions of the campaign in the order they are recorded."""
    order = {"phase1": 0, "phase2": 1}
    return sorted((u for u in plan(s) if u.kind in order), key=lambda u: (u.hours, order[u.kind], u.name))


def publish_unit(s: Scenario, store: PartStore, unit: Unit, seq: int, live_dir: Path) -> dict:
    """Write one stored unit into ``live_dir`` as data file then manifest (module docstring)."""
    stem = f"{seq:06d}-{unit.kind}-{unit.name}"
    data_path = live_dir / f"{stem}.h5"
    axis = nominal_axis_description(s)
    attrs, data, dattrs = store.read(unit.kind, unit.name)
    if unit.kind == "phase1":
        ds.assemble_measurements(data_path, axis, [(unit.name, attrs, data)])
    else:
        ds.assemble_measurements(data_path, axis, (), [phase2_item(s, unit.name, attrs, data, dattrs)])
    manifest = {"format": UNIT_FORMAT, "version": UNIT_VERSION, "seq": seq, "kind": unit.kind,
                "name": unit.name, "hours": unit.hours, "file": data_path.name,
                "bytes": data_path.stat().st_size, "sha256": sha256_of(data_path)}
    if unit.kind == "phase1":
        manifest.update(sample=unit.sample, captures_in_sample=s.captures_per_sample)
    write_json(live_dir / f"{stem}.json", manifest)
    return manifest


def simulate_live(s: Scenario, out_dir: str | Path, speedup: float = 3600.0,
                  on_unit: Callable[[int, int, dict], None] | None = None,
                  sleep: Callable[[float], None] = time.sleep,
                  clock: Callable[[], float] = time.monotonic) -> dict:
    """Simulate the campaign into ``out_dir`` publishing its units live (module docstring).

    speedup: operating hours run this many times faster than real time (3600: an hour a
    second). on_unit(seq, total, manifest) after each publication. Returns {"units": n,
    "published": n_new, "seconds": wall time}.
    """
    out = Path(out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    _claim(out, s)
    store = PartStore(out)
    store.remove_temporaries()
    live = out / LIVE_DIR
    live.mkdir(exist_ok=True)
    for tmp in live.glob(".*.tmp"):
        tmp.unlink(missing_ok=True)
    units = live_units(s)
    if not (live / "source.json").is_file():
        write_json(live / "source.json", {"format": SOURCE_FORMAT, "version": UNIT_VERSION,
                                          "scenario": s.name, "units": len(units),
                                          "captures_per_sample": s.captures_per_sample,
                                          "speedup": speedup})
    payload = s.to_json()
    t_start = clock()
    t0 = h0 = None
    published = 0
    for seq, u in enumerate(units):
        stem = f"{seq:06d}-{u.kind}-{u.name}"
        mpath = live / f"{stem}.json"
        if mpath.is_file() and manifest_ok(live, read_json(mpath, "a live unit's manifest")):
            continue
        if not store.has(u.kind, u.name):
            run_unit(payload, u, str(out))
        if t0 is None:
            t0, h0 = clock(), u.hours
        wait = t0 + (u.hours - h0) * 3600.0 / speedup - clock()
        if wait > 0:
            sleep(wait)
        manifest = publish_unit(s, store, u, seq, live)
        published += 1
        if on_unit:
            on_unit(seq + 1, len(units), manifest)
    everything = plan(s)
    for u in everything:  # the dial-indicator readings, for the assembled campaign
        if not store.has(u.kind, u.name):
            run_unit(payload, u, str(out))
    assemble(s, out, everything)
    write_json(live / "end.json", {"format": SOURCE_FORMAT, "version": UNIT_VERSION,
                                   "units": len(units), "finished": True})
    return {"units": len(units), "published": published, "seconds": clock() - t_start}

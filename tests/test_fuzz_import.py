"""Importer fuzz (issue 31, deliverable 6): 500 cases of a laboratory's small recording (CSV, vendor
CSV with decimal commas, TDMS, MATLAB, MDF; tests/fuzz_imports.py) with one data file or the
import spec damaged, given to ``run_import``.

Every case must end in one of two ways, never with a traceback nor silent garbage:

- refused: :class:`ImportSpecError` or :class:`DatasetError` whose message names a file of the
  lab (the damaged file, the spec, or the campaign being written);
- imported: every run's samples, rate and hours equal those of the undamaged import (to 1e-9
  relative), or are the first ≥ 90 % of its samples (a file cut at a line end by less than the
  import's length tolerance: shorter, but no sample wrong), or the import's warnings name the
  file.

The cases are drawn from a fixed seed; ``FUZZ_IMPORT_N`` changes their number. Figures printed:
outcomes per kind of mutation.
"""

from __future__ import annotations

import json
import os
import traceback

import numpy as np
import pytest

from analysis.dataset import DatasetError, open_measurements
from analysis.ingest import ImportSpecError, run_import
from analysis.ingest.convert import LENGTH_TOLERANCE
from tests.fuzz_imports import FILE_MUTATIONS, KINDS, SPEC_MUTATIONS, build_lab

CHANNELS = ("imu_acc", "imu_gyro", "position_cmd")


def _read(out) -> dict[str, dict]:
    """{source file name: {"hours", "<ch>", "<ch>_fs"}} of an imported campaign."""
    src = json.loads((out / "import.json").read_text())["phase2"]
    res = {}
    with open_measurements(out / "measurements.h5") as m:
        for key, path in src.items():
            s, r = key.split("/")
            run = m.phase2(s, r)
            rec = {"hours": m.session_hours(s)}
            for ch in CHANNELS:
                a = getattr(run, ch, None)
                if a is not None:
                    rec[ch], rec[f"{ch}_fs"] = np.asarray(a), getattr(run, f"{ch}_fs_hz")
            res[os.path.basename(path)] = rec
    return res


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    out = {}
    for kind in KINDS:
        root = tmp_path_factory.mktemp(f"clean-{kind}")
        spec, _ = build_lab(root, kind)
        s = run_import(spec)
        assert s.warnings == [] and s.runs == 4, (kind, s.warnings)
        out[kind] = _read(root / "out")
    return out


def _same(a: dict, b: dict) -> str:
    """'' if run ``a`` (damaged import) equals ``b`` (clean) or is its prefix of ≥ 90 %; else why."""
    if a["hours"] != b["hours"]:
        return f"hours {a['hours']} vs {b['hours']}"
    for ch in CHANNELS:
        if ch not in a:
            continue  # a channel left out is less data, not wrong data
        x, y = a[ch], b[ch]
        if not np.isclose(a[f"{ch}_fs"], b[f"{ch}_fs"], rtol=1e-9, atol=0):
            return f"{ch} at {a[f'{ch}_fs']} Hz vs {b[f'{ch}_fs']} Hz"
        if x.shape[1:] != y.shape[1:] or len(x) > len(y) or len(x) < (1 - LENGTH_TOLERANCE) * len(y):
            return f"{ch} shape {x.shape} vs {y.shape}"
        if not np.allclose(x, y[: len(x)], rtol=1e-9, atol=1e-12):
            return f"{ch} values differ"
    return ""


def run_case(i: int, root, clean: dict, rng) -> tuple[str, str, str]:
    """(mutation, outcome, detail) of case ``i``; outcome 'refused', 'same', 'warned' or 'BAD: ...'."""
    kind = KINDS[i % len(KINDS)]
    spec, files = build_lab(root, kind)
    if rng.random() < 0.25:
        mut = SPEC_MUTATIONS[int(rng.integers(len(SPEC_MUTATIONS)))]
        text, what = mut(spec.read_text(), rng)
        spec.write_text(text, encoding="utf-8", errors="surrogateescape")
        name = f"{kind}/{mut.__name__}"
    else:
        muts = FILE_MUTATIONS[kind]
        mut = muts[int(rng.integers(len(muts)))]
        target = files[int(rng.integers(len(files)))]
        what = f"{target.name}: {mut(target, rng)}"
        name = f"{kind}/{mut.__name__}"
    try:
        s = run_import(spec)
    except (ImportSpecError, DatasetError) as e:
        msg = str(e)
        if str(root) not in msg:
            return name, f"BAD: refusal names no file of the lab: {msg[:300]}", what
        return name, "refused", what
    except Exception:  # noqa: BLE001 - what the fuzz is for
        return name, f"BAD: traceback:\n{traceback.format_exc()[-1500:]}", what
    got = _read(s.output)
    bad = []
    for f, rec in got.items():
        why = _same(rec, clean[kind][f]) if f in clean[kind] else "a file the clean import does not have"
        if why and not any(f in w for w in s.warnings or []):
            bad.append(f"{f}: {why}")
    if bad:
        return name, f"BAD: silent garbage: {'; '.join(bad)}", what
    return name, "warned" if s.warnings else "same", what


def test_fuzz_import_500(clean, tmp_path):
    n = int(os.environ.get("FUZZ_IMPORT_N", "500"))
    rng = np.random.default_rng(31)
    rows = [run_case(i, tmp_path / f"c{i:04d}", clean, rng) for i in range(n)]
    table: dict[str, dict[str, int]] = {}
    for name, outcome, _ in rows:
        key = "BAD" if outcome.startswith("BAD") else outcome
        table.setdefault(name, {}).setdefault(key, 0)
        table[name][key] += 1
    print(f"\nimporter fuzz, {n} cases: outcomes per mutation")
    for name in sorted(table):
        print(f"  {name:32s} {table[name]}")
    bad = [f"{name} [{what}] {outcome}" for name, outcome, what in rows if outcome.startswith("BAD")]
    if bad:
        pytest.fail("\n".join(bad[:10]), pytrace=False)
    outcomes = {o for _, o, _ in rows}
    assert {"refused", "warned"} <= outcomes


@pytest.mark.parametrize("kind", KINDS)
def test_twin_import_of_a_cut_file_exits_2_without_a_traceback(tmp_path, kind):
    """The command line on each reader's file cut in half: exit 2, one message naming the file,
    nothing of the readers' own logs or tracebacks (asammdf, npTDMS) on stderr."""
    from tests.conftest import run_twin

    spec, files = build_lab(tmp_path, kind)
    data = files[1].read_bytes()
    files[1].write_bytes(data[: len(data) // 2])
    r = run_twin("import", spec, check=False)
    assert r.returncode == 2, r.stderr
    text = " ".join(r.stderr.split())
    assert "Traceback" not in r.stderr and "Exception ignored" not in r.stderr and "WARNING" not in r.stderr
    assert f"error: {files[1]}: " in text

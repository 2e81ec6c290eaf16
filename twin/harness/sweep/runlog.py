"""The sweep's output directory: manifest (a restart must match it), append-only log, per-point results."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from analysis.base.files import write_json
from twin.harness.sweep.plan import Plan, Task
from twin.harness.sweep.schema import LOG_NAME, MANIFEST_NAME, RESULT_NAME, SweepError

# ---------------------------------------------------------------------------------------------
# Output directory: manifest, records, log


def _diff(a: Any, b: Any, prefix: str = "") -> list[tuple[str, Any, Any]]:
    """(dotted key, a, b) where ``a`` and ``b`` differ; lists of equal length item by item."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b), key=str):
            out += _diff(a.get(k), b.get(k), f"{prefix}.{k}" if prefix else str(k))
        return out
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b) and a != b and \
            any(isinstance(x, (dict, list)) for x in a):
        out = []
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            out += _diff(x, y, f"{prefix}[{i}]")
        return out
    return [] if a == b else [(prefix, a, b)]


def _claim(out: Path, plan: Plan) -> None:
    """Write OUT/sweep.json, or check that OUT holds this very sweep (else SweepError)."""
    path = out / MANIFEST_NAME
    mine = json.loads(json.dumps(plan.manifest()))
    if path.exists():
        theirs = json.loads(path.read_text())
        diffs = [d for d in _diff(theirs, mine) if d[0] != "sweep_file"]
        if diffs:
            shown = "; ".join(f"`{k}`: {a!r} there, {b!r} in {plan.path}" for k, a, b in diffs[:6])
            more = f" (and {len(diffs) - 6} more)" if len(diffs) > 6 else ""
            raise SweepError(
                f"{out} holds the results of another sweep ({theirs.get('sweep_file')}); "
                f"differences: {shown}{more}. Its finished points cannot be reused: choose a new "
                "output directory (-o), or delete this one.")
        return
    out.mkdir(parents=True, exist_ok=True)
    write_json(path, mine)



def _append_log(out: Path, rec: dict) -> None:
    """Append one JSON line (after a newline if a killed writer left a partial line)."""
    path = out / LOG_NAME
    with open(path, "a+b") as f:
        f.seek(0, os.SEEK_END)
        if f.tell():
            f.seek(-1, os.SEEK_END)
            if f.read(1) != b"\n":
                f.write(b"\n")
        f.write((json.dumps(rec, allow_nan=False) + "\n").encode())
        f.flush()
        os.fsync(f.fileno())


def read_log(out: str | Path) -> list[dict]:
    """The log's records (a partial line left by a killed writer is skipped)."""
    path = Path(out) / LOG_NAME
    recs = []
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                recs.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return recs


def point_dir(out: Path, task: Task) -> Path:
    return out / "points" / task.id


def read_result(out: Path, task: Task) -> dict | None:
    path = point_dir(out, task) / RESULT_NAME
    if not path.is_file():
        return None
    try:
        rec = json.loads(path.read_text())
    except json.JSONDecodeError:
        return None
    return rec if rec.get("error") is None else None

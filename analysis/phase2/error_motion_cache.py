"""Sessions' error motions kept on disk: the arrays of :class:`SessionErrorMotions` as one npz
(:func:`error_motion_arrays`, :func:`error_motions_from`; the gate's cache stores its campaigns
so) and :class:`ErrorMotionCache`, which ``twin backlash --cache DIR`` uses so that a rerun with
other estimator parameters computes no session's error motions again.

A cached session is found by a SHA-256 over the recording's bytes (``measurements.h5``), the
session's name, the bad-run policy, the error-motion options and this package's version: a
changed recording, option or release misses and is computed anew.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from analysis.base.files import atomic_write, package_version, sha256_of
from analysis.phase2.traces import DirectionalTraces, SessionErrorMotions

__all__ = ["ErrorMotionCache", "error_motion_arrays", "error_motions_from", "frozen"]

FORMAT = 1  # the layout of error_motion_arrays; part of the cache key


def error_motion_arrays(ems: list[SessionErrorMotions]) -> dict[str, np.ndarray]:
    """The sessions' error motions as named arrays (for ``np.savez``): ``sessions``, ``hours``
    (h), ``position_reference`` (one per session), and per session index i ``i/runs``,
    ``i/skipped`` (k, 2) of (run, reason), ``i/{combined,slow}/{x_m,forward,reverse}`` (m, rad)
    and ``.../band_m`` where it is known. Read back by :func:`error_motions_from`."""
    arrays: dict[str, np.ndarray] = {
        "sessions": np.array([e.session for e in ems]), "hours": np.array([e.hours for e in ems], dtype=float),
        "position_reference": np.array([e.position_reference for e in ems])}
    for i, e in enumerate(ems):
        arrays[f"{i}/runs"] = np.array(e.runs, dtype=str)
        arrays[f"{i}/skipped"] = np.array(e.skipped, dtype=str).reshape(-1, 2)
        for part in ("combined", "slow"):
            tr = getattr(e, part)
            arrays[f"{i}/{part}/x_m"] = tr.x_m
            arrays[f"{i}/{part}/forward"] = tr.forward
            arrays[f"{i}/{part}/reverse"] = tr.reverse
            if tr.band_m is not None:
                arrays[f"{i}/{part}/band_m"] = tr.band_m
    return arrays


def frozen(a: np.ndarray) -> np.ndarray:
    """A read-only copy of ``a``."""
    a = np.array(a)
    a.setflags(write=False)
    return a


def error_motions_from(z, read_only: bool = False) -> list[SessionErrorMotions]:
    """The sessions of an open npz (or any mapping) written from :func:`error_motion_arrays`;
    ``read_only`` makes every array read-only (the gate: a method that writes into its input
    fails its check instead of changing what the next method is given)."""
    keep = frozen if read_only else np.asarray
    ems = []
    for i, name in enumerate(z["sessions"]):
        parts = {part: DirectionalTraces(keep(z[f"{i}/{part}/x_m"]), keep(z[f"{i}/{part}/forward"]),
                                         keep(z[f"{i}/{part}/reverse"]),
                                         keep(z[f"{i}/{part}/band_m"]) if f"{i}/{part}/band_m" in z else None)
                 for part in ("combined", "slow")}
        skipped = z[f"{i}/skipped"] if f"{i}/skipped" in z else np.empty((0, 2), dtype=str)
        ems.append(SessionErrorMotions(session=str(name), hours=float(z["hours"][i]),
                                       runs=tuple(str(r) for r in z[f"{i}/runs"]),
                                       combined=parts["combined"], slow=parts["slow"],
                                       skipped=tuple((str(r), str(w)) for r, w in skipped),
                                       position_reference=str(z["position_reference"][i])))
    return ems


class ErrorMotionCache:
    """One npz per session under ``root``, named by its key (see the module docstring).

    ``for_recording(path)`` hashes the recording once; ``get(session, on_bad_run, options)``
    returns the cached :class:`SessionErrorMotions` or None, ``put(...)`` stores one (written
    to a temporary file and moved into place: a killed run leaves no half file, and concurrent
    runs may share ``root``)."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        self._recording: str | None = None

    def for_recording(self, path: str | Path) -> ErrorMotionCache:
        self._recording = sha256_of(path)
        return self

    def _path(self, session: str, on_bad_run: str, options: dict) -> Path:
        if self._recording is None:
            raise RuntimeError("ErrorMotionCache: call for_recording(path) first")
        what = json.dumps({"recording": self._recording, "session": session, "on_bad_run": on_bad_run,
                           "options": options, "format": FORMAT, "version": package_version()},
                          sort_keys=True, default=str)
        return self.root / f"{hashlib.sha256(what.encode()).hexdigest()}.npz"

    def get(self, session: str, on_bad_run: str, options: dict) -> SessionErrorMotions | None:
        path = self._path(session, on_bad_run, options)
        if not path.is_file():
            return None
        try:
            with np.load(path, allow_pickle=False) as z:
                (em,) = error_motions_from(z)
        except (OSError, ValueError, KeyError):  # unreadable: computed again and rewritten
            return None
        return em if em.session == session else None

    def put(self, em: SessionErrorMotions, on_bad_run: str, options: dict) -> None:
        def write(tmp: Path) -> None:
            with open(tmp, "wb") as fh:
                np.savez(fh, **error_motion_arrays([em]))

        atomic_write(self._path(em.session, on_bad_run, options), write)

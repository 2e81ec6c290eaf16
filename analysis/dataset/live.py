"""The live-unit convention: how a growing campaign folder says that a unit (one Phase I
capture or one Phase II session in the dataset format) is complete. Written by
``twin simulate --live`` (and by any DAQ exporter that follows it), read by ``twin monitor``;
docs/monitoring.md describes it.

A unit is a data file ``<seq>-<kind>-<name>.h5`` and, written after it, its manifest
``<seq>-<kind>-<name>.json`` (:data:`UNIT_FORMAT`) with the data file's size and SHA-256: the
unit is complete when the manifest exists and the data file matches it (:func:`manifest_ok`).
"""

from __future__ import annotations

from pathlib import Path

from analysis.base.files import sha256_of

__all__ = ["MANIFEST_KEYS", "SOURCE_FORMAT", "UNIT_FORMAT", "UNIT_VERSION", "manifest_ok", "sha256_of"]

UNIT_FORMAT = "ballscrew-twin/live-unit"
SOURCE_FORMAT = "ballscrew-twin/live-source"
UNIT_VERSION = 1
#: Keys every manifest has (Phase I manifests also ``sample`` and ``captures_in_sample``).
MANIFEST_KEYS = frozenset({"format", "version", "seq", "kind", "name", "hours", "file", "bytes", "sha256"})


def manifest_ok(live_dir: str | Path, manifest: dict) -> bool:
    """True when the manifest's data file (in ``live_dir``) is complete: its size and SHA-256
    are the manifest's."""
    p = Path(live_dir) / manifest["file"]
    try:
        return p.stat().st_size == manifest["bytes"] and sha256_of(p) == manifest["sha256"]
    except OSError:
        return False

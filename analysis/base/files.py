"""Reading and writing the small output files of the analysis and the harness (JSON, PNG, HTML,
HDF5, Parquet): JSON read with an error that names the file, and writes that never leave a
half-written file behind.

Every writer writes a uniquely named temporary file ``.<name>.<random>.tmp`` next to the target
and ``os.replace``-s it into place, so a process killed at any point leaves the previous file or
the new one, and two processes writing the same target never share a temporary file.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import secrets
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["atomic_write", "fsync_path", "json_safe", "read_json", "write_json", "write_text"]


def fsync_path(path: str | os.PathLike) -> None:
    """Flush a file or a directory entry to stable storage."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def atomic_write(path: str | os.PathLike, write: Callable[[Path], Any], *, fsync: bool = False) -> Path:
    """Call ``write(tmp)`` on a temporary path next to ``path``, then move it to ``path``.

    ``write`` creates the file at ``tmp`` (``h5py.File(tmp, "w")``, ``df.to_parquet(tmp)``, ...).
    The parent directory is created. On any exception (KeyboardInterrupt included) the temporary
    file is removed and the exception propagates; ``path`` is untouched. ``fsync`` also flushes
    the file and its directory to stable storage (protects against power loss, not needed
    against killed processes). Returns ``path``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
    try:
        write(tmp)
        if fsync:
            fsync_path(tmp)
        os.replace(tmp, path)
        if fsync:
            fsync_path(path.parent)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def exclusive_lock(path: str | os.PathLike, busy: str, error: type[Exception] = ValueError,
                   wait: Callable[[str], None] | None = None):
    """An exclusive lock on ``path`` (created, its folder too), held while the returned file
    stays open: the kernel releases it when the process dies, even by SIGKILL. When another
    process holds it: raises ``error(busy)``, or with ``wait`` calls ``wait(busy)`` and blocks
    until it is free."""
    import fcntl

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fh = open(path, "a+")  # noqa: SIM115 - held for the caller's life
    try:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        if wait is None:
            fh.close()
            raise error(busy) from None
        wait(busy)
        fcntl.flock(fh, fcntl.LOCK_EX)
    return fh


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def json_safe(obj: Any) -> Any:
    """``obj`` with numpy scalars as Python numbers, tuples as lists and NaN/inf as None (strict
    JSON has no NaN)."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def write_json(path: str | os.PathLike, doc: Any, *, nan_as_null: bool = False, **dumps: Any) -> Path:
    """Write ``doc`` as strict JSON to ``path`` atomically.

    ``nan_as_null`` first passes ``doc`` through :func:`json_safe` (NaN and inf become ``null``);
    without it a non-finite float raises ValueError, because strict JSON readers reject it.
    ``dumps``: keywords of :func:`json.dumps` (default ``indent=1``).
    """
    dumps.setdefault("indent", 1)
    dumps.setdefault("allow_nan", False)
    return write_text(path, json.dumps(json_safe(doc) if nan_as_null else doc, **dumps))


def read_json(path: str | os.PathLike, what: str, *, error: type[Exception] = ValueError,
              missing_ok: bool = False) -> dict | None:
    """The JSON object in ``path``.

    Args:
        path: the file.
        what: what the file should hold, for the message (e.g. "the Phase I detection results
            of `twin detect`").
        error: the exception class raised for a missing (unless ``missing_ok``), unreadable or
            invalid file; the message names the file, the problem and what was expected.
        missing_ok: return None when the file does not exist.

    Returns:
        The parsed object (a dict), or None for a missing file with ``missing_ok``.
    """
    path = Path(path)
    if missing_ok and not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise error(f"{path}: not valid JSON ({exc}); expected {what}; rerun the command that writes it") from None
    except OSError as exc:
        raise error(f"{path}: cannot read it ({exc.strerror}); expected {what}") from None
    if not isinstance(doc, dict):
        raise error(f"{path}: JSON of type {type(doc).__name__}; expected {what} (a JSON object)")
    return doc


def sha256_of(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def package_version() -> str:
    """The installed version of ``ballscrew-twin`` ("unknown" when it is not installed): part of
    the key of what a cache keeps."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ballscrew-twin")
    except PackageNotFoundError:
        return "unknown"

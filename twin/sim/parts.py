"""Resumable campaigns: each finished unit of work in its own atomically written HDF5 file."""

from __future__ import annotations

import os
import re
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from analysis.base.files import atomic_write
from analysis.dataset import DatasetError
from analysis.dataset.attrs import from_attr, write_attrs
from analysis.dataset.h5file import open_h5
from analysis.dataset.validate import NAME_RE, as_str, check_dtype

_KIND_RE = re.compile(r"^[A-Za-z0-9_-]+(/[A-Za-z0-9_-]+)*$")
_PART_FORMAT = "ballscrew-twin/part"
_PART_MARKER = "__part__"


class PartStore:
    """Finished units of work of a campaign, each in its own atomically written HDF5 file.

    A part lives in ``root_dir/.parts/<kind>/<name>.h5``. It is written to a unique temporary
    file ``.<name>.h5.<random>.tmp`` in the same directory and ``os.replace``-d into place, so a
    process killed (even with SIGKILL) at any point leaves either the complete part or no part;
    temporaries are ignored by :meth:`has`, :meth:`names` and :meth:`read`, and
    :meth:`remove_temporaries` deletes them. :meth:`has` also returns False for a part that is
    not a complete, readable part file (e.g. truncated by a disk problem), so it gets recomputed.

    Arrays are stored uncompressed in the dtype given (gzip level 1 saves little on float32
    sensor noise but makes a capture many times slower to write; figures in docs/validation.md)
    and read back bit for bit,
    so a campaign assembled from parts of an interrupted run equals an uninterrupted one.

    ``kind`` is a relative path of names (e.g. ``"phase1"``, ``"phase2/s0007"``), ``name`` a
    file-safe name (e.g. ``"c000123"``); zero-pad numbers so that names sort. Dataset keys may
    contain ``/`` to group datasets (e.g. ``"r0003/imu_acc"``).

    Parameters
    ----------
    root_dir : campaign directory.
    fsync : also flush each part to stable storage before moving it into place (protects against
        power loss, not needed against killed processes; costs time on real disks).

    Example (a campaign runner)::

        store = PartStore(campaign_dir)
        store.remove_temporaries()            # before any writer starts
        for name in capture_names:
            if not store.has("phase1", name):
                store.write("phase1", name, {"hours": h, "sample": s, "fs_hz": 10e3},
                            {"speed": w, "torque": q, "acc1": a1, "acc2": a2})
        phase1 = ((name, attrs, data) for name, attrs, data, _ in store.items("phase1"))
    """

    def __init__(self, root_dir: str | os.PathLike, *, fsync: bool = False):
        self.root_dir = Path(root_dir)
        self.parts_dir = self.root_dir / ".parts"
        self.fsync = fsync

    def _kind_dir(self, kind: str) -> Path:
        if not isinstance(kind, str) or not _KIND_RE.match(kind):
            raise ValueError(f"part kind {kind!r}: expected names of letters, digits, '_', '-' separated by '/'")
        return self.parts_dir / kind

    def path(self, kind: str, name: str) -> Path:
        """Path of the part file ``root_dir/.parts/<kind>/<name>.h5``."""
        if not isinstance(name, str) or not NAME_RE.match(name) or name.endswith(".tmp"):
            raise ValueError(f"part name {name!r}: expected letters, digits, '_', '-', '.' (not starting with '.')")
        return self._kind_dir(kind) / f"{name}.h5"

    def has(self, kind: str, name: str) -> bool:
        """True when the part exists and is a complete, readable part file."""
        p = self.path(kind, name)
        if not p.is_file():
            return False
        try:
            with h5py.File(p, "r") as f:
                return as_str(f.attrs.get(_PART_MARKER)) == _PART_FORMAT
        except OSError:
            return False

    def write(
        self,
        kind: str,
        name: str,
        attrs: Mapping[str, Any],
        datasets: Mapping[str, np.ndarray],
        dataset_attrs: Mapping[str, Mapping[str, Any]] | None = None,
    ) -> Path:
        """Store one finished unit of work atomically; return the part's path.

        ``attrs``: scalars, strings or 1-D lists (no names starting with ``__``);
        ``datasets``: arrays of real numbers, any shape, stored in their dtype;
        ``dataset_attrs``: per-dataset attributes, keyed like ``datasets``.
        An existing part of the same kind and name is replaced.
        """
        final = self.path(kind, name)
        dataset_attrs = dict(dataset_attrs or {})
        for key in attrs:
            if key.startswith("__"):
                raise ValueError(f"part {kind}/{name}: attribute {key!r}: names starting with '__' are reserved")
        arrays = {}
        for key, value in datasets.items():
            if not isinstance(key, str) or not _KIND_RE.match(key):
                raise ValueError(f"part {kind}/{name}: dataset key {key!r}: expected names separated by '/'")
            arr = np.asarray(value)
            if arr.dtype.kind not in "biuf":
                raise ValueError(f"part {kind}/{name}: dataset {key!r} has dtype {arr.dtype}; expected real numbers")
            arrays[key] = arr
        unknown = sorted(set(dataset_attrs) - set(arrays))
        if unknown:
            raise ValueError(f"part {kind}/{name}: dataset_attrs for unknown datasets {unknown}")
        def create(tmp: Path) -> None:
            with h5py.File(tmp, "w") as f:
                write_attrs(f, attrs)
                for key in sorted(arrays):
                    ds = f.create_dataset(key, data=arrays[key])
                    write_attrs(ds, dataset_attrs.get(key))
                f.attrs[_PART_MARKER] = _PART_FORMAT

        atomic_write(final, create, fsync=self.fsync)
        return final

    def read(self, kind: str, name: str, prefix: str = "") -> tuple[dict[str, Any], dict[str, np.ndarray],
                                                                     dict[str, dict[str, Any]]]:
        """Return ``(attrs, datasets, dataset_attrs)`` of a part, arrays in their stored dtype;
        with ``prefix``, only the datasets whose keys start with it (the others are not read).

        ``dataset_attrs`` has an entry only for datasets that have attributes. Raises
        FileNotFoundError for a missing part and :class:`DatasetError` for an unreadable one.
        """
        p = self.path(kind, name)
        label = str(p)
        with open_h5(p, label) as f:
            if as_str(f.attrs.get(_PART_MARKER)) != _PART_FORMAT:
                raise DatasetError(f"{label}: /@{_PART_MARKER} is missing; expected {_PART_FORMAT!r}")
            attrs = {k: from_attr(v) for k, v in f.attrs.items() if k != _PART_MARKER}
            keys: list[str] = []
            f.visititems(lambda k, obj: keys.append(k) if isinstance(obj, h5py.Dataset) else None)
            datasets: dict[str, np.ndarray] = {}
            dattrs: dict[str, dict[str, Any]] = {}
            for key in sorted(k for k in keys if k.startswith(prefix)):
                ds = f[key]
                check_dtype(label, "/" + key, ds.dtype)
                try:
                    datasets[key] = ds[()]
                except OSError as e:
                    raise DatasetError(f"{label}: /{key} could not be read; the file may be corrupt ({e})") from None
                if len(ds.attrs):
                    dattrs[key] = {k: from_attr(v) for k, v in ds.attrs.items()}
        return attrs, datasets, dattrs

    def names(self, kind: str) -> list[str]:
        """Sorted names of the stored parts of ``kind`` (temporaries excluded)."""
        d = self._kind_dir(kind)
        if not d.is_dir():
            return []
        return sorted(
            p.name[:-3] for p in d.iterdir() if p.is_file() and p.name.endswith(".h5") and not p.name.startswith(".")
        )

    def items(self, kind: str) -> Iterator[tuple[str, dict, dict, dict]]:
        """Yield ``(name, attrs, datasets, dataset_attrs)`` for every part of ``kind``, by name."""
        for name in self.names(kind):
            yield (name, *self.read(kind, name))

    def remove_temporaries(self, kind: str | None = None) -> int:
        """Delete leftover temporaries of killed writes (of ``kind``, or all); return how many.

        Call it when no writer is running (e.g. when a campaign starts): it would also delete the
        temporary file of a write in progress.
        """
        base = self.parts_dir if kind is None else self._kind_dir(kind)
        if not base.is_dir():
            return 0
        n = 0
        for p in base.rglob(".*.tmp"):
            p.unlink(missing_ok=True)
            n += 1
        return n


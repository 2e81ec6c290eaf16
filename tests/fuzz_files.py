"""Mutations of a ``measurements.h5`` for the reader fuzzer (tests/test_fuzz_readers.py): each
takes a copy of a good file and damages it in one way a laboratory's file can be damaged or
odd (cut short, flipped bytes, wrong dtype or shape, NaN and inf, absurd values, attributes and
dimensions, soft and external links, items swapped or deleted). Every draw comes from the
generator given, so a seed gives the same mutations."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np


def _datasets(f: h5py.File) -> list[str]:
    keys: list[str] = []
    f.visititems(lambda k, o: keys.append(k) if isinstance(o, h5py.Dataset) else None)
    return sorted(keys)


def _groups(f: h5py.File) -> list[str]:
    keys: list[str] = []
    f.visititems(lambda k, o: keys.append(k) if isinstance(o, h5py.Group) else None)
    return sorted(keys)


def _pick(rng, items):
    return items[int(rng.integers(len(items)))]


def _replace(f: h5py.File, key: str, data=None, **kw) -> None:
    attrs = dict(f[key].attrs)
    del f[key]
    ds = f.create_dataset(key, data=data, **kw)
    for k, v in attrs.items():
        ds.attrs[k] = v


def truncate(path: Path, rng) -> str:
    data = path.read_bytes()
    n = int(rng.integers(0, len(data)))
    path.write_bytes(data[:n])
    return f"truncated to {n} of {len(data)} bytes"


def flip_anywhere(path: Path, rng) -> str:
    data = bytearray(path.read_bytes())
    k = int(rng.integers(1, 21))
    for i in rng.integers(0, len(data), size=k):
        data[int(i)] ^= int(rng.integers(1, 256))
    path.write_bytes(bytes(data))
    return f"{k} bytes flipped anywhere"


def flip_in_dataset(path: Path, rng) -> str:
    with h5py.File(path, "r") as f:
        key = _pick(rng, _datasets(f))
        ds = f[key]
        if ds.chunks is not None:
            info = ds.id.get_chunk_info(int(rng.integers(ds.id.get_num_chunks())))
            start, size = info.byte_offset, info.size
        else:
            start, size = ds.id.get_offset(), ds.id.get_storage_size()
    data = bytearray(path.read_bytes())
    k = int(rng.integers(1, 6))
    for i in rng.integers(start, start + size, size=k):
        data[int(i)] ^= int(rng.integers(1, 256))
    path.write_bytes(bytes(data))
    return f"{k} bytes flipped inside /{key}"


def wrong_dtype(path: Path, rng) -> str:
    with h5py.File(path, "a") as f:
        key = _pick(rng, _datasets(f))
        arr = f[key][()]
        kind = _pick(rng, ["S8", "complex128", "bool", "int8", "uint64", "compound"])
        if kind == "compound":
            new = np.zeros(arr.shape[:1], dtype=[("a", "f8"), ("b", "i4")])
        elif kind == "S8":
            new = arr.astype("S8")
        else:
            new = arr.astype(kind)
        _replace(f, key, new)
    return f"/{key} as {kind}"


def wrong_shape(path: Path, rng) -> str:
    with h5py.File(path, "a") as f:
        key = _pick(rng, _datasets(f))
        arr = f[key][()]
        kind = _pick(rng, ["transposed", "flat", "extra axis", "two columns", "empty", "scalar", "one sample"])
        new = {"transposed": arr.T, "flat": arr.reshape(-1), "extra axis": arr[..., None],
               "two columns": np.zeros((len(arr), 2)), "empty": arr[:0], "scalar": np.float64(1.0),
               "one sample": arr[:1]}[kind]
        _replace(f, key, new)
    return f"/{key} {kind}"


def non_finite(path: Path, rng) -> str:
    with h5py.File(path, "a") as f:
        key = _pick(rng, _datasets(f))
        ds = f[key]
        arr = ds[()].astype(np.float64)
        v = _pick(rng, [np.nan, np.inf, -np.inf])
        flat = arr.reshape(-1)
        idx = rng.integers(0, flat.size, size=int(rng.integers(1, 4)))
        flat[idx] = v
        _replace(f, key, arr)
    return f"/{key} with {v}"


def absurd_values(path: Path, rng) -> str:
    with h5py.File(path, "a") as f:
        key = _pick(rng, _datasets(f))
        arr = f[key][()].astype(np.float64)
        v = float(_pick(rng, [1e30, -1e30, 1e300, 1e6, -1e6, 1e15]))
        if rng.random() < 0.5:
            arr[...] = v
        else:
            arr.reshape(-1)[int(rng.integers(arr.size))] = v
        _replace(f, key, arr)
    return f"/{key} with {v:g}"


ATTR_VALUES = [-1.0, -1e30, 1e300, np.nan, np.inf, 0, -5, 1e-300, 2**62, "x", b"\xff\xfe", np.array([1.0, 2.0, 3.0]),
               np.array([]), True, 1e9]


def absurd_attribute(path: Path, rng) -> str:
    with h5py.File(path, "a") as f:
        items = [(k, a) for k in ["/", *_groups(f), *_datasets(f)] for a in f[k].attrs
                 if a not in ("format", "axis")]
        key, name = _pick(rng, items)
        value = _pick(rng, ATTR_VALUES)
        del f[key].attrs[name]
        f[key].attrs[name] = value
    return f"{key}@{name} = {value!r}"


AXIS_VALUES = [{"lead_mm": "x"}, {"lead_mm": -5}, {"lead_mm": 0}, {"travel_mm": 1e300}, {"lead_mm": True},
               {"travel_mm": [1, 2]}, {"sensors": "garbage"}, {"sensors": {"imu_accelerometer": {"bandwidth_hz": -1}}},
               {"lead_mm": 1e-12}]


def absurd_axis(path: Path, rng) -> str:
    with h5py.File(path, "a") as f:
        axis = json.loads(f.attrs["axis"])
        kind = int(rng.integers(4))
        if kind == 0:
            change = _pick(rng, AXIS_VALUES)
            axis.update(change)
            f.attrs["axis"] = json.dumps(axis)
            return f"/@axis with {json.dumps(change)}"
        value = ["[1, 2]", "{not json", np.float64(5.0), "null", '"a string"'][int(rng.integers(5))]
        f.attrs["axis"] = value
    return f"/@axis = {value!r}"


def format_attrs(path: Path, rng) -> str:
    with h5py.File(path, "a") as f:
        kind = _pick(rng, ["version 99", "version string", "version -1", "no format", "other format"])
        if kind == "version 99":
            f.attrs["format_version"] = 99
        elif kind == "version string":
            f.attrs["format_version"] = "1"
        elif kind == "version -1":
            f.attrs["format_version"] = -1
        elif kind == "no format":
            del f.attrs["format"]
        else:
            f.attrs["format"] = "ballscrew-twin/truth"
    return kind


def absurd_dimension(path: Path, rng) -> str:
    with h5py.File(path, "a") as f:
        key = _pick(rng, _datasets(f))
        shape = f[key].shape
        n = int(_pick(rng, [10**9, 2**40, 10**7]))
        new = (n, *shape[1:]) if shape else (n,)
        _replace(f, key, None, shape=new, dtype="f4", chunks=(1024, *shape[1:]) if shape else (1024,))
    return f"/{key} declared {new}"


def absurd_rate(path: Path, rng) -> str:
    with h5py.File(path, "a") as f:
        items = [(k, "fs_hz") for k in [*_groups(f), *_datasets(f)] if "fs_hz" in f[k].attrs]
        key, name = _pick(rng, items)
        value = float(_pick(rng, [1e-9, 1e-3, 1e12, 3e8, 0.5]))
        f[key].attrs[name] = value
    return f"{key}@fs_hz = {value:g}"


def link(path: Path, rng) -> str:
    with h5py.File(path, "a") as f:
        targets = _datasets(f) + [g for g in _groups(f) if g.count("/") >= 1]
        key = _pick(rng, targets)
        kind = _pick(rng, ["soft to another", "dangling soft", "external to self", "external to nothing",
                           "external to a text file"])
        other = _pick(rng, _datasets(f))
        del f[key]
        if kind == "soft to another":
            f[key] = h5py.SoftLink("/" + other)
        elif kind == "dangling soft":
            f[key] = h5py.SoftLink("/nowhere/at/all")
        elif kind == "external to self":
            f[key] = h5py.ExternalLink(path.name, "/" + other)
        elif kind == "external to nothing":
            f[key] = h5py.ExternalLink("absent.h5", "/x")
        else:
            f[key] = h5py.ExternalLink("/etc/hostname", "/x")
    return f"/{key} replaced by {kind}"


def swap_kind(path: Path, rng) -> str:
    with h5py.File(path, "a") as f:
        if rng.random() < 0.5:
            key = _pick(rng, [g for g in _groups(f) if g.count("/") >= 1])
            del f[key]
            f[key] = np.zeros(3)
            return f"/{key} group replaced by a dataset"
        key = _pick(rng, _datasets(f))
        del f[key]
        f.create_group(key)
    return f"/{key} dataset replaced by a group"


def delete(path: Path, rng) -> str:
    with h5py.File(path, "a") as f:
        if rng.random() < 0.5:
            key = _pick(rng, _datasets(f) + _groups(f))
            del f[key]
            return f"/{key} deleted"
        items = [(k, a) for k in ["/", *_groups(f), *_datasets(f)] for a in f[k].attrs]
        key, name = _pick(rng, items)
        del f[key].attrs[name]
    return f"{key}@{name} deleted"


MUTATIONS: dict[str, Callable[[Path, np.random.Generator], str]] = {
    f.__name__: f for f in (truncate, flip_anywhere, flip_in_dataset, wrong_dtype, wrong_shape, non_finite,
                            absurd_values, absurd_attribute, absurd_axis, format_attrs, absurd_dimension,
                            absurd_rate, link, swap_kind, delete)
}


def mutate(src: Path, dst_dir: Path, rng: np.random.Generator, kind: str | None = None) -> str:
    """Copy ``src`` to ``dst_dir/measurements.h5`` and apply one mutation (``kind``, or one drawn
    from ``rng``); return its description."""
    dst_dir.mkdir(parents=True, exist_ok=True)
    dst = dst_dir / "measurements.h5"
    shutil.copy(src, dst)
    kind = kind or _pick(rng, sorted(MUTATIONS))
    return f"{kind}: {MUTATIONS[kind](dst, rng)}"

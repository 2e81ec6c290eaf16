"""The MJCF text of the axis model (``twin export-model``, ``models/linear_axis.xml``), written by
MuJoCo from the spec (``MjSpec.to_xml``) with every number exact: loaded back, the text compiles
to the model the simulator compiles from the spec, bit for bit but for the sign of one zero (the
ball nut's range (−0.0, 0.0) in the new state, which the writer leaves out as equal to its
default and so reads back as +0.0; tests/test_model_spec.py).

MuJoCo's XML writer prints floats with 6 significant digits by default (``%g``), which moves
e.g. the nut's stiffness 86844994.30243008 N/m to 8.6845e+07 and its drag torque in the 7th
digit. Its precision is a library setting: MuJoCo's src/xml/xml_numeric_format.h declares the
exported ``_mjPRIVATE__set_xml_precision`` and, for "full precision printing of floating point
numbers in saved XMLs", ``mujoco::FullFloatPrecision``, which sets it to 17 digits (exact round
trips) and back to 6. It is not part of the public API, so the MuJoCo version is pinned
(pyproject) and tests/test_model_spec.py checks the round trip. :func:`spec_to_mjcf` sets 17
digits for the one call, then prints each number back in the shortest form that reads as the same double (Python's
``repr``; an ``rgba``, which MuJoCo stores in single precision, as the same float32). Where the
library does not export that setting, the text keeps MuJoCo's 6 digits and a warning says so.
"""

from __future__ import annotations

import ctypes
import re
import warnings
from contextlib import contextmanager
from pathlib import Path

import mujoco
import numpy as np

from twin.sim.axis import Axis
from twin.sim.model.machine_base import BaseMode
from twin.sim.model.spec import build_spec

FULL_PRECISION = 17  # significant digits that read back as the same double (IEEE 754 binary64)
_ATTRIBUTE = re.compile(r'(\w+)="([^"]*)"')
_SINGLE = ("rgba",)  # attributes MuJoCo stores as float32 (mjModel's *_rgba)
_FLOAT = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


def _library() -> ctypes.CDLL | None:
    """The MuJoCo shared library the Python bindings loaded (the same handle: the loader returns
    the library already mapped), or None when it is not found beside the package."""
    folder = Path(mujoco.__file__).parent
    for pattern in ("libmujoco.so*", "libmujoco*.dylib", "mujoco.dll"):
        for path in sorted(folder.glob(pattern)):
            try:
                return ctypes.CDLL(str(path))
            except OSError:
                continue
    return None


@contextmanager
def _xml_precision(digits: int):
    """MuJoCo's XML writer at ``digits`` significant digits inside the block, restored after.
    Yields whether the setting was available."""
    lib = _library()
    try:
        get, put = lib._mjPRIVATE__get_xml_precision, lib._mjPRIVATE__set_xml_precision
    except AttributeError:  # no library, or one without the setting
        yield False
        return
    get.restype, put.argtypes = ctypes.c_int, [ctypes.c_int]
    before = get()
    put(digits)
    try:
        yield True
    finally:
        put(before)


def _shortest(text: str) -> str:
    """Every decimal number inside an attribute value printed in the shortest form that reads
    as the same double, or as the same float32 in :data:`_SINGLE` attributes (integers and names
    untouched)."""
    def number(token: str, single: bool) -> str:
        if not _FLOAT.fullmatch(token) or not any(ch in token for ch in ".eE"):
            return token
        if single:
            return np.format_float_positional(np.float32(token), unique=True, trim="-")
        short = repr(float(token))
        return short[:-2] if short.endswith(".0") else short

    def attribute(m: re.Match) -> str:
        single = m.group(1) in _SINGLE
        return f'{m.group(1)}="' + " ".join(number(t, single) for t in m.group(2).split(" ")) + '"'

    return _ATTRIBUTE.sub(attribute, text)


def spec_to_mjcf(spec: mujoco.MjSpec) -> str:
    """MJCF text of ``spec`` (``spec.to_xml()``) whose numbers read back as the spec's floats."""
    with _xml_precision(FULL_PRECISION) as exact:
        text = spec.to_xml()
    if not exact:
        warnings.warn("this MuJoCo build does not export its XML precision setting: the MJCF "
                      "carries MuJoCo's default 6 significant digits and compiles to a model "
                      "slightly different from the simulator's", RuntimeWarning, stacklevel=2)
    else:
        text = _shortest(text)
    return text if text.endswith("\n") else text + "\n"


def build_mjcf(axis: Axis, timestep: float, base: BaseMode | None = None) -> str:
    """MJCF text of the axis in its new (healthy, zero-backlash) state, the spec of
    :func:`twin.sim.model.build_spec` (same arguments: ``timestep`` in s, ``base`` a compliant
    machine base or None): a complete model that holds still when loaded on its own.

    Raises ValueError when the base is too light for the time step."""
    return spec_to_mjcf(build_spec(axis, timestep, base))

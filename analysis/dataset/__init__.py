"""The versioned on-disk dataset of one campaign (HDF5, ``format_version`` 2; version 1 is read too).

One campaign is one directory holding two files:

- ``measurements.h5``: what a real testbed records (Phase I captures of controller and nut
  accelerometer signals, Phase II IMU runs, dial-indicator readings). Estimators read only this.
- ``truth.h5``: what only a simulator knows (preload, backlash, stiffness over time, true error
  motions, onset hours, effect parameters). Scorers read both.

The layout is described for users in ``docs/dataset-format.md``. The package holds

- :mod:`~analysis.dataset.schema`: the format's names, channels, units and :class:`DatasetError`;
- :mod:`~analysis.dataset.read`: the readers (:func:`open_measurements`, :func:`open_truth`), which
  validate on access and raise :class:`DatasetError` naming the file, the HDF5 key, the offending
  value and what was expected;
- :mod:`~analysis.dataset.write`: the writers (:func:`assemble_measurements`,
  :func:`assemble_truth`), which write to a temporary file and ``os.replace`` it into place;
- :mod:`~analysis.dataset.leak_guard`: the truth-leak guard (:data:`TRUTH_KEYS`,
  :func:`measurement_keys`, :func:`truth_mentions`);
- :mod:`~analysis.dataset.validate`, :mod:`~analysis.dataset.attrs`,
  :mod:`~analysis.dataset.h5file`: the checks, attribute conversion and file opening they share.

Units are SI inside (rad/s, N*m, m/s^2, m, rad, s); names carry their unit where it is not SI
(``hours``, ``backlash_um``, ``speeds_mm_s``). Reading never executes code from a file: attributes
holding structured data are JSON (parsed with :func:`json.loads`), and datasets of object, string
or compound dtype are rejected.
"""


from analysis.dataset.leak_guard import measurement_keys, truth_mentions
from analysis.dataset.read import Measurements, Phase1Capture, Phase2Run, Truth, open_measurements, open_truth
from analysis.dataset.schema import (
    ALLOWED_TRUTH_MENTIONS,
    DOFS,
    FORMAT_VERSION,
    MEASUREMENTS_FORMAT,
    OPTIONAL_PHASE2_CHANNELS,
    PHASE1_CHANNELS,
    PHASE2_CHANNELS,
    STROKE_TRUTH,
    SUPPORTED_VERSIONS,
    TRUTH_FORMAT,
    TRUTH_KEYS,
    DatasetError,
)
from analysis.dataset.write import assemble_measurements, assemble_truth

__all__ = [
    "FORMAT_VERSION",
    "SUPPORTED_VERSIONS",
    "MEASUREMENTS_FORMAT",
    "TRUTH_FORMAT",
    "PHASE1_CHANNELS",
    "PHASE2_CHANNELS",
    "OPTIONAL_PHASE2_CHANNELS",
    "STROKE_TRUTH",
    "DOFS",
    "TRUTH_KEYS",
    "ALLOWED_TRUTH_MENTIONS",
    "DatasetError",
    "Phase1Capture",
    "Phase2Run",
    "Measurements",
    "Truth",
    "assemble_measurements",
    "assemble_truth",
    "open_measurements",
    "open_truth",
    "measurement_keys",
    "truth_mentions",
]


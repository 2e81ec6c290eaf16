"""Bringing a laboratory's recordings into the dataset format (``twin import SPEC``).

- :mod:`~analysis.ingest.spec`: the TOML import spec (pydantic), which files are Phase I
  captures and Phase II runs, their channels, units and rates, and the axis description;
- :mod:`~analysis.ingest.readers`: readers of CSV, MATLAB ``.mat`` (v5 and v7.3), NI TDMS and
  ASAM MDF files, returning named channels with the sample index of every value;
- :mod:`~analysis.ingest.units`: conversion of the laboratory's units to the format's SI units;
- :mod:`~analysis.ingest.convert`: the import itself, resumable, through the validating writer
  :func:`analysis.dataset.assemble_measurements`.
- :mod:`~analysis.ingest.watch`: ``twin import --watch``, a growing export folder imported file
  by file as live units for ``twin monitor``.

Every problem raises :class:`ImportSpecError` (a ``ValueError``) naming the file, the channel
and the line or sample.
"""

from analysis.ingest.convert import ImportSummary, run_import
from analysis.ingest.spec import ImportSpec, ImportSpecError, load_spec

__all__ = ["ImportSpec", "ImportSpecError", "ImportSummary", "load_spec", "run_import"]

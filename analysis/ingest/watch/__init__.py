"""``twin import SPEC --watch``: a laboratory's export folder, growing while the machine runs,
imported as a live source of ``twin monitor`` (docs/import.md, "twin import SPEC --watch").

**When a lab file is complete.** A lab's files carry no completeness mark, so a file is taken
when (1) it is not empty and its size and modification time have not changed over ``settle_s``
seconds of this process's own observation (two looks at least ``settle_s`` apart; the file
system's clock is not used, so a network share's clock skew does not matter), and (2) the
reader of the spec converts it without error (a TDMS file with a cut last segment, a CSV line
with fewer columns than the header, NaN samples, ... are errors). A file that changes while it
is read is looked at again. A file that fails (2) is *refused*: the reason, naming the file, is
logged, and the file is not read again unless its size or modification time changes (a copy
that stalled longer than ``settle_s`` and then resumed is read again and imported once whole).
Further refusals: a rate that differs from the axis description's sensor rate (or, for a channel
the axis does not rate, from the first imported file's) by more than :data:`RATE_TOLERANCE`; a
file whose operating hours come before the last imported unit's (files must arrive in hours
order, because the units' sequence and names are given once and for all); a file of a sample or
session already imported; a run whose hours differ from its session's (as ``twin import``).

**Units.** Accepted files are grouped as ``twin import`` groups them: captures into samples (the
``sample`` group of ``name_pattern``, else one sample per hours value), runs into sessions (the
``session`` group, else one per hours value). A group is *closed* when it has
``[watch] captures_per_sample`` (``runs_per_session``) files, when a file of later operating hours
has been accepted, or when a finite watch ends (``--once``, ``--until-idle``). Closed groups are
published in hours order (a capture before a session at equal hours) into ``OUT/live/`` in the
live-unit convention of :mod:`analysis.dataset.live` that ``twin monitor`` reads: each Phase I
capture a unit ``<seq>-phase1-c<NNNNNN>.h5`` (``captures_in_sample`` = the sample's captures),
each Phase II session a unit ``<seq>-phase2-s<NNNN>.h5``, written under a temporary name and
renamed into place, then its manifest (size, SHA-256). The names are those ``twin import`` gives
the same files in batch. A finite watch ends by writing ``OUT/measurements.h5`` and
``OUT/import.json`` from the imported files exactly as ``twin import`` does, then
``OUT/live/end.json``.

**State.** What was imported is the manifests in ``OUT/live/`` (each names its source files,
with their size and modification time); what was refused is ``OUT/import-watch.jsonl``, an
append-only log (``watch started``, ``file refused``, ``unit published``, ``watch stopped``).
A restarted watcher rebuilds both, so it neither imports a file again nor misses one that
arrived while it was stopped; a sample whose captures were being published when the process
was killed is completed first. Converted files are kept as parts in ``OUT/.import/`` (as by
``twin import``), so a restart does not convert an accepted file again.

**Modules.** :mod:`~analysis.ingest.watch.watcher` (:class:`ImportWatcher`: accepting or refusing
a settled file, the loop), :mod:`~analysis.ingest.watch.folder` (the folder and its settling
files, the hours tables), :mod:`~analysis.ingest.watch.groups` (the open groups and when one is
closed), :mod:`~analysis.ingest.watch.publish` (writing the live units and their manifests),
:mod:`~analysis.ingest.watch.state` (the manifests and the log, rebuilt at a restart). Every
public name is importable from this package.
"""

from analysis.ingest.watch.state import LIVE_DIR, WATCH_LOG
from analysis.ingest.watch.watcher import RATE_TOLERANCE, ImportWatcher, WatchResult

__all__ = ["LIVE_DIR", "RATE_TOLERANCE", "WATCH_LOG", "ImportWatcher", "WatchResult"]

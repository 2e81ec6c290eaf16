"""The Rerun recording of a campaign directory (``twin view``); the only module that imports Rerun.

What the recording holds (entity paths; the blueprint arranges them in four tabs):

- ``/world/...``: the axis in 3D (z up, x along the travel, m): base, the two rails, the screw
  and, under ``/world/carriage``, the trucks, the carriage plate, the nut, the load and the IMU.
  ``/world/carriage`` carries one :class:`rerun.Transform3D` per pose on the ``sim_time``
  timeline (s from the start of the run) of one Phase II run: the carriage at the commanded
  position plus the six error motions multiplied by a stated factor (``exaggeration``, e.g.
  2000), placed so that the IMU point moves by the exaggerated translations and the carriage
  turns by the exaggerated angles. The error motions are the true ones of the session
  (``truth.h5``) when it exists, else the estimated ones (``backlash/error_motions.h5``, the
  forward or reverse profile by the direction of travel); the property ``view`` and the notes
  say which. With ``truth.h5`` the carriage is placed at its rail coordinate (commanded position
  plus the session's origin offset); without it, at the commanded position.
- ``/phase2/<session>/<run>/...``: that run's IMU channels and commanded position, and the error
  motions along the run (unexaggerated, µm and µrad), on ``sim_time``.
- ``/phase1/<capture>/...``: motor speed and torque and the two nut accelerometers of one or
  more Phase I captures, on ``sim_time`` (s from the start of the capture). Channels longer than
  ``max_points`` samples keep every k-th sample (stated in the series name).
- ``/hours/...`` on the ``hours`` timeline (operating hours, stored as a duration of
  hours·3600 s): the Phase I scores of every method of ``phase1/detection.json`` with their
  limits (values exactly those of the file), the injected onset (``truth.h5``) and the true
  preload; the backlash estimates of ``backlash/backlash.json`` (shift estimate, perceived-pitch
  estimate, Kalman smoothed value with ±2σ, dial-indicator change) against the injected change
  of backlash (``truth.h5``, relative to the mean of the baseline sessions as the estimates);
  ``/hours/events`` marks the onset and each method's first detection.
- Properties: ``scenario`` (the scenario of ``truth.h5``, flattened to dotted keys, plus the whole
  JSON as ``json``) or, without ``truth.h5``, ``measurements`` (the axis description of
  ``measurements.h5``); ``view`` (what was drawn and from what).
- ``/notes``: a Markdown document of the above, including what was left out and why.

A directory without ``truth.h5`` (a real machine) gives a recording without the truth parts;
missing ``phase1/`` or ``backlash/`` outputs are left out with a note naming the file and the
command that writes it.
"""


from twin.harness.view.base import (
    ENTITY_CARRIAGE,
    EXAGGERATION,
    MAX_POINTS,
    POSE_RATE_HZ,
    ViewError,
    ViewSummary,
    hours_to_ns,
)
from twin.harness.view.output import serve_recording, write_recording
from twin.harness.view.poses import carriage_poses
from twin.harness.view.recording import build

__all__ = ["ENTITY_CARRIAGE", "EXAGGERATION", "MAX_POINTS", "POSE_RATE_HZ", "ViewError", "ViewSummary",
           "build", "carriage_poses", "hours_to_ns", "serve_recording", "write_recording"]

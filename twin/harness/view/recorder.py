"""The one class that calls Rerun while a recording is logged (:class:`_Recorder`): static
archetypes, scalar series on a timeline (``sim_time`` in s, ``hours`` as durations), the 3D
shapes of the axis, and the text events on the ``hours`` timeline.
"""

from __future__ import annotations

import numpy as np

from twin.harness.view.base import (
    hours_to_ns,
)
from twin.harness.view.poses import _Shape


class _Recorder:
    """Everything that calls Rerun."""

    def __init__(self, rec, rr):
        self.rec, self.rr = rec, rr

    def static(self, path: str, archetype) -> None:
        self.rec.log(path, archetype, static=True)

    def series(self, path: str, t_s, values, *, timeline: str = "sim_time", name: str | None = None,
               color=None, points: bool = False) -> None:
        rr = self.rr
        if name is not None or color is not None:
            style = (rr.SeriesPoints(names=name, colors=color, marker_sizes=4.0) if points else
                     rr.SeriesLines(names=name, colors=color))
            self.static(path, style)
        index = (rr.TimeColumn(timeline, duration=np.asarray(t_s, dtype=np.float64)) if timeline == "sim_time"
                 else rr.TimeColumn(timeline, duration=hours_to_ns(t_s).astype("timedelta64[ns]")))
        self.rec.send_columns(path, indexes=[index],
                              columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=np.float64)))

    def shapes(self, root: str, shapes: list[_Shape]) -> None:
        rr = self.rr
        for sh in shapes:
            if sh.kind == "box":
                arch = rr.Boxes3D(centers=[sh.center], half_sizes=[sh.size], colors=[sh.color],
                                  labels=[sh.label], fill_mode="solid")
            else:
                arch = rr.Cylinders3D(centers=[sh.center], lengths=[2 * sh.size[0]], radii=[sh.size[1]],
                                      rotation_axis_angles=[rr.RotationAxisAngle(axis=[0, 1, 0], degrees=90.0)],
                                      colors=[sh.color], labels=[sh.label], fill_mode="solid")
            self.static(f"{root}/{sh.path}", arch)

    def events(self, hours: list[float], texts: list[str], levels: list[str]) -> None:
        rr = self.rr
        order = np.argsort(hours, kind="stable")
        self.rec.send_columns(
            "/hours/events",
            indexes=[rr.TimeColumn("hours", duration=hours_to_ns(np.asarray(hours)[order]).astype("timedelta64[ns]"))],
            columns=rr.TextLog.columns(text=[texts[i] for i in order], level=[levels[i] for i in order]))

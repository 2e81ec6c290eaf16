"""Live review of ``twin monitor`` in Rerun: every event streamed as it is computed, on the
``hours`` timeline of ``twin view`` (operating hours as a duration of hours·3600 s) and at the
same entity paths, so the views of a finished campaign and of a live one look alike:

- ``/hours/phase1/<detector>/score`` and ``.../limit``: each scored sample's score and the limit;
- ``/hours/events``: alarms, alarms cleared, the Phase II request, refused input (text log);
- ``/hours/backlash/delta_um`` and ``/hours/backlash/smoothed_um``: each Phase II session's
  change of backlash and the Kalman trend at it (µm).

Where it goes: ``serve`` (a gRPC server and a web viewer), ``connect`` (a running viewer's gRPC
address, ``rerun+http://HOST:PORT/proxy``) or ``save`` (an ``.rrd`` file).
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import quote

import rerun.blueprint as rrb

from twin.harness.view.base import APP_ID, RED
from twin.harness.view.recorder import _Recorder

__all__ = ["MonitorView"]

_LEVELS = {"alarm": "WARN", "alarm cleared": "INFO", "Phase II requested": "WARN",
           "input refused": "ERROR"}


class MonitorView:
    """A Rerun stream fed with the monitor's events (:meth:`on_event`). detectors: {name:
    label}; thresholds: {name: limit} (the model's)."""

    def __init__(self, detectors: dict[str, str], thresholds: dict[str, float], *, serve: bool = False,
                 connect: str | None = None, save: str | Path | None = None, web_port: int = 9090,
                 grpc_port: int = 9876):
        import rerun as rr

        rec = rr.RecordingStream(APP_ID)
        rec.send_recording_name("twin monitor")
        self.url = None
        if save is not None:
            rec.save(str(save))
        elif connect is not None:
            rec.connect_grpc(connect)
        elif serve:
            uri = rec.serve_grpc(grpc_port=grpc_port)
            rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=uri)
            self.url = f"http://localhost:{web_port}/?url={quote(uri, safe='')}"
        self.rec, self.r, self.rr = rec, _Recorder(rec, rr), rr
        self.detectors, self.thresholds = detectors, thresholds
        self._styled: set[str] = set()
        views = [rrb.TimeSeriesView(origin=f"/hours/phase1/{n}", name=f"{label} against operating hours")
                 for n, label in detectors.items()]
        views.append(rrb.TimeSeriesView(origin="/hours/backlash", name="backlash change (µm)"))
        rec.send_blueprint(rrb.Blueprint(rrb.Horizontal(rrb.Grid(*views),
                                                        rrb.TextLogView(origin="/hours/events",
                                                                        name="events (hours)")),
                                         rrb.TimePanel(timeline="hours")))

    def _point(self, path: str, hours: float, value: float, name: str, color=None) -> None:
        first = path not in self._styled
        self._styled.add(path)
        self.r.series(path, [hours], [value], timeline="hours", name=name if first else None,
                      color=color if first else None)

    def on_event(self, ev: dict) -> None:
        kind, h = ev["event"], ev.get("hours")
        if h is None:
            return
        if kind == "sample scored":
            for name, s in ev["scores"].items():
                if s is None:
                    continue
                label = self.detectors.get(name, name)
                self._point(f"/hours/phase1/{name}/score", h, s, label)
            for name, thr in self.thresholds.items():
                self._point(f"/hours/phase1/{name}/limit", h, thr, f"{self.detectors.get(name, name)} limit",
                            RED)
        elif kind in _LEVELS:
            self.r.events([h], [f"{kind}: {ev.get('reason', '')}"], [_LEVELS[kind]])
        elif kind in ("Phase II baseline", "Phase II estimated"):
            if ev.get("delta_backlash_um") is not None:
                self._point("/hours/backlash/delta_um", h, ev["delta_backlash_um"], "change of backlash (µm)")
            if "trend" in ev:
                self._point("/hours/backlash/smoothed_um", h, ev["trend"]["smoothed_um"], "Kalman trend (µm)")

    def close(self) -> None:
        self.rec.flush()

"""The Rerun blueprint: the layout of the views a reviewer opens."""

from __future__ import annotations

from twin.harness.view.base import ViewSummary


def _blueprint(rrb, summary: ViewSummary, phase2_roots: list[str], phase1_roots: list[str],
               ranges: dict[str, tuple | None], travel: float, has_backlash: bool, has_truth: bool):
    tabs = []
    k = f"{summary.exaggeration:g}"
    eye = rrb.EyeControls3D(position=[travel / 2 + 0.35, -0.95, 0.55], look_target=[travel / 2, 0.0, 0.05],
                            eye_up=[0, 0, 1])
    view3d = rrb.Spatial3DView(origin="/world", eye_controls=eye,
                               name=f"axis, error motions ×{k} ({summary.error_motion_source})")
    if phase2_roots:
        plots = [rrb.TimeSeriesView(origin=p, name=p.rsplit("/", 1)[1] + f" ({summary.session}/{summary.run})")
                 for p in phase2_roots]
        tabs.append(rrb.Horizontal(view3d, rrb.Vertical(*plots), column_shares=[3, 2],
                                   name="Phase II run (sim_time)"))
    else:
        tabs.append(rrb.Horizontal(view3d, name="axis"))
    if phase1_roots:
        tabs.append(rrb.Grid(*[rrb.TimeSeriesView(origin=p, name=p.removeprefix("/phase1/"))
                               for p in phase1_roots], grid_columns=4, name="Phase I captures (sim_time)"))
    hours_views = []
    for name, rng in ranges.items():
        hours_views.append(rrb.TimeSeriesView(
            origin=f"/hours/phase1/{name}", name=f"{name} against operating hours",
            axis_y=rrb.ScalarAxis(range=rng) if rng is not None else None))
    if has_truth:
        hours_views.append(rrb.TimeSeriesView(origin="/hours/truth", name="injected preload (truth.h5)"))
    if has_backlash:
        hours_views.append(rrb.TimeSeriesView(origin="/hours/backlash", name="backlash change (µm)"))
    if hours_views:
        first = hours_views[:1] if ranges else []
        rest = hours_views[1:] if ranges else hours_views
        tabs.append(rrb.Vertical(*first, rrb.Grid(*rest, grid_columns=3), row_shares=[1, 1] if first else None,
                                 name="operating hours (timeline: hours)"))
    tabs.append(rrb.Vertical(rrb.TextDocumentView(origin="/notes", name="notes"),
                             rrb.TextLogView(origin="/hours/events", name="events (hours)"),
                             row_shares=[3, 1], name="notes"))
    return rrb.Blueprint(rrb.Tabs(*tabs, active_tab=0), rrb.TimePanel(timeline="sim_time"))

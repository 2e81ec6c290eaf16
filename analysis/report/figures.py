"""The report's figures: the PNGs of the analyses copied into OUT/figures, or drawn from their
JSON when the analysis ran without plots (Fig. 6 from detection.json, Figs. 10–13 from
backlash.json, with the same plotters as ``twin detect`` and ``twin backlash``)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from analysis.phase1.figures import plot_fig6
from analysis.phase2.figures import draw_trend_figure
from analysis.report.paper import FIG_FILES


class Figures:
    """Copies (or draws) the PNGs into OUT/figures and hands out their relative links."""

    def __init__(self, directory: Path, out: Path):
        self.directory, self.out = directory, out
        self.dir = out / "figures"
        self.dir.mkdir(parents=True, exist_ok=True)
        for stale in self.dir.glob("fig*.png"):  # from an earlier report of this folder
            stale.unlink()
        self.written: list[Path] = []

    def source(self, fig: str) -> Path:
        sub, name = FIG_FILES[fig]
        return self.directory / sub / name

    def copy(self, fig: str) -> str | None:
        src = self.source(fig)
        if not src.is_file() or src.stat().st_size == 0:
            return None
        dst = self.dir / (src.name if src.name.startswith("fig") else f"fig{int(fig):02d}_{src.name}")
        if src.resolve() != dst.resolve():
            shutil.copyfile(src, dst)
        self.written.append(dst)
        return f"figures/{dst.name}"

    def draw_fig6(self, detection: dict, details: dict | None, onset: float | None,
                  names: dict[str, str]) -> str | None:
        """The Fig. 6 analogue from detection.json, when detection.png is absent."""
        methods = detection.get("methods") or {}
        if not methods:
            return None
        hours = np.asarray(next(iter(methods.values()))["hours"], float)
        results = {k: {"scores": np.asarray(v["scores"], float), "threshold": float(v["threshold"]),
                       "label": v.get("label") or names.get(k, k)} for k, v in methods.items()}
        n_base = int((details or {}).get("n_baseline", 15))
        dst = self.dir / "fig06_detection_drawn.png"
        plot_fig6(dst, hours, results, n_base, onset,
                  {k: v.get("detection_hours") for k, v in methods.items()})
        self.written.append(dst)
        return f"figures/{dst.name}"

    def draw_phase2(self, fig: str, doc: dict, p2_score: dict | None) -> str | None:
        """A Fig. 10-13 analogue from backlash.json, when ``twin backlash`` drew no PNGs; Fig. 13
        with the injected change of ``p2_score`` (score.json's phase2), if any."""
        if not doc.get("sessions"):
            return None
        injected = None
        if p2_score and p2_score.get("sessions"):
            injected = ([r["hours"] for r in p2_score["sessions"]],
                        [r["injected_delta_um"] for r in p2_score["sessions"]])
        dst = self.dir / f"fig{int(fig):02d}_drawn.png"
        draw_trend_figure(fig, doc, dst, injected=injected)
        self.written.append(dst)
        return f"figures/{dst.name}"

"""The figure of Phase I like the paper's Fig. 6: one panel per method, its score against operating
hours with its limit, the baseline, the onset and the detection (matplotlib, Agg). Each method is
drawn in its fixed colour and marker (:func:`analysis.base.registry.style`)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from analysis.base.registry import label, style

__all__ = ["plot_fig6"]


def plot_fig6(path: Path, hours: np.ndarray, results: dict[str, dict], n_baseline: int,
              onset_hours: float | None, detections: dict[str, float | None]) -> None:
    """One panel per method: score trajectory, control limit, baseline, injected onset, detection.

    results: {name: {"scores" (n,), "threshold", "label"?}}; the panel title is the label.

    Scores rising more than three decades above the limit (or the baseline) are drawn on a log
    (or symmetric-log) axis.
    """
    names = list(results)
    rows = max(1, (len(names) + 1) // 2)
    fig, axes = plt.subplots(rows, 2 if len(names) > 1 else 1, figsize=(11, 3.0 * rows), squeeze=False)
    for ax, name in zip(axes.ravel(), names, strict=True):
        s = np.asarray(results[name]["scores"], dtype=float)
        thr = results[name]["threshold"]
        color, marker = style("detectors", name)
        ax.plot(hours[:n_baseline], s[:n_baseline], marker=marker, ls="-", ms=3, color="0.75",
                label="baseline")
        ax.plot(hours[n_baseline - 1:], s[n_baseline - 1:], marker=marker, ls="-", ms=3, color=color,
                label="test")
        ax.axhline(thr, color="0.25", ls="--", label=f"limit {thr:.3g}")
        if onset_hours is not None:
            ax.axvline(onset_hours, color="k", ls=":", label=f"injected onset {onset_hours:g} h")
        if detections.get(name) is not None:
            ax.axvline(detections[name], color=color, ls="-.", lw=1.5, label=f"detection {detections[name]:g} h")
        pos = s[np.isfinite(s) & (s > 0)]
        ref = max(abs(thr), float(np.median(np.abs(s[:n_baseline]))), 1e-300)
        if pos.size and pos.max() / ref > 1e3:
            if np.all(s > 0) and thr > 0:
                ax.set_yscale("log")
            else:
                ax.set_yscale("symlog", linthresh=max(ref, 1e-3))
        ax.set_title(results[name].get("label") or label("detectors", name), color=color)
        ax.set_xlabel("operating hours")
        ax.set_ylabel("score")
        ax.legend(fontsize=7, loc="upper left")
    for ax in axes.ravel()[len(names):]:
        ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

"""PNG figures of the backlash analysis, in the spirit of the paper's Figs. 7–13 (matplotlib, Agg).

:func:`write_trace_figures` draws Figs. 7–9 from the traces of a
:class:`analysis.phase2.backlash.CampaignBacklash`; :func:`draw_trend_figure` draws Figs. 10–13
from a ``backlash.json`` document alone, so that ``twin backlash`` and the report (for campaigns
analysed with ``--no-plots``) draw the same figure. :func:`write_figures` writes all seven:

- ``fig07_slow.png``: slow-speed E_XX and E_YX, forward, first and last session (Fig. 7);
- ``fig08_winfilt.png``: the same after winfilt, zoomed (Fig. 8);
- ``fig09_correlation.png``: correlation against lag of the last session's E_YX (forward) with
  the 75 % threshold, the fit of the main peak, and the line through the local shifts of the
  comb DOF if any (Fig. 9);
- ``fig10_position_shifts.png``: E_XX's position shift per session, forward and reverse, whole
  and zoomed (Fig. 10a, b), and ours: forward − reverse of the estimator's DOFs;
- ``fig11_delta_position_shift.png``: ΔPositionShift per DOF (Fig. 11);
- ``fig12_gamma.png``: γ per DOF, the DOF of the highest γ without E_XX, ΔBacklash per DOF with
  the weighted sum (Fig. 12a, b, c);
- ``fig13_backlash.png``: Δbacklash by shifts (a) and by pitch (b) against hours, each with the
  Savitzky–Golay filtered curve the paper draws; ours: the Kalman-smoothed trend (±2σ) in (a),
  dial-indicator changes and, when given, the injected change (Fig. 13).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from analysis.dataset import DOFS
from analysis.phase2.shifts import correlate_traces
from analysis.phase2.winfilt import winfilt

_SCALE = {"E_XX": (1e6, "µm"), "E_YX": (1e6, "µm"), "E_ZX": (1e6, "µm"),
          "E_AX": (1e6, "µrad"), "E_BX": (1e6, "µrad"), "E_CX": (1e6, "µrad")}



def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_trace_figures(result, out_dir) -> list[Path]:
    """Write Figs. 7–9 (the traces of the first and last session) into ``out_dir``; returns
    their paths. ``result``: :class:`analysis.phase2.backlash.CampaignBacklash`."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    est = result.estimator
    ses = result.sessions
    ems = result.error_motions
    paths = []

    first, last = ems[0].slow, ems[-1].slow
    fig, axes = plt.subplots(2, 2, figsize=(11, 6))
    for row, dof in enumerate(("E_XX", "E_YX")):
        j = DOFS.index(dof)
        sc, unit = _SCALE[dof]
        for col, zoom in enumerate((None, 5e-3)):
            ax = axes[row, col]
            for tr, label in ((first, f"{ems[0].hours:g} h"), (last, f"{ems[-1].hours:g} h")):
                x = tr.x_m
                sel = slice(None) if zoom is None else (x >= x[x.size // 2]) & (x <= x[x.size // 2] + zoom)
                ax.plot(x[sel] * 1e3, tr.forward[j][sel] * sc, lw=0.7, label=label)
            ax.set_xlabel("commanded position (mm)")
            ax.set_ylabel(f"slow({dof}↑) ({unit})")
            ax.legend(fontsize=8)
    axes[0, 0].set_title("slow-speed component (Fig. 7)")
    axes[0, 1].set_title("zoom")
    paths.append(_save(fig, out / "fig07_slow.png"))

    fig, axes = plt.subplots(1, 2, figsize=(11, 3.5))
    j = DOFS.index("E_YX")
    for ax, zoom in zip(axes, (None, 3e-3), strict=True):
        for tr, label in ((first, f"{ems[0].hours:g} h"), (last, f"{ems[-1].hours:g} h")):
            w = winfilt(tr.forward[j], tr.dx_m, est.cutoff_wavelength_m, est.window_definition)
            x = tr.x_m
            sel = slice(None) if zoom is None else (x >= x[x.size // 2]) & (x <= x[x.size // 2] + zoom)
            ax.plot(x[sel] * 1e3, w[sel] * 1e6, lw=0.7, label=label)
        ax.set_xlabel("commanded position (mm)")
        ax.set_ylabel("winfilt(E_YX↑) (µm)")
        ax.legend(fontsize=8)
    axes[0].set_title(f"winfilt, λc = {est.cutoff_wavelength_m * 1e3:g} mm (Fig. 8)")
    paths.append(_save(fig, out / "fig08_winfilt.png"))

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    w_last = winfilt(last.forward[j], last.dx_m, est.cutoff_wavelength_m, est.window_definition)
    ref = est.reference_
    lags, c = correlate_traces(w_last, ref["forward"][j], last.dx_m, float(last.x_m[0]), ref["x0"],
                               est.upsample)
    r = ses[-1].shifts[("E_YX", "forward")]
    axes[0].plot(lags * 1e3, c, lw=0.6)
    axes[0].axhline(est.threshold * r.gamma, color="r", lw=0.6, ls="--", label="75 % of γ")
    axes[0].set_xlabel("position lag (mm)")
    axes[0].set_ylabel("correlation")
    axes[0].set_title(f"corr winfilt(E_YX↑), {ems[-1].hours:g} h vs {ems[0].hours:g} h")
    axes[0].legend(fontsize=8)
    near = np.abs(lags - r.shift_m) <= 0.15e-3
    axes[1].plot((lags[near] - r.shift_m) * 1e6, c[near], ".", ms=2, label="correlation")
    axes[1].axvline(0.0, color="r", lw=0.6, label=f"shift {r.shift_m * 1e6:.2f} µm")
    axes[1].set_xlabel("lag − fitted shift (µm)")
    axes[1].set_title("main peak (Fig. 9b)")
    axes[1].legend(fontsize=8)
    comb = [(key, s) for key, s in ses[-1].shifts.items() if np.isfinite(est.comb_pitch(s))]
    if comb:
        key, s = max(comb, key=lambda kv: kv[1].gamma)
        axes[2].plot(s.peak_index, s.local_shifts_m * 1e3, "o", ms=3, label="local shifts")
        nn = np.array([s.peak_index.min(), s.peak_index.max()])
        axes[2].plot(nn, (s.shift_m + nn * s.spacing_m) * 1e3, "-", lw=0.8,
                     label=f"line: spacing {s.spacing_m * 1e3:.5f} mm")
        axes[2].set_title(f"{key[0]} {key[1]}: local shifts (Fig. 9c)")
        axes[2].legend(fontsize=8)
    else:
        axes[2].text(0.5, 0.5, "no comb of peaks\n(single-peak correlations)", ha="center",
                     va="center", transform=axes[2].transAxes)
    axes[2].set_xlabel("peak number n")
    axes[2].set_ylabel("lag (mm)")
    paths.append(_save(fig, out / "fig09_correlation.png"))
    return paths


#: File name of each figure drawn from ``backlash.json``.
TREND_FIGURES = {"10": "fig10_position_shifts.png", "11": "fig11_delta_position_shift.png",
                 "12": "fig12_gamma.png", "13": "fig13_backlash.png"}


def _column(sessions: list[dict], get) -> np.ndarray:
    """One value per session (NaN where missing or null)."""
    out = []
    for s in sessions:
        try:
            v = get(s)
        except (KeyError, TypeError, AttributeError):
            v = None
        out.append(np.nan if v is None else float(v))
    return np.array(out, float)


def draw_trend_figure(fig: str, doc: dict, path: Path,
                      injected: tuple[list[float], list[float]] | None = None, dpi: int = 110) -> Path:
    """Draw Fig. ``fig`` ("10" to "13") from a ``backlash.json`` document into ``path``.

    Args:
        fig: "10" position shifts, "11" ΔPositionShift, "12" γ and Δbacklash per DOF,
            "13" Δbacklash by shifts and by pitch with the Kalman trend (±2σ) and the dial.
        doc: the ``backlash.json`` object (µm, h); needs ``sessions``.
        path: the PNG to write.
        injected: (hours (n,), injected change of backlash (n,) µm), drawn in Fig. 13, or None.
    """
    if fig not in TREND_FIGURES:
        raise ValueError(f"figure {fig!r}: expected one of {', '.join(TREND_FIGURES)}")
    ses = doc["sessions"]
    hours = _column(ses, lambda s: s["hours"])
    params = doc.get("parameters") or {}
    dofs = list(params.get("dofs") or [])
    present = [d for d in DOFS if any(d in (s.get("gamma") or {}) for s in ses)]
    if fig == "10":
        # the paper's Fig. 10: E_XX's position shift in both directions (a) and zoomed (b); the
        # difference of the directions (c) is ours
        f, axes = plt.subplots(1, 3, figsize=(15, 3.6))
        fw = _column(ses, lambda s: s["position_shift_um"]["E_XX/forward"])
        rv = _column(ses, lambda s: s["position_shift_um"]["E_XX/reverse"])
        for ax, scale, unit in ((axes[0], 1e3, "mm"), (axes[1], 1.0, "µm")):
            ax.plot(hours, fw / scale, "-", marker=".", label="E_XX forward")
            ax.plot(hours, rv / scale, "--", marker=".", label="E_XX reverse")
            ax.set_ylabel(f"position shift ({unit})")
        both = np.concatenate([fw, rv])
        if np.isfinite(both).any():  # the zoom: the middle half of the shifts, with a margin
            lo, hi = np.nanpercentile(both, [25, 75])
            pad = max(0.5 * (hi - lo), 5.0)
            axes[1].set_ylim(lo - pad, hi + pad)
        for d in dofs:
            dfw = _column(ses, lambda s, d=d: s["position_shift_um"][f"{d}/forward"])
            drv = _column(ses, lambda s, d=d: s["position_shift_um"][f"{d}/reverse"])
            axes[2].plot(hours, dfw - drv, marker=".", label=d)
        axes[0].set_title("E_XX position shift vs the first session (Fig. 10a)")
        axes[1].set_title("zoomed, both directions (Fig. 10b)")
        axes[2].set_ylabel("forward − reverse (µm)")
        axes[2].set_title("difference of the directions, estimator's DOFs (ours)")
    elif fig == "11":
        f, ax = plt.subplots(figsize=(7, 3.6))
        axes = [ax]
        for d in DOFS:
            v = _column(ses, lambda s, d=d: s["delta_position_shift_um"][d])
            if not np.all(np.isnan(v)):
                ax.plot(hours, np.clip(v, -100, 100), marker=".", label=d)
        ax.set_ylabel("ΔPositionShift (µm, clipped ±100)")
        ax.set_title("ΔPositionShift per DOF (Eq. 4, Fig. 11)")
    elif fig == "12":
        f, axes = plt.subplots(1, 3, figsize=(15, 3.6))
        for d in present:
            axes[0].plot(hours, _column(ses, lambda s, d=d: s["gamma"][d]), marker=".", label=d)
        # Fig. 12b: per session, the DOF of the highest correlation other than E_XX
        others = [d for d in present if d != "E_XX"]
        best = []
        for s in ses:
            g = {d: v for d, v in (s.get("gamma") or {}).items() if d in others and v is not None}
            best.append(others.index(max(g, key=g.get)) if g else np.nan)
        axes[1].plot(hours, best, "o", ms=4, label="highest γ without E_XX")
        axes[1].set_yticks(range(len(others)), others)
        axes[1].set_ylim(-0.5, max(len(others) - 0.5, 0.5))
        for d in dofs:
            axes[2].plot(hours, _column(ses, lambda s, d=d: s["delta_backlash_um_by_dof"][d]), marker=".",
                         lw=0.7, label=f"ΔBacklash {d}")
        axes[2].plot(hours, _column(ses, lambda s: s["delta_backlash_um_shift"]), "k-", marker="o", ms=3,
                     label=f"weighted (σ = {params.get('sigma', '?')})")
        axes[0].set_ylabel("γ_ij = min over directions")
        axes[0].set_title("correlation per DOF (Fig. 12a)")
        axes[1].set_ylabel("DOF")
        axes[1].set_title("DOF of the highest correlation, E_XX excluded (Fig. 12b)")
        axes[2].set_ylabel("Δbacklash (µm)")
        axes[2].set_title("per DOF and weighted sum (Eqs. 5–6, Fig. 12c)")
    else:
        f, axes = plt.subplots(1, 2, figsize=(12, 4))
        smoothed = _column(ses, lambda s: s["smoothed_um"])
        std = _column(ses, lambda s: s["smoothed_std_um"])
        dial = _column(ses, lambda s: s["dial_delta_um"])
        series = (("delta_backlash_um_shift", "savgol_um", "signal position shifts (Eq. 6, Fig. 13a)", True),
                  ("delta_backlash_um_pitch", "savgol_pitch_um", "perceived pitch (Eq. 9, Fig. 13b)", False))
        for ax, (key, sg_key, title, with_trend) in zip(axes, series, strict=True):
            ax.plot(hours, _column(ses, lambda s, key=key: s[key]), "o", ms=3, label="estimate")
            if with_trend and not np.all(np.isnan(smoothed)):
                ax.plot(hours, smoothed, "-", label="Kalman-smoothed ±2σ (ours)")
                if not np.all(np.isnan(std)):
                    ax.fill_between(hours, smoothed - 2 * std, smoothed + 2 * std, alpha=0.2)
            sg = _column(ses, lambda s, sg_key=sg_key: s[sg_key])
            if not np.all(np.isnan(sg)):
                p = (doc.get("parameters") or {}).get("savgol") or {}
                ax.plot(hours, sg, "-.", color="tab:purple",
                        label=f"filtered: Savitzky–Golay ({p.get('window_sessions')} sessions, "
                              f"order {p.get('polyorder')})")
            if not np.all(np.isnan(dial)):
                ax.plot(hours, dial, "s", ms=3, mfc="none", label="dial indicator (change)")
            if injected is not None:
                ax.plot(injected[0], injected[1], "k--", lw=0.8, label="injected (truth)")
            ax.set_ylabel("Δbacklash (µm)")
            ax.set_title(f"change of backlash by {title}", fontsize=10)
    for ax in axes:
        ax.set_xlabel("operating hours (h)")
        ax.legend(fontsize=7)
    f.tight_layout()
    f.savefig(path, dpi=dpi)
    plt.close(f)
    return Path(path)


def write_figures(result, doc: dict, out_dir, injected=None) -> list[Path]:
    """Write Figs. 7–13 into ``out_dir``; returns their paths.

    Args:
        result: :class:`analysis.phase2.backlash.CampaignBacklash` (Figs. 7–9).
        doc: its ``backlash.json`` object (Figs. 10–13).
        injected: (hours (n,), injected change of backlash (n,) µm) or None (simulations only).
    """
    out = Path(out_dir)
    paths = write_trace_figures(result, out)
    for fig, name in TREND_FIGURES.items():
        paths.append(draw_trend_figure(fig, doc, out / name, injected=injected))
    return paths

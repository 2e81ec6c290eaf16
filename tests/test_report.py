"""Issue 5, check 6: ``twin report DIR`` writes an HTML report that names every figure of the
paper it reproduces (6, 10, 11, 12, 13 and Table III) and links only PNGs that exist in its own
folder; with Phase I missing it says so and names the command; an empty or absent DIR exits 2
naming what is missing. Also: the code of docs/developer-guide.md runs against the current code.

The HTML is parsed with :mod:`html.parser` (headings, tables, links, tag balance), and the values
in it are checked against ``score.json`` / ``backlash.json``, which the report must not alter.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import h5py
import pytest
from conftest import REPO, run_twin

from analysis.report import compare_fig10, compare_fig12, write_report
from analysis.scoring import score

FIGURES = ("6", "10", "11", "12", "13")
VOID = {"meta", "img", "br", "hr", "link", "input"}


class ReportParser(HTMLParser):
    """Headings (tag, id, text), tables {id: rows of cell texts}, PNG links per heading id,
    paragraphs {id: text}, and whether every non-void tag was closed in order."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.headings: list[tuple[str, str, str]] = []
        self.tables: dict[str, list[list[str]]] = {}
        self.links: dict[str, list[str]] = {}
        self.paragraphs: dict[str, str] = {}
        self.text: list[str] = []
        self.stack: list[str] = []
        self.balanced = True
        self._heading = "top"
        self._cap: list[str] | None = None  # text being captured for a heading / cell / paragraph
        self._kind = None
        self._id = None
        self._table = None
        self._row: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag not in VOID:
            self.stack.append(tag)
        if tag in ("h1", "h2", "h3", "h4"):
            self._cap, self._kind, self._id = [], tag, a.get("id", "")
        elif tag == "table":
            self._table = a.get("id", f"table{len(self.tables)}")
            self.tables[self._table] = []
        elif tag == "tr" and self._table is not None:
            self._row = []
        elif tag in ("td", "th") and self._row is not None:
            self._cap, self._kind = [], "cell"
        elif tag == "p" and a.get("id"):
            self._cap, self._kind, self._id = [], "p", a["id"]
        for key in ("src", "href"):
            v = a.get(key)
            if v and v.lower().endswith(".png"):
                self.links.setdefault(self._heading, []).append(v)

    def handle_endtag(self, tag):
        if tag in VOID:
            return
        if not self.stack or self.stack[-1] != tag:
            self.balanced = False
        else:
            self.stack.pop()
        text = "".join(self._cap).strip() if self._cap is not None else None
        if tag in ("h1", "h2", "h3", "h4") and self._kind == tag:
            self.headings.append((tag, self._id, text))
            self._heading, self._cap = self._id or text, None
        elif tag in ("td", "th") and self._kind == "cell" and self._row is not None:
            self._row.append(text)
            self._cap = None
        elif tag == "tr" and self._row is not None:
            self.tables[self._table].append(self._row)
            self._row = None
        elif tag == "table":
            self._table = None
        elif tag == "p" and self._kind == "p" and self._cap is not None:
            self.paragraphs[self._id] = text
            self._cap = None

    def handle_data(self, data):
        self.text.append(data)
        if self._cap is not None:
            self._cap.append(data)


def parse(path: Path) -> ReportParser:
    p = ReportParser()
    p.feed(path.read_text(encoding="utf-8"))
    p.close()
    return p


def rows_by_first(table: list[list[str]]) -> dict[str, dict[str, str]]:
    head, *rows = table
    return {r[0]: dict(zip(head, r, strict=True)) for r in rows}


@pytest.fixture(scope="module")
def analysed(demo_run):
    """The session's ``twin demo`` directory (conftest ``demo_run``: demo.toml at 250 h, 25 Phase I
    samples with the onset at 172 h, three sessions of 3 runs), both phases analysed and scored.
    The tests work on copies without its score.json and report/, so it stays untouched."""
    return demo_run[0]


def workdir(src: Path, dst: Path, parts=("measurements.h5", "truth.h5", "phase1", "backlash")) -> Path:
    """``dst`` with the given parts of ``src`` (HDF5 files linked, output folders copied)."""
    dst.mkdir()
    for p in parts:
        if (src / p).is_dir():
            shutil.copytree(src / p, dst / p)
        else:
            (dst / p).symlink_to(src / p)
    return dst


def check_links(out: Path, page: ReportParser) -> list[Path]:
    """Every linked PNG is a relative path inside ``out`` that exists and is non-empty."""
    files = []
    for heading, links in page.links.items():
        for link in links:
            assert not Path(link).is_absolute() and ".." not in Path(link).parts, link
            f = out / link
            assert f.is_file() and f.stat().st_size > 0, (heading, link)
            files.append(f)
    return files


def test_report_names_every_figure_and_links_existing_pngs(analysed, tmp_path):
    d = workdir(analysed, tmp_path / "camp")
    r = run_twin("report", d)
    out = d / "report"
    page = parse(out / "index.html")
    assert page.balanced and not page.stack, page.stack

    # Every figure and Table III is named, each figure with our PNG in its section.
    ids = {i for _, i, _ in page.headings}
    texts = " ".join(t for *_, t in page.headings)
    for fig in FIGURES:
        assert f"fig{fig}" in ids and f"Fig. {fig}:" in texts, fig
        assert any(link.endswith(".png") for link in page.links.get(f"fig{fig}", [])), fig
    assert "table-iii" in ids and "Table III" in texts
    pngs = check_links(out, page)
    assert len({p.name for p in pngs}) == 8  # detection.png and fig07..fig13
    assert all(p.parent == out / "figures" for p in pngs)

    # score.json was missing: the report computed and wrote it, equal to a fresh scoring.
    assert "score.json computed" in " ".join(r.stderr.split())
    doc = json.loads((d / "score.json").read_text())
    assert doc == score(d)

    # Table III: the paper's hours and ours, from score.json.
    t3 = rows_by_first(page.tables["table-iii"])
    paper = {"PCA": "2972", "GMM": "2972", "SOM": "2972", "IF": "1678*", "OCSVM": "3069", "AE": "2972"}
    keys = {"PCA": "pca_t2", "GMM": "gmm_md", "SOM": "som_mqe", "IF": "iforest", "OCSVM": "ocsvm",
            "AE": "autoencoder"}
    methods = doc["phase1"]["methods"]
    for row, cells in t3.items():
        short = row.split(" ")[0]
        assert cells["paper: detection (h)"] == paper[short]
        h = methods[keys[short]]["detection_hours"]
        assert cells["ours: detection (h)"] == ("–" if h is None else f"{h:g}")
    assert [r.split(" ")[0] for r in t3] == list(paper)
    assert f"Injected onset here: {doc['phase1']['onset_hours']:g} h" in " ".join(page.text)

    # Phase II: the per-session table and the summary carry score.json's values.
    p2 = doc["phase2"]
    sessions = rows_by_first(page.tables["phase2-sessions"])
    assert list(sessions) == [s["session"] for s in p2["sessions"]]
    for s in p2["sessions"]:
        assert sessions[s["session"]]["estimated Δ (µm)"] == f"{s['estimated_delta_um']:.3f}"
        assert sessions[s["session"]]["injected Δ (µm)"] == f"{s['injected_delta_um']:.3f}"
    summary = rows_by_first(page.tables["phase2-summary"])
    assert summary["RMS error (µm)"]["value"] == f"{p2['rms_error_um']:.3f}"

    # The comparison lines are computed from our data.
    last = p2["sessions"][-1]
    fig13 = page.paragraphs["compare-fig13"]
    est, inj = last["estimated_delta_um"], last["injected_delta_um"]
    assert f"estimated {est:.3g} µm, injected {inj:.3g} µm" in fig13
    bl = json.loads((d / "backlash" / "backlash.json").read_text())
    g = {k: v for k, v in bl["sessions"][-1]["gamma"].items() if k != "E_XX"}
    assert max(g, key=g.get) in page.paragraphs["compare-fig12"]
    fig6 = page.paragraphs["compare-fig6"]
    t2 = methods["pca_t2"]["detection_hours"]
    assert f"PCA-T² detects at {t2:g} h" in fig6
    print(f"\nreport: {len(set(pngs))} PNGs; PCA-T² {t2:g} h (onset {doc['phase1']['onset_hours']:g} h); "
          f"Phase II RMS error {p2['rms_error_um']:.3f} µm\n{fig13}")


def test_phase2_only_report_says_phase1_is_missing_and_escapes_text(analysed, tmp_path):
    d = workdir(analysed, tmp_path / "p2", parts=("backlash",))
    (d / "backlash" / "fig13_backlash.png").unlink()  # drawn from backlash.json instead
    shutil.copy(analysed / "truth.h5", d / "truth.h5")
    with h5py.File(d / "truth.h5", "r+") as f:  # a scenario name that must be escaped
        scen = json.loads(f.attrs["scenario"])
        scen["name"] = "<b>x & y</b>"
        f.attrs["scenario"] = json.dumps(scen)
    index = write_report(d)
    assert index == d / "report" / "index.html"
    page = parse(index)
    html_text = index.read_text()
    assert page.balanced and not page.stack
    assert "&lt;b&gt;x &amp; y&lt;/b&gt;" in html_text and "<b>x & y</b>" not in html_text
    text = " ".join(" ".join(page.text).split())
    assert f"Phase I missing: {d / 'phase1' / 'detection.json'} not found" in text
    assert f"twin detect {d} --reference REF" in text
    assert not page.links.get("fig6")
    for row in rows_by_first(page.tables["table-iii"]).values():
        assert row["ours: detection (h)"] == "–"
    bl = json.loads((d / "backlash" / "backlash.json").read_text())
    assert len(page.tables["phase2-sessions"]) == 1 + len(bl["sessions"])
    for fig in ("10", "11", "12"):
        link = page.links[f"fig{fig}"][0]
        assert link.startswith(f"figures/fig{fig}_") and "drawn" not in link
    assert page.links["fig13"][0] == "figures/fig13_drawn.png"
    check_links(d / "report", page)
    assert json.loads((d / "score.json").read_text())["phase1"] is None


def test_empty_or_absent_directory_exits_2_naming_what_is_missing(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    r = run_twin("report", empty, check=False)
    err = " ".join(r.stderr.split())
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    for name in ("measurements.h5", "truth.h5", "phase1/detection.json", "backlash/backlash.json"):
        assert name in err, name
    r = run_twin("report", tmp_path / "absent", check=False)
    assert r.returncode == 2 and "no such directory" in r.stderr


def test_comparison_lines_follow_the_data():
    """The Fig. 10 and Fig. 12 lines change their verdict with the data (not hard-coded)."""
    def session(h, fwd, rev, gamma):
        return {"session": f"s{h}", "hours": float(h),
                "position_shift_um": {"E_XX/forward": fwd, "E_XX/reverse": rev},
                "gamma": gamma}
    common = {"parameters": {"dofs": ["E_YX"], "sigma": 4},
              "sessions": [session(0, 0.0, 0.0, {}),
                           session(1, 1500.0, 1490.0, {"E_XX": 1.0, "E_YX": 0.99, "E_ZX": 0.9})]}
    assert "common-mode, as in the paper" in compare_fig10(common)
    assert "up to 1.5 mm" in compare_fig10(common) and "at most 10 µm" in compare_fig10(common)
    assert "E_YX 1×" in compare_fig12(common) and "as in the paper" in compare_fig12(common)
    apart = {"parameters": {"dofs": ["E_YX"], "sigma": 4},
             "sessions": [session(0, 0.0, 0.0, {}),
                          session(1, 100.0, -100.0, {"E_YX": 0.5, "E_ZX": 0.9})]}
    assert "not common-mode" in compare_fig10(apart)
    assert "E_ZX 1×" in compare_fig12(apart) and "(paper: E_YX every time)" in compare_fig12(apart)


def test_developer_guide_code_runs(analysed, tmp_path):
    """Every ```python block of docs/developer-guide.md runs (``runs/demo`` is the fixture's
    directory) and prints what it claims."""
    guide = (REPO / "docs" / "developer-guide.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", guide, flags=re.DOTALL)
    assert len(blocks) >= 3
    d = workdir(analysed, tmp_path / "demo")
    # A sweep's output as twin.harness.sweep writes it, with the demo's scores for its first two tasks.
    from twin.harness.sweep import plan_sweep, point_dir, records, results_table, write_table
    from twin.harness.sweep.plots import roc_table

    sweep = tmp_path / "sweep"
    plan = plan_sweep(REPO / "scenarios/sweeps/detection.toml")
    doc = score(d)
    for t in plan.tasks[:2]:
        point_dir(sweep, t).mkdir(parents=True)
        (point_dir(sweep, t) / "result.json").write_text(json.dumps({"score": doc, "error": None}))
    write_table(results_table(plan, sweep), sweep)
    roc_table(records(plan, sweep)).to_csv(sweep / "roc.csv", index=False)
    blocks = [b.replace('"runs/demo"', repr(str(d))).replace('"runs/sweeps/detection"', repr(str(sweep)))
              for b in blocks]
    # One interpreter, a fresh namespace per block (saves the imports of five processes).
    driver = ("import json, sys, traceback\n"
              "for i, code in enumerate(json.loads(sys.stdin.read())):\n"
              "    print(f'--- guide block {i} ---', flush=True)\n"
              "    try:\n"
              "        exec(compile(code, f'<guide block {i}>', 'exec'), {'__name__': '__main__'})\n"
              "    except BaseException:\n"
              "        traceback.print_exc()\n"
              "        sys.exit(f'guide block {i} failed')\n")
    r = subprocess.run([sys.executable, "-c", driver], input=json.dumps(blocks), cwd=REPO, check=False,
                       capture_output=True, text=True, timeout=600,
                       env=dict(os.environ, PYTHONPATH=str(REPO)))
    print("\n" + r.stdout)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert r.stdout.count("--- guide block") == len(blocks)
    assert "KNNDistance" in r.stdout and "MedianBacklash" in r.stdout
    assert "rejected: scenarios/demo.toml: key `degradation.wear_rate_um_per_kh` = -1" in r.stdout
    # Section 3: a law by module:Class, a gap-diagnosis candidate.
    assert "onset 100 h; preload [0.962 0.6   0.238]; backlash [0.47 5.   9.53] µm" in r.stdout
    assert "rejected: scenarios/demo.toml: key `degradation.midpoint_hours` = -5.0: allowed >= 0." in r.stdout
    assert "and for the degradation law 'mylaws:Sigmoid': midpoint_hours, width_hours" in r.stdout
    assert "carriage with HEAVY at 40 kg: 160.0 kg" in r.stdout
    assert f"detection: {plan.n_points} points x {len(plan.seeds)} seeds" in r.stdout
    assert "sensors.imu_noise" in r.stdout.split("rejected:")[-1]

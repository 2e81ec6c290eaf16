"""The HTML report of one analysed campaign directory: the scenario, the scores of both phases,
and the paper's Table III and Figs. 6, 10, 11, 12, 13 side by side with ours.

:func:`write_report` reads only what the analyses wrote (it never reruns an estimator):

- ``DIR/truth.h5``: the scenario and the injected onset (absent for a real machine's recordings;
  the axis description of ``DIR/measurements.h5`` is shown instead);
- ``DIR/score.json`` (:mod:`analysis.scoring`); if it is missing, or older than the analysis
  outputs, and ``truth.h5`` is there, it is computed with :func:`analysis.scoring.score` and
  written;
- ``DIR/phase1/detection.json``, ``detection_details.json``, ``detection.png`` (``twin detect``);
  without ``detection.png`` the Fig. 6 analogue is drawn from ``detection.json``;
- ``DIR/backlash/backlash.json`` and ``fig07`` … ``fig13`` PNGs (``twin backlash``).

It writes ``OUT/index.html`` (default ``OUT = DIR/report``) and copies every PNG it shows into
``OUT/figures`` with relative links, so the folder is self-contained. A phase whose outputs are
missing gets a section that says so and names the command that creates them.

The paper's figures are not reproduced as images: each figure's findings are given in words with
the paper's numbers (:data:`PAPER_FIGURES`, :data:`PAPER_TABLE_III`), next to our PNG and one
line computed from our data (the ``compare_*`` functions). Units: h, µm, µrad, mm as named.
"""

from analysis.report.compare import compare_fig6, compare_fig10, compare_fig11, compare_fig12, compare_fig13
from analysis.report.inputs import ReportError, read_inputs
from analysis.report.page import INPUT_ERRORS, Report, render, write_report
from analysis.report.paper import PAPER_FIGURES, PAPER_TABLE_III

__all__ = [
    "INPUT_ERRORS",
    "PAPER_FIGURES",
    "PAPER_TABLE_III",
    "Report",
    "ReportError",
    "compare_fig6",
    "compare_fig10",
    "compare_fig11",
    "compare_fig12",
    "compare_fig13",
    "read_inputs",
    "render",
    "write_report",
]

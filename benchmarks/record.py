"""The figures the README and the docs quote, kept in ``docs/validation.json`` by the benchmarks
that measure them, and written into the docs from there.

A benchmark run with ``--record`` stores its figures under its own name::

    {"bench_demo": {"command": ".venv/bin/python benchmarks/bench_demo.py --record",
                    "scale": "...", "machine": "...", "load_average_1min": 0.4,
                    "figures": {"pca_t2_first_alarm_h": {"text": "182", "value": 182.0}, ...},
                    "tables": {"table3": "| method | ... |\\n|---|...|\\n..."}}}

A test measures figures too: its ``quote`` fixture (tests/conftest.py) records them under the
test file's name, with ``TWIN_RECORD=1`` (what ``make validate`` sets for the tests marked
``quoted``). A doc quotes a figure as ``<!-- fig:bench_demo.pca_t2_first_alarm_h -->182<!-- /fig -->`` and a
whole table between ``<!-- table:bench_table3.table3 -->`` and ``<!-- /table -->`` (HTML comments:
invisible where the Markdown is rendered). ``python benchmarks/record.py`` (what ``make validate``
runs last) rewrites every such span from the JSON; ``tests/test_quoted_figures.py`` fails when a
span and the JSON disagree, so no quoted figure is typed by hand.
"""

from __future__ import annotations

import json
import os
import platform
import re
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
VALIDATION_JSON = REPO / "docs" / "validation.json"
#: Files whose quoted figures come from the JSON.
QUOTING = ("README.md", "docs/*.md")
FIGURE = re.compile(r"<!-- fig:([\w.]+) -->(.*?)<!-- /fig -->", re.S)
TABLE = re.compile(r"(<!-- table:([\w.]+) -->\n)(.*?)(<!-- /table -->)", re.S)


def machine() -> str:
    """The machine a figure was measured on: CPU model and cores (figures of speed depend on it)."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores, Python {platform.python_version()}"


def text(v: float | None, fmt: str = "{:.2f}") -> str:
    """A figure as the docs write it: ``fmt`` (e.g. ``"{:+.2f}"`` for a sign), a real minus
    sign (−), never −0.00, and – for a figure that does not exist (None)."""
    if v is None:
        return "–"
    out = fmt.format(v)
    if float(out) == 0.0:
        out = fmt.format(0.0)
    return out.replace("-", "−")


def load(path: Path = VALIDATION_JSON) -> dict:
    return json.loads(path.read_text()) if path.is_file() else {}


def record(bench: str, *, command: str, scale: str, figures: dict[str, tuple[float | None, str]],
           tables: dict[str, str] | None = None, path: Path = VALIDATION_JSON, merge: bool = False) -> None:
    """Store the figures of benchmark ``bench`` (replacing its earlier ones).

    Args:
        bench: the benchmark's name (its file's stem; a test file's for the figures its tests quote).
        command: the command that re-measures them.
        scale: what was run (campaign, scale, seeds), in words.
        figures: name -> (value in the unit the docs quote, the text the docs show).
        tables: name -> a Markdown table the docs show whole.
        merge: keep the entry's other figures and tables (one test of a file records its own).
    """
    doc = load(path)
    old = doc.get(bench, {}) if merge else {}
    doc[bench] = {"command": command, "scale": scale, "machine": machine(),
                  "load_average_1min": round(os.getloadavg()[0], 2),
                  "figures": {**old.get("figures", {}),
                              **{k: {"value": v, "text": t} for k, (v, t) in figures.items()}},
                  "tables": {**old.get("tables", {}), **dict(tables or {})}}
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(dict(sorted(doc.items())), indent=1, ensure_ascii=False) + "\n")
    os.replace(tmp, path)


def quoting_files(root: Path = REPO) -> list[Path]:
    return sorted({p for pattern in QUOTING for p in root.glob(pattern)})


def lookup(doc: dict, key: str, kind: str) -> str:
    """The text of figure (``kind="figures"``) or table (``"tables"``) ``bench.name``.

    Raises:
        KeyError: no such benchmark or figure in the JSON, named.
    """
    bench, _, name = key.partition(".")
    try:
        return doc[bench][kind][name] if kind == "tables" else doc[bench][kind][name]["text"]
    except KeyError:
        raise KeyError(f"{key}: not in {VALIDATION_JSON.name} (run the benchmark {bench} with --record)") from None


def render(text: str, doc: dict) -> str:
    """``text`` with every quoted figure and table replaced by the JSON's."""
    text = FIGURE.sub(lambda m: f"<!-- fig:{m[1]} -->{lookup(doc, m[1], 'figures')}<!-- /fig -->", text)
    return TABLE.sub(lambda m: f"{m[1]}{lookup(doc, m[2], 'tables').rstrip()}\n{m[4]}", text)


def main() -> int:
    doc = load()
    changed = []
    for p in quoting_files():
        old = p.read_text()
        new = render(old, doc)
        if new != old:
            p.write_text(new)
            changed.append(str(p.relative_to(REPO)))
    print(f"{len(changed)} file(s) rewritten from {VALIDATION_JSON.relative_to(REPO)}: {', '.join(changed) or '-'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

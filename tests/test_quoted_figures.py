"""Every figure the README and the docs quote between ``<!-- fig:... -->`` markers (and every
table between ``<!-- table:... -->`` markers) is the one ``docs/validation.json`` holds, which the
benchmarks write with ``--record`` (``make validate``): a figure typed by hand, or left behind when
the JSON changed, fails here. ``python benchmarks/record.py`` rewrites the docs from the JSON."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from conftest import REPO, record_module

record = record_module()

DOC = record.load()
FILES = record.quoting_files(REPO)


def _quotes(kind: str) -> list[tuple[str, str, str]]:
    """(file, key, quoted text) of every figure (``fig``) or table (``table``) marker."""
    out = []
    for p in FILES:
        text = p.read_text()
        pattern = record.FIGURE if kind == "fig" else record.TABLE
        for m in pattern.finditer(text):
            key, quoted = (m[1], m[2]) if kind == "fig" else (m[2], m[3].rstrip())
            out.append((str(p.relative_to(REPO)), key, quoted))
    return out


def test_the_docs_quote_figures_from_the_json():
    # the walk must find the quotes, or the tests below pass vacuously
    assert any(f == "README.md" for f, _, _ in _quotes("fig"))
    assert any(f == "docs/validation.md" for f, _, _ in _quotes("table"))


@pytest.mark.parametrize("where,key,quoted", _quotes("fig"), ids=lambda v: str(v)[:60])
def test_a_quoted_figure_is_the_json_s(where, key, quoted):
    assert quoted == record.lookup(DOC, key, "figures"), (
        f"{where} quotes {key} as {quoted!r}; docs/validation.json says "
        f"{record.lookup(DOC, key, 'figures')!r} (python benchmarks/record.py rewrites the docs)")


@pytest.mark.parametrize("where,key,quoted", _quotes("table"), ids=lambda v: str(v)[:60])
def test_a_quoted_table_is_the_json_s(where, key, quoted):
    assert quoted == record.lookup(DOC, key, "tables").rstrip(), (
        f"{where}: the table {key} differs from docs/validation.json's (python benchmarks/record.py)")


def test_every_benchmark_in_the_json_names_the_command_that_re_measures_it():
    assert DOC, "docs/validation.json is empty"
    for bench, entry in DOC.items():
        script = "--record" in entry["command"] and re.search(r"benchmarks/(\w+)\.py", entry["command"])
        test = re.fullmatch(r"TWIN_RECORD=1 \.venv/bin/python -m pytest -m quoted (tests/test_\w+\.py)",
                            entry["command"])
        assert (script and (REPO / "benchmarks" / f"{script[1]}.py").is_file()) or (
            test and (REPO / test[1]).is_file() and bench == Path(test[1]).stem), (bench, entry["command"])
        assert entry["scale"] and entry["machine"], bench


def test_a_marker_whose_key_is_missing_is_named():
    with pytest.raises(KeyError, match=r"bench_demo\.no_such_figure: not in validation\.json"):
        record.render("<!-- fig:bench_demo.no_such_figure -->1<!-- /fig -->", DOC)


def test_the_readme_stays_short():
    # the README is for users: the two commands, then each part; measured tables live in the docs
    n = len((REPO / "README.md").read_text().splitlines())
    assert n <= 200, f"README.md has {n} lines (at most 200: move detail to docs/)"


def test_render_replaces_what_a_span_holds_and_nothing_else():
    doc = {"b": {"figures": {"x": {"value": 1.5, "text": "1.50"}}, "tables": {"t": "| a |\n|---|\n| 1 |"}}}
    text = ("before <!-- fig:b.x -->9.99<!-- /fig --> after\n"
            "<!-- table:b.t -->\n| old |\n<!-- /table -->\nend\n")
    out = record.render(text, doc)
    assert out == ("before <!-- fig:b.x -->1.50<!-- /fig --> after\n"
                   "<!-- table:b.t -->\n| a |\n|---|\n| 1 |\n<!-- /table -->\nend\n")
    assert record.render(out, doc) == out  # idempotent: a rendered page is what the test reads

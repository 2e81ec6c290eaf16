"""The verb's body and its JUnit XML: the checks asked for, run on the methods named, written
for a CI's test report.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from xml.etree import ElementTree as ET

from twin.harness.gate.cache import cache_dir, ensure_cache, package_version, verify
from twin.harness.gate.checks import CheckResult, resolve_methods, run_gate, select_checks
from twin.harness.gate.suite import GateError, Suite, get_suite

# ---------------------------------------------------------------------------------------------
# JUnit XML


def junit_xml(results: Sequence[CheckResult], suite: Suite, path: str | Path) -> None:
    """Write ``results`` as JUnit XML (one ``testsuite`` per method, one ``testcase`` per check,
    ``failure`` with the figure or the error): the form Jenkins, GitLab CI, GitHub Actions
    reporters and Azure Pipelines read."""
    root = ET.Element("testsuites", name=f"twin gate {suite.name} v{suite.version}",
                      tests=str(len(results)), failures=str(sum(not r.passed for r in results)),
                      time=f"{sum(r.seconds for r in results):.3f}")
    groups: dict[tuple[str, str], list[CheckResult]] = {}
    for r in results:
        groups.setdefault((r.kind, r.method), []).append(r)
    for (kind, method), rs in groups.items():
        ts = ET.SubElement(root, "testsuite", name=f"{kind}.{method}", tests=str(len(rs)),
                           failures=str(sum(not r.passed for r in rs)), errors="0", skipped="0",
                           time=f"{sum(r.seconds for r in rs):.3f}")
        props = ET.SubElement(ts, "properties")
        for k, v in (("suite", suite.name), ("suite_version", str(suite.version)),
                     ("package_version", package_version())):
            ET.SubElement(props, "property", name=k, value=v)
        for r in rs:
            tc = ET.SubElement(ts, "testcase", classname=f"twin.gate.{kind}.{method}", name=r.check,
                               time=f"{r.seconds:.3f}")
            text = f"{r.what}\nfigure: {r.figure}\ntolerance: {r.tolerance}\n" + "".join(
                f"  {s}: injected {i:g} µm, estimated {g:.3f} µm, tolerance {t:.2f} µm\n" for s, i, g, t in r.rows)
            if not r.passed:
                f = ET.SubElement(tc, "failure", message=(r.error or f"{r.figure}; tolerance {r.tolerance}"),
                                  type="error" if r.error else "tolerance")
                f.text = text
            ET.SubElement(tc, "system-out").text = text
    ET.indent(root)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)


# ---------------------------------------------------------------------------------------------
# The command


def _default(kind: str) -> list[str]:
    from analysis.base import registry

    return [registry.default(kind).name]


def _expand(kind: str, specs: Sequence[str]) -> list[str]:
    from analysis.base import registry

    out: list[str] = []
    for s in specs:
        out.extend(registry.names(kind) if s == "all" else [s])
    return resolve_methods(kind, out)


def command(estimators: Sequence[str], detectors: Sequence[str], suite: str = "standard",
            junit: str | Path | None = None, root: str | Path | None = None,
            checks: Sequence[str] = (), rebuild: bool = False, console=None) -> int:
    """``twin gate``: verify or build the cache, run the checks, print one row per check (figure,
    tolerance, verdict) and the times, write JUnit XML if asked. Returns the exit code: 0 if
    every check passed, 1 otherwise. Without ``estimators`` and ``detectors``: the default
    estimator and the default detector (the paper's methods); ``all`` stands for every
    registered one. Raises :class:`GateError` on bad input (exit 2)."""
    from rich.console import Console

    console = console or Console()
    s = get_suite(suite)
    if not estimators and not detectors:
        estimators, detectors = _default("backlash_estimators"), _default("detectors")
    estimators, detectors = _expand("backlash_estimators", estimators), _expand("detectors", detectors)
    b_checks, d_checks = select_checks(s, checks)
    if not ((b_checks and estimators) or (d_checks and detectors)):
        raise GateError(f"no check to run: {len(b_checks)} backlash checks for {len(estimators)} estimators, "
                        f"{len(d_checks)} detection checks for {len(detectors)} detectors")
    folder = cache_dir(root, s)
    if (rebuild or verify(folder, s) is not None) and not _has_simulator():
        raise GateError(f"gate cache {folder} must be built, which needs the simulator: "
                        "pip install 'ballscrew-twin[sim]' (or restore the cache folder)")
    t0 = time.perf_counter()
    cache = ensure_cache(root, s, rebuild=rebuild,
                         log=lambda line: console.print(line, markup=False, highlight=False, soft_wrap=True))
    t_cache = time.perf_counter() - t0

    def on_result(r: CheckResult) -> None:
        console.print(f"{'PASS' if r.passed else 'FAIL'}  {r.kind} {r.check} [{r.method}]: {r.figure}; "
                      f"tolerance {r.tolerance}", markup=False, highlight=False, soft_wrap=True,
                      style="green" if r.passed else "red")

    console.print(f"suite {s.name} v{s.version}, package {package_version()}", markup=False,
                  highlight=False, soft_wrap=True)
    t0 = time.perf_counter()
    results = run_gate(estimators if b_checks else [], detectors if d_checks else [], cache,
                       checks, on_result)
    t_checks = time.perf_counter() - t0
    failed = [r for r in results if not r.passed]
    how = (f"cache built in {cache.build_seconds:.0f} s" if cache.build_seconds is not None
           else f"cache verified in {t_cache:.1f} s")
    console.print(f"{len(results)} checks, {len(failed)} failed; checks took {t_checks:.1f} s, {how} "
                  f"({cache.folder})", markup=False, highlight=False, soft_wrap=True)
    if junit is not None:
        junit_xml(results, s, junit)
        console.print(f"wrote {junit}", markup=False, highlight=False)
    return 1 if failed or not results else 0


def _has_simulator() -> bool:
    import importlib.util

    return importlib.util.find_spec("mujoco") is not None

"""The arrows of the layout, read from the source (docs/architecture.md).

twin.cli -> twin.harness -> twin.sim (the simulator) -> analysis. The imports of every module of the two
packages are collected with :mod:`ast` (top-level and function-level alike, relative imports
resolved), so nothing here lists modules by hand: a new module is checked the day it appears.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("twin", "analysis")
FORBIDDEN_IN_ANALYSIS = ("twin", "mujoco", "rerun")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    found = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            found[_module_name(path)] = path
    return found


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """Absolute names of every module `name` imports (the longest known prefix for package code)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_package = path.name == "__init__.py"
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base if is_package else base[:-1]
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.add(mod)
            # `from pkg import module` imports a module, not only a name
            out.update(f"{mod}.{alias.name}" for alias in node.names if f"{mod}.{alias.name}" in MODULES)
    return out


def _project_target(imported: str) -> str | None:
    """The project module an import resolves to (the longest prefix that is one), or None."""
    parts = imported.split(".")
    for k in range(len(parts), 0, -1):
        cand = ".".join(parts[:k])
        if cand in MODULES:
            return cand
    return None


IMPORTS = {name: _imports(name, path) for name, path in MODULES.items()}


def _in(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


def test_the_walk_sees_the_packages():
    # a broken walk (wrong root, nothing parsed) must not pass the tests below vacuously
    assert any(_in(m, "analysis.phase2") for m in MODULES)
    assert any(_in(m, "twin.harness") for m in MODULES)
    assert "twin.cli" in MODULES
    assert any(_project_target(i) for i in IMPORTS["twin.cli"])


@pytest.mark.parametrize("name", sorted(m for m in MODULES if _in(m, "analysis")))
def test_analysis_imports_neither_twin_nor_mujoco_nor_rerun(name):
    bad = sorted(i for i in IMPORTS[name] if i.split(".")[0] in FORBIDDEN_IN_ANALYSIS)
    assert not bad, f"{name} ({MODULES[name].relative_to(ROOT)}) imports {bad}"


def test_the_shared_base_imports_nothing_of_the_project_beyond_itself():
    # registry, files and executors serve both halves: they may not pull either in
    for name in (m for m in MODULES if _in(m, "analysis.base")):
        bad = sorted(i for i in IMPORTS[name] if _project_target(i) and not _in(_project_target(i), "analysis.base"))
        assert not bad, f"{name} imports {bad}"


def test_twin_holds_its_three_layers_as_folders():
    # the simulator, the harness and the face, each a package; nothing loose beside them
    loose = sorted(p.name for p in (ROOT / "twin").iterdir()
                   if p.suffix == ".py" and p.stem not in ("__init__", "__main__"))
    assert not loose, f"modules loose in twin/: {loose} (twin/sim/, twin/harness/ or twin/cli/)"
    assert {"twin.sim", "twin.harness", "twin.cli"} <= set(MODULES)


@pytest.mark.parametrize("name", sorted(m for m in MODULES if _in(m, "twin.sim")))
def test_simulator_imports_nothing_of_the_harness_or_cli(name):
    bad = sorted(i for i in IMPORTS[name] if _in(i, "twin.harness") or _in(i, "twin.cli"))
    assert not bad, f"{name} ({MODULES[name].relative_to(ROOT)}) imports {bad}"


@pytest.mark.parametrize("name", sorted(m for m in MODULES if _in(m, "twin.harness")))
def test_harness_does_not_import_the_cli(name):
    bad = sorted(i for i in IMPORTS[name] if _in(i, "twin.cli"))
    assert not bad, f"{name} imports {bad}"


def _graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for name, imports in IMPORTS.items():
        targets = {_project_target(i) for i in imports} - {None, name}
        # importing a submodule runs its package's __init__ first; that edge is not a cycle of ours
        graph[name] = {t for t in targets if not _in(name, t)}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle():
    cycles = _cycles(_graph())
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_no_source_file_is_over_500_lines():
    # one concept per module: a file that grows past this holds several jobs; split it along them
    long = {str(p.relative_to(ROOT)): n for p in MODULES.values()
            if (n := len(p.read_text().splitlines())) > 500}
    assert not long, f"source files over 500 lines: {long}"

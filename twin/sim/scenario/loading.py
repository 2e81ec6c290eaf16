"""Loading a scenario with readable errors: a TOML file or a shipped scenario by name
(:func:`load`, :func:`find_scenario`), ``KEY=VALUE`` overrides (:func:`parse_override`), and the
validation of a dict (:func:`from_dict`) whose errors name the key, the value and what is
allowed (:class:`ScenarioError`).
"""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from twin.sim.config import explain_errors, set_dotted
from twin.sim.scenario.document import Scenario


class ScenarioError(ValueError):
    """A scenario that cannot be used; the message is one paragraph naming key, value, allowed."""


def parse_override(text: str) -> tuple[str, Any]:
    """Parse ``KEY=VALUE`` (VALUE as TOML, else a plain string)."""
    if "=" not in text:
        raise ScenarioError(f"--set {text!r}: expected KEY=VALUE, e.g. phase2.runs_per_session=10")
    key, raw = text.split("=", 1)
    key = key.strip()
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return key, value


def from_dict(data: dict[str, Any], source: str = "scenario") -> Scenario:
    """Validate a scenario dict; raises :class:`ScenarioError` with one paragraph per problem."""
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        raise ScenarioError(explain_errors(exc, data, source, Scenario)) from None


def read_toml(path: str | Path, what: str, error: type[Exception] = ValueError) -> dict[str, Any]:
    """The TOML document of ``path`` (a scenario or a sweep file, named ``what`` in messages);
    an unreadable file or invalid TOML raises ``error`` naming the file."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise error(f"{path}: cannot read the {what} ({exc.strerror}).") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML: {exc}.") from None


#: The scenarios shipped with the package (``scenarios/`` of the checkout, package data once
#: installed): found by name, e.g. ``twin simulate quick``.
SHIPPED = Path(__file__).parents[2] / "scenarios"


def shipped_names() -> list[str]:
    """Names of the shipped scenarios (file stems), sorted."""
    return sorted(p.stem for p in SHIPPED.glob("*.toml"))


def find_scenario(path: str | Path) -> Path:
    """``path`` if it exists, else the shipped scenario of that name (``quick`` or
    ``quick.toml``); an unknown name raises :class:`ScenarioError` listing the shipped ones."""
    path = Path(path)
    if path.exists() or len(path.parts) != 1:
        return path
    shipped = SHIPPED / (path.name if path.suffix == ".toml" else f"{path.name}.toml")
    if shipped.is_file():
        return shipped
    raise ScenarioError(f"{path}: no such file, nor a shipped scenario; shipped scenarios: "
                        f"{', '.join(shipped_names())}")


def load(path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> Scenario:
    """Read a TOML scenario (a file, or a shipped scenario by name: :func:`find_scenario`) and
    apply ``KEY=VALUE`` overrides."""
    path = find_scenario(path)
    data = copy.deepcopy(read_toml(path, "scenario file", ScenarioError))
    for item in overrides:
        key, value = parse_override(item)
        set_dotted(data, key, value, source=f"{path}: --set", error=ScenarioError)
    return from_dict(data, source=str(path))

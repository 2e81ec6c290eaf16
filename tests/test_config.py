"""Dotted keys (``--set``, sweep axes, effects) and the validation messages of twin.sim.config."""

from __future__ import annotations

import pytest
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from twin.sim.config import explain_errors, get_dotted, set_dotted


def test_set_and_get_dotted_keys_with_list_elements():
    d = {"a": {"b": [1.0, 2.0, 3.0]}, "c": 4}
    set_dotted(d, "a.b[2]", 9.0)
    set_dotted(d, "x.y", 5)  # missing sections are created
    assert d == {"a": {"b": [1.0, 2.0, 9.0]}, "c": 4, "x": {"y": 5}}
    assert get_dotted(d, "a.b[1]") == 2.0 and get_dotted(d, "a.b") == [1.0, 2.0, 9.0]


@pytest.mark.parametrize("key, message", [
    ("a.b[3]", "key `a.b[3]`: index 3 is beyond the list `b` = [1.0, 2.0] (length 2); allowed: 0 <= i < 2."),
    ("c.d", "key `c.d`: `c` is a value, not a section."),
    ("a[0]", "key `a[0]`: `a` is {'b': [1.0, 2.0]}, not a list; allowed: `[i]` only on list-valued keys."),
    ("a.b-c", "key `a.b-c` is not a scenario key"),
])
def test_bad_keys_name_the_source_and_the_key(key, message):
    d = {"a": {"b": [1.0, 2.0]}, "c": 4}
    with pytest.raises(ValueError) as exc:
        set_dotted(d, key, 1.0, source="sweep.toml: [set]", error=ValueError)
    assert str(exc.value).startswith("sweep.toml: [set]: ") and message in str(exc.value)


def test_get_of_a_missing_key_says_missing():
    with pytest.raises(KeyError, match=r"effect e: key `x\.y` is missing"):
        get_dotted({"a": 1}, "x.y", source="effect e")
    with pytest.raises(KeyError, match=r"key `a\.z` is missing"):
        get_dotted({"a": {"b": 1}}, "a.z")


class _Inner(BaseModel):
    model_config = ConfigDict(extra="forbid")
    rate_hz: float = Field(10.0, gt=0)


class _Root(BaseModel):
    model_config = ConfigDict(extra="forbid")
    inner: _Inner = Field(default_factory=_Inner)
    items: list[_Inner] = Field(default_factory=list)


def test_validation_messages_name_file_key_value_and_what_is_allowed():
    data = {"inner": {"rate_hz": -1.0, "rte": 2}, "items": [{"rate_hz": 1.0, "x": 1}]}
    with pytest.raises(ValidationError) as exc:
        _Root.model_validate(data)
    msg = explain_errors(exc.value, data, "s.toml", _Root)
    assert "s.toml: key `inner.rate_hz` = -1.0 is out of range; allowed: value > 0.0." in msg
    assert "s.toml: unknown key `inner.rte` (value 2); allowed keys in [inner]: rate_hz." in msg
    assert "s.toml: unknown key `items[0].x` (value 1); allowed keys in [[items]]: rate_hz." in msg

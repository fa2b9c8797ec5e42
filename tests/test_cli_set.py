"""``--set`` parsing follows the config declarations: it refuses what the config refuses, naming the same
dotted field, and parses a field of any declared type without a rule of its own for that type."""

from __future__ import annotations

import dataclasses
import datetime
import re
from typing import Annotated, Any, ClassVar, Literal

import pytest
from pydantic import AfterValidator, Field

import agentsim_env
from agentsim_env.cli_set import parse_set
from agentsim_env.core.config_model import FieldError, Int, Real, Text, config
from agentsim_env.scenarios.registry import scenario_class


def _leaves(cls: type, prefix: str = "") -> list[tuple[str, type, str]]:
    """(dotted key, owning class, field name) of every field of ``cls`` and of its sub-configs."""
    out = []
    subs = dict(getattr(cls, "nested", None) or {})
    for f in dataclasses.fields(cls):
        out.append((prefix + f.name, cls, f.name))
        if f.name in subs:
            out += _leaves(subs[f.name], f"{prefix}{f.name}.")
    return out


def _python_error(top: type, key: str, value: Any) -> str:
    """The dotted field a config names when ``key`` is given ``value`` in Python."""
    *parents, leaf = key.split(".")
    kwargs: dict[str, Any] = {leaf: value}
    for p in reversed(parents):
        kwargs = {p: kwargs}
    with pytest.raises(ValueError) as err:
        top(**kwargs)
    assert isinstance(err.value, FieldError), str(err.value)
    return err.value.field


def _set_error(top: type, key: str, text: str) -> str:
    """The dotted field ``--set key=text`` names in its error."""
    with pytest.raises(ValueError) as err:
        parse_set(top, [f"{key}={text}"])
    found = re.match(r"--set ([\w.]+): ", str(err.value))
    assert found, str(err.value)
    return found.group(1)


CASES = [
    (name, key, owner, field)
    for name in agentsim_env.list_scenarios()
    for key, owner, field in _leaves(scenario_class(name).config_cls)
    if owner.__pydantic_fields__[field].annotation is not Any  # an Any field takes every value
]


@pytest.mark.parametrize(("scenario", "key", "owner", "field"), CASES, ids=[f"{c[0]}:{c[1]}" for c in CASES])
def test_set_and_construction_refuse_the_same_field(scenario: str, key: str, owner: type, field: str) -> None:
    top = scenario_class(scenario).config_cls
    # a control character is of no declared type: not a number, flag, list, choice, sub-config or printable text
    assert _set_error(top, key, "\x01") == _python_error(top, key, "\x01").split("[")[0] == key
    # below a declared lower bound: refused by both, named by both
    schema = owner.__pydantic_fields__[field]
    low = next((m for m in schema.metadata if hasattr(m, "ge") or hasattr(m, "gt")), None)
    if low is not None:
        bound = getattr(low, "ge", None)
        bad = (bound - 1) if bound is not None else low.gt
        bad = int(bad) if schema.annotation is int else float(bad)
        assert _set_error(top, key, str(bad)) == _python_error(top, key, bad) == key


def test_the_cases_cover_the_scenarios() -> None:
    assert {c[0] for c in CASES} == set(agentsim_env.list_scenarios())
    assert any(c[1].count(".") >= 2 for c in CASES)  # sub-configs of sub-configs too (wsn.radio.*)


def _even(n: int) -> int:
    """A rule of the test's own: ``n`` must be even."""
    if n % 2:
        raise ValueError("must be even")
    return n


@config()
class _Novel:
    """Field types cli_set has never seen: it parses them by their declarations alone."""

    gain: Annotated[Real, Field(ge=0.0)] = 1.0
    mode: Literal["fast", "slow", 3] = "fast"
    day: datetime.date = datetime.date(2024, 1, 1)
    sizes: Annotated[tuple[Int, ...], Field(max_length=3)] = ()
    label: Text | None = None
    pair: tuple[Literal["a", "b"], Real] = ("a", 0.0)
    even: Annotated[Int, AfterValidator(_even)] = 0

    nested: ClassVar[dict[str, type]] = {}


@pytest.mark.parametrize(
    ("pair", "expected"),
    [
        ("gain=2", 2.0),
        ("gain=1e-3", 1e-3),
        ("mode=slow", "slow"),
        ("mode=3", 3),
        ("day=2025-02-03", datetime.date(2025, 2, 3)),
        ("sizes=1,2", (1, 2)),
        ("sizes=[4]", (4,)),
        ("label=none", None),
        ("label=hello, world", "hello, world"),
        ("pair=b,2.5", ("b", 2.5)),
        ("even=4", 4),
    ],
)
def test_a_newly_declared_type_parses_without_change(pair: str, expected: Any) -> None:
    key = pair.partition("=")[0]
    values = parse_set(_Novel, [pair])
    assert values == {key: expected}
    assert getattr(_Novel(**values), key) == expected  # the config takes what --set gives


@pytest.mark.parametrize(
    ("pair", "needles"),
    [
        ("gain=-1", ["--set gain:", "greater than or equal to 0", "-1"]),
        ("gain=x", ["--set gain:", "a finite number", "'x'"]),
        ("mode=medium", ["--set mode:", "one of fast/slow/3", "'medium'"]),
        ("day=yesterday", ["--set day:", "'yesterday'"]),
        ("sizes=1,2,3,4", ["--set sizes:", "0 to 3 integers", "'1,2,3,4'"]),
        ("pair=c,1", ["--set pair:", "'c,1'"]),
        ("even=3", ["--set even:", "must be even"]),
    ],
)
def test_a_newly_declared_type_is_refused_as_declared(pair: str, needles: list[str]) -> None:
    with pytest.raises(ValueError) as err:
        parse_set(_Novel, [pair])
    assert all(n in str(err.value) for n in needles), str(err.value)

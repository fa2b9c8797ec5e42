"""Declared configs: frozen pydantic dataclasses whose field types carry the checks.

A config class is a dataclass decorated with :func:`config`; its fields are annotated with the types of this
module (``Int``, ``Real``, ``Flag``, ``Text``, ``Literal[...]``, tuples of them, sub-configs) and bounds as
``Annotated[Real, Field(ge=0.0, le=1.0)]``. Pydantic (v2) checks every field at construction, so one
declaration gives the types, the bounds, the JSON schema and the parsing of command-line text
(``agentsim_env.cli_set``). Rules across fields stay in ``__post_init__`` and raise :class:`FieldError`.

What the declarations accept:

- ``Int``: an integer (Python or numpy, stored as ``int``; never a bool or a float).
- ``Real``: a finite real number (Python or numpy int or float, stored as ``float``; never a bool).
- ``Flag``: ``True`` or ``False`` (a numpy bool is stored as a bool); no truthy number or string.
- ``Text`` / ``FreeText``: printable text (:func:`printable`); ``FreeText`` also takes tab and line feed.
- ``tuple[...]``: a tuple, list or 1-d array of the right length (stored as a tuple).
- a sub-config: an instance, or a dict of some of its fields merged over the field's default (the class's
  ``nested`` ClassVar names these fields).

Errors are ``ValueError``\\ s in the project's words: the field with its dotted path (``body.altitude[1]``), the
value (a short ``repr``) and what is allowed (``must be >= 0.01, got -1``), translated from pydantic's
``ValidationError`` by :func:`config_error`.
"""

from __future__ import annotations

import dataclasses
import functools
import re
import types
import typing
from collections.abc import Callable, Mapping
from typing import Annotated, Any, TypeVar

import numpy as np
import pydantic
import pydantic.dataclasses
from pydantic import AfterValidator, AllowInfNan, BeforeValidator, ConfigDict, Strict
from pydantic_core import PydanticCustomError

from agentsim_env.core.short_text import short_repr

__all__ = [
    "CONFIG",
    "Choice",
    "FieldError",
    "Flag",
    "FreeText",
    "Int",
    "Real",
    "Text",
    "config",
    "config_error",
    "in_range",
    "ordered",
    "printable",
]

T = TypeVar("T")

#: Pydantic settings of every config: unknown keys refused; defaults are trusted (they are checked by tests).
CONFIG = ConfigDict(extra="forbid", arbitrary_types_allowed=True)


class FieldError(ValueError):
    """A bad value of one field, raised by a config's cross-field rules (``__post_init__``).

    ``field`` is relative to the config that raises it; the message gets the dotted path of that config in
    front (``comms.`` when it is the ``comms`` sub-config of a scenario config).

    Args:
        field: The field (``"altitude"``, ``"elevations_deg"``), relative to the config raising it.
        problem: What is wrong and what is allowed (``"must be >= 1, got 0"``).
    """

    def __init__(self, field: str, problem: str) -> None:
        super().__init__(f"{field} {problem}")
        self.field = field
        self.problem = problem


# ------------------------------------------------------------------------------------------------ types
def _number(value: Any) -> Any:
    """Numpy scalars as Python numbers (a numpy bool as a bool, which the strict number types refuse)."""
    if isinstance(value, np.generic):
        return value.item()
    return value


def _bool(value: Any) -> Any:
    """A numpy bool as a Python bool; anything else unchanged (the strict bool type decides)."""
    return bool(value) if isinstance(value, np.bool_) else value


#: Characters no text field takes: C0 controls, DEL and C1 controls (a terminal acts on them), the
#: bidirectional embeddings, overrides and isolates (they reorder what is shown), and surrogates (in a Python
#: string they are always unpaired, and no UTF-8 encoder writes them).
BAD_TEXT = re.compile("[\x00-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069\ud800-\udfff]")
BAD_TEXT_OR_NEWLINE = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069\ud800-\udfff]")


def printable(value: str, *, allow_newlines: bool = False) -> str:
    """Raise unless ``value`` is safe to print, log, plot and encode as UTF-8.

    Refused: C0 and C1 control characters and DEL (U+0000-001F, U+007F-009F), the bidirectional embeddings,
    overrides and isolates (U+202A-202E, U+2066-2069) and unpaired surrogates (U+D800-DFFF).

    Args:
        value: The text.
        allow_newlines: Also accept tab and line feed (free text such as a description).

    Returns:
        ``value`` unchanged.

    Raises:
        pydantic_core.PydanticCustomError: ``printable_text``, naming the first refused character (its code
            point, e.g. ``U+202E``) and its position; the message never contains the character itself.
    """
    bad = (BAD_TEXT_OR_NEWLINE if allow_newlines else BAD_TEXT).search(value)
    if bad is not None:
        raise PydanticCustomError(
            "printable_text",
            "must be printable text without control characters, bidirectional overrides or unpaired "
            "surrogates; found {char} at position {position}",
            {"char": f"U+{ord(bad.group()):04X}", "position": bad.start()},
        )
    return value


def ordered(pair: tuple[float, float]) -> tuple[float, float]:
    """Raise unless ``pair`` is ``(low, high)`` with ``low <= high`` (an ``AfterValidator`` of pair fields).

    Args:
        pair: The validated pair.

    Returns:
        ``pair`` unchanged.

    Raises:
        pydantic_core.PydanticCustomError: ``pair_order``, with both ends (the error names ``field[1]``).
    """
    if pair[1] < pair[0]:  # named as the high end: ``gap[1] must be >= 30.0, got 20.0``
        raise PydanticCustomError(
            "pair_order",
            "must be >= {low}, got {high}",
            {"low": short_repr(pair[0]), "high": short_repr(pair[1])},
        )
    return pair


def _printable_if_text(value: Any) -> Any:
    """Text checked by :func:`printable` before a ``Literal`` compares it (errors never echo a control code)."""
    return printable(value) if isinstance(value, str) else value


#: Put on a ``Literal`` of choices (``Annotated[Literal["a", "b"], Choice]``): text given is checked to be
#: printable first, so an error names a control character by its code point instead of echoing it.
Choice = BeforeValidator(_printable_if_text)
#: An integer (numpy integers accepted, stored as ``int``; bools and floats refused).
Int = Annotated[int, BeforeValidator(_number), Strict()]
#: A finite real number (numpy numbers and ints accepted, stored as ``float``; bools refused).
Real = Annotated[float, BeforeValidator(_number), Strict(), AllowInfNan(False)]
#: ``True`` or ``False`` (a numpy bool accepted); no truthy number or string.
Flag = Annotated[bool, BeforeValidator(_bool), Strict()]
#: Printable text on one line.
Text = Annotated[str, Strict(), AfterValidator(printable)]
#: Printable text that may hold tabs and line feeds.
FreeText = Annotated[str, Strict(), AfterValidator(functools.partial(printable, allow_newlines=True))]


def in_range(
    field: str,
    value: float,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
) -> None:
    """A bound that depends on other fields (the value's type is already checked by its declaration).

    Args:
        field: The field, relative to the config.
        value: Its value.
        lo: Lowest allowed value (exclusive with ``lo_open``); ``None``: none.
        hi: Highest allowed value; ``None``: none.
        lo_open: Whether ``lo`` itself is refused.

    Raises:
        FieldError: ``must be >= lo`` (``> lo``) or ``must be <= hi``, with the value.
    """
    if lo is not None and (value <= lo if lo_open else value < lo):
        raise FieldError(field, f"must be {'>' if lo_open else '>='} {lo}, got {short_repr(value)}")
    if hi is not None and value > hi:
        raise FieldError(field, f"must be <= {hi}, got {short_repr(value)}")


# --------------------------------------------------------------------------------------- the decorator
def _nested(cls: type) -> dict[str, type]:
    """Sub-config fields of ``cls`` (its ``nested`` ClassVar): field name -> config class."""
    return dict(getattr(cls, "nested", None) or {})


@functools.cache
def _field_names(cls: type) -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(cls) if f.init)


@functools.cache
def _defaults(cls: type) -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(cls)}


def _unknown(cls: type, keys: Mapping[str, Any], label: str) -> None:
    """Raise on keys that are no field of ``cls`` (the message lists the allowed keys)."""
    names = _field_names(cls)
    unknown = [k for k in keys if k not in names]
    if unknown:
        shown = sorted(unknown, key=repr)
        raise ValueError(f"unknown {label} key(s) {shown} for {cls.__name__}; allowed keys: {sorted(names)}")


def _shallow(obj: Any) -> dict[str, Any]:
    """A config instance's fields as a dict (sub-configs kept as instances)."""
    return {name: getattr(obj, name) for name in _field_names(type(obj))}  # type: ignore[arg-type]


def _merge_nested(cls: type, values: dict[str, Any], where: str) -> dict[str, Any]:
    """Dicts given for sub-config fields merged over the field's default (recursively); unknown keys raise."""
    subs = _nested(cls)
    if not subs or not any(isinstance(values.get(n), dict) for n in subs):
        return values
    out = dict(values)
    for name, sub in subs.items():
        given = out.get(name)
        if not isinstance(given, dict):
            continue
        _unknown(sub, given, where + name)
        f = _defaults(cls)[name]
        base = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
        start = _shallow(base) if isinstance(base, sub) else {}
        out[name] = _merge_nested(sub, {**start, **given}, f"{where}{name}.")
    return out


@typing.dataclass_transform(frozen_default=True, field_specifiers=(dataclasses.field, pydantic.Field))
def config(label: str = "") -> Callable[[type[T]], type[T]]:
    """Class decorator: a frozen pydantic dataclass whose construction errors are the project's ``ValueError``.

    Args:
        label: The dotted path the class has as a sub-config (``"body"``, ``"comms"``), put in front of field
            names in its errors when it is built by itself; ``""`` for a top-level config.

    Returns:
        The decorator. The class keeps the dataclass interface (``dataclasses.fields``, ``replace``,
        ``asdict``, ``__post_init__``); its ``__init__`` merges dicts given for sub-configs over their
        defaults, refuses unknown keys by name and translates validation errors (:func:`config_error`).
    """

    def wrap(cls: type[T]) -> type[T]:
        built = pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)(cls)
        init = built.__init__

        def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
            top = type(self)
            if kwargs:
                _unknown(top, kwargs, "config")
                kwargs = _merge_nested(top, kwargs, "")
            try:
                init(self, *args, **kwargs)
            except pydantic.ValidationError as exc:
                raise config_error(exc, top, getattr(top, "_label", "")) from None

        __init__.__doc__ = init.__doc__
        built.__init__ = __init__  # type: ignore[method-assign]
        built._label = label  # type: ignore[attr-defined]
        return typing.cast("type[T]", built)

    return wrap


# ------------------------------------------------------------------------------------ error translation
def _config_class(tp: Any) -> type | None:
    """The config class an annotation holds (itself, or the config member of ``X | None``)."""
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return tp
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        for arg in typing.get_args(tp):
            if isinstance(arg, type) and dataclasses.is_dataclass(arg):
                return arg
    return None


def _fields_of(cls: type | None) -> dict[str, Any]:
    """Field name -> annotation of a pydantic config class (``{}`` for anything else)."""
    found = getattr(cls, "__pydantic_fields__", None) if cls is not None else None
    return {name: info.annotation for name, info in (found or {}).items()}


def _walk(cls: type, loc: tuple[int | str, ...]) -> tuple[str, Any, type | None]:
    """Dotted path of a pydantic error location, the annotation of its last field, and the config class there.

    Union member tags (``'function-after[...]'``, ``'none'``) and other non-field steps are skipped.
    """
    path = ""
    cur: type | None = cls
    annotation: Any = None
    for step in loc:
        if isinstance(step, int):
            path += f"[{step}]"
            cur = None
            continue
        fields = _fields_of(cur)
        if step in fields:
            path += ("." if path else "") + step
            annotation = fields[step]
            cur = _config_class(annotation)
    return path, annotation, cur


def _choices(annotation: Any) -> list[Any] | None:
    """The values of a ``Literal`` annotation (or of the ``Literal`` member of a union)."""
    if typing.get_origin(annotation) is typing.Literal:
        return list(typing.get_args(annotation))
    for arg in typing.get_args(annotation):
        found = _choices(arg)
        if found is not None:
            return found
    return None


_SKIP = {"none_required", "is_instance_of"}
"""Errors of a union's ``None`` member: the other member's error says more."""

_WHAT = {
    "int_type": "must be an integer",
    "int_from_float": "must be an integer",
    "int_parsing": "must be an integer",
    "float_type": "must be a finite number",
    "float_parsing": "must be a finite number",
    "finite_number": "must be a finite number",
    "bool_type": "must be True or False (a bool)",
    "bool_parsing": "must be True or False (a bool)",
    "string_type": "must be a string",
    "tuple_type": "must be a sequence (a tuple or list)",
    "dict_type": "must be a mapping of keys",
}


def describe(error: Mapping[str, Any], annotation: Any = None) -> str:
    """What a pydantic error says is wrong, in this project's words (without the field's name).

    Args:
        error: One item of ``ValidationError.errors()``.
        annotation: The annotation of the field it is about (for the allowed values of a ``Literal``).

    Returns:
        E.g. ``"must be >= 0.01, got -1"`` or ``"must be one of ['a', 'b'], got 'c'"``.
    """
    kind, ctx, value = error["type"], error.get("ctx") or {}, error.get("input")
    got = f"got {short_repr(value)}"
    if kind in _WHAT:
        return f"{_WHAT[kind]}, {got}"
    for key, op in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<")):
        if key in ctx and kind.startswith(("greater", "less")):
            return f"must be {op} {ctx[key]}, {got}"
    if kind == "literal_error":
        return f"must be one of {_choices(annotation) or ctx.get('expected')}, {got}"
    if kind in ("too_short", "too_long"):
        n = ctx.get("max_length") if kind == "too_long" else ctx.get("min_length")
        fixed = _fixed_length(annotation)
        if fixed == 2:
            return f"must be a pair (low, high), {got}"
        if fixed is not None:
            return f"must be {fixed} values, {got}"
        return f"must hold {'at most' if kind == 'too_long' else 'at least'} {n} values, {got}"
    if kind in ("dataclass_type", "dataclass_exact_type", "model_type"):
        name = getattr(_config_class(annotation), "__name__", "config")
        return f"must be a mapping of {name} fields (or a {name}), {got}"
    if kind in ("printable_text", "pair_order"):
        return error["msg"]
    if kind in ("missing", "missing_argument"):
        return "is required"
    return f"{error['msg'][:1].lower()}{error['msg'][1:]}, {got}"


def _fixed_length(annotation: Any) -> int | None:
    """The length of a fixed-length tuple annotation (``None`` for ``tuple[X, ...]`` and other types)."""
    for tp in (annotation, *typing.get_args(annotation)):
        if typing.get_origin(tp) is tuple:
            args = typing.get_args(tp)
            return None if len(args) == 2 and args[1] is Ellipsis else len(args)
    return None


def config_error(exc: pydantic.ValidationError, cls: type, label: str = "") -> ValueError:
    """The first error of a failed config construction as one line naming the field, the value and the rule.

    Args:
        exc: Pydantic's error.
        cls: The config class being built.
        label: Its dotted path as a sub-config (``"body"``), put in front of field names; ``""``: none.

    Returns:
        A ``ValueError`` (a :class:`FieldError` when one field is named) to raise.
    """
    errors = exc.errors(include_url=False)
    chosen = next((e for e in errors if e["type"] not in _SKIP), errors[0])
    loc = tuple(chosen["loc"])
    if chosen["type"] in ("unexpected_keyword_argument", "extra_forbidden"):
        parent, _, owner = _walk(cls, loc[:-1])
        keys = sorted({str(e["loc"][-1]) for e in errors if tuple(e["loc"][:-1]) == loc[:-1]})
        names = sorted(_field_names(owner)) if owner is not None else []
        where = ".".join(p for p in (label, parent) if p) or "config"
        return ValueError(f"unknown {where} key(s) {keys} for {getattr(owner, '__name__', '?')}; allowed keys: {names}")
    path, annotation, _ = _walk(cls, loc)
    if chosen["type"] == "pair_order":
        path += "[1]"
    prefix = ".".join(p for p in (label, path) if p)
    if chosen["type"] == "value_error":
        raised = (chosen.get("ctx") or {}).get("error")
        if isinstance(raised, FieldError):
            return FieldError(f"{prefix}.{raised.field}" if prefix else raised.field, raised.problem)
        text = str(raised) if raised is not None else chosen["msg"]
        return ValueError(f"{prefix}: {text}" if path else text)
    return FieldError(prefix or "config", describe(chosen, annotation))

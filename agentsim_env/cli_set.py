"""Typed parsing of the command line's ``--set KEY=VALUE`` pairs.

Each value is parsed by the type of the config field it sets (read from the config dataclass with
``typing.get_type_hints``), not guessed from its spelling:

=====================  ==============================================================================
field type             accepted values
=====================  ==============================================================================
``bool``               ``true``/``false``/``1``/``0``/``yes``/``no`` (any case), nothing else
``int``                integers only (``8``, ``-1``; not ``1.5``)
``float``              finite numbers (``0.1``, ``2``, ``1e-3``)
``str``                the text as given
``tuple[...]``         a JSON list (``[12, 20]``) or comma-separated values (``12,20``; one value: ``7,``)
``X | None``           ``none`` or ``null`` (any case), or a value of ``X``
sub-config             a JSON object of its fields (``body={"radius": 1.0}``), or dotted keys
                       (``body.radius=1.0``), merged into one dict per sub-config
``Any`` (and others)   JSON when it parses (lists become tuples), else the text
=====================  ==============================================================================

Sub-configs are the fields named in the config class's ``nested`` ClassVar (field name -> sub-config
dataclass); dotted keys recurse into them, and the leaf is parsed by the sub-config field's type. Alias keys
(the class's ``aliases`` ClassVar, e.g. ``n_uavs`` -> ``n_agents``, and PettingZoo's ``max_cycles`` ->
``max_steps``) are resolved before the type is looked up. An unknown key raises ``ValueError`` listing the
allowed keys. Values are only parsed here; the config classes still validate ranges and choices.

JSON values refuse a key given twice and nesting deeper than ``MAX_JSON_DEPTH`` (32) levels, and an error
quotes at most about 80 characters of the value it refuses (an argument may be 100 KB long).

This module imports nothing from the package: it reads whatever config class it is given.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import re
import types
import typing
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ["BOOL_WORDS", "MAX_JSON_DEPTH", "NONE_WORDS", "TOP_ALIASES", "canonical", "parse_set"]

#: Accepted spellings of booleans (compared lower-case).
BOOL_WORDS: dict[str, bool] = {"true": True, "false": False, "1": True, "0": False, "yes": True, "no": False}
#: Accepted spellings of ``None`` for optional fields (compared lower-case).
NONE_WORDS: tuple[str, ...] = ("none", "null")
#: Aliases every scenario config accepts (PettingZoo's name for the episode length).
TOP_ALIASES: dict[str, str] = {"max_cycles": "max_steps"}

_INT = re.compile(r"[+-]?\d+")
_NoneType = type(None)


class _Bad(Exception):
    """A value that does not fit a type (turned into a ``ValueError`` naming the key by the caller)."""


class _Refused(_Bad):
    """JSON that parses but is refused (a duplicate key, nesting too deep); ``str()`` says why."""


#: Most levels of lists and objects in a JSON value (configs nest a few levels; Python's parser recurses).
MAX_JSON_DEPTH = 32
#: Characters of a command-line value quoted in an error (an argument may be 100 KB long).
_SHOWN = 80


def _shown(value: Any) -> str:
    """``repr`` of a command-line value or key, cut to about ``_SHOWN`` characters."""
    if isinstance(value, str) and len(value) > _SHOWN:
        return f"{value[:_SHOWN]!r}... ({len(value):,} characters)"
    text = repr(value)  # decoded JSON: as long as the argument at most
    return text if len(text) <= _SHOWN + 20 else f"{text[:_SHOWN]}... ({len(text):,} characters)"


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object's pairs as a dict, refusing a key given twice (``json`` keeps the last one silently)."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _Refused(f"duplicate key {_shown(key)} in a JSON object; give each key once")
        out[key] = value
    return out


def _json(text: str) -> Any:
    """Decode JSON, refusing duplicate keys and nesting past ``MAX_JSON_DEPTH`` (``_Refused``).

    Raises:
        json.JSONDecodeError: On text that is not JSON.
        _Refused: On a duplicate key or too deep a nesting.
    """
    try:
        value = json.loads(text, object_pairs_hook=_unique_keys)
    except RecursionError:
        value = None
    else:
        stack = [(value, 0)]
        while stack:  # iterative: the depth is what is being bounded
            item, depth = stack.pop()
            if isinstance(item, (dict, list)):
                if depth >= MAX_JSON_DEPTH:
                    break
                stack.extend((v, depth + 1) for v in (item.values() if isinstance(item, dict) else item))
        else:
            return value
    raise _Refused(f"JSON nested deeper than {MAX_JSON_DEPTH} levels; at most {MAX_JSON_DEPTH} are allowed")


@functools.cache
def _field_types(cls: type) -> dict[str, Any]:
    """Field name -> resolved type of a config dataclass (``Any`` where an annotation cannot be resolved)."""
    try:
        hints = typing.get_type_hints(cls)
    except Exception:  # an annotation that does not evaluate: parse those fields like Any
        hints = {}
    return {f.name: hints.get(f.name, Any) for f in dataclasses.fields(cls)}


def _aliases(cls: type, top: bool) -> dict[str, str]:
    """Alias -> field name for ``cls`` (the top-level config also takes ``max_cycles``)."""
    own = dict(getattr(cls, "aliases", None) or {})
    return {**TOP_ALIASES, **own} if top else own


def _nested(cls: type) -> dict[str, type]:
    """Sub-config fields of ``cls``: field name -> sub-config dataclass."""
    return dict(getattr(cls, "nested", None) or {})


def _describe(tp: Any) -> str:
    """What a type accepts, in words (for error messages)."""
    if tp is bool:
        return "one of true/false/1/0/yes/no (any case)"
    if tp is int:
        return "an integer"
    if tp is float:
        return "a finite number"
    if tp is str:
        return "text"
    if tp is _NoneType:
        return "none/null"
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_describe(a) for a in args)
    if _is_tuple(tp):
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_plural(args[0])} (JSON [a, b] or a,b)"
        if args:
            return f"a list of {len(args)} {_plural(args[0])} (JSON [a, b] or a,b)"
        return "a list (JSON [a, b] or a,b)"
    if origin is typing.Literal:
        return "one of " + "/".join(str(a) for a in args)
    return "a value"


def _plural(tp: Any) -> str:
    return {int: "integers", float: "numbers", bool: "booleans", str: "strings"}.get(tp, "values")


def _legacy(text: str) -> Any:
    """JSON when it parses (lists become tuples), else the text: the rule for ``Any`` fields."""
    try:
        value = _json(text)
    except json.JSONDecodeError:
        return text
    return _tuples(value)


def _tuples(value: Any) -> Any:
    """JSON lists as tuples (recursively)."""
    if isinstance(value, list):
        return tuple(_tuples(v) for v in value)
    if isinstance(value, dict):
        return {k: _tuples(v) for k, v in value.items()}
    return value


def _is_tuple(tp: Any) -> bool:
    """Whether ``tp`` is ``tuple`` or ``tuple[...]``."""
    return tp is tuple or typing.get_origin(tp) is tuple


def _union_members(tp: Any) -> list[Any] | None:
    """The member types of a union (``X | None``, ``Optional[X]``), non-str ones first; None otherwise."""
    if typing.get_origin(tp) not in (typing.Union, types.UnionType):
        return None
    return sorted(typing.get_args(tp), key=lambda a: a is str)  # str accepts anything: try it last


def _elements(tp: Any, n: int) -> list[Any]:
    """The element type of each of ``n`` items of tuple type ``tp`` (raises ``_Bad`` on a length mismatch)."""
    args = typing.get_args(tp)
    if not args:
        return [Any] * n
    if len(args) == 2 and args[1] is Ellipsis:
        return [args[0]] * n
    if len(args) != n:
        raise _Bad
    return list(args)


def _parse_text(tp: Any, text: str) -> Any:
    """Parse one command-line value by type ``tp`` (raises ``_Bad`` when it does not fit)."""
    s = text.strip()
    members = _union_members(tp)
    if members is not None:
        if _NoneType in members and s.lower() in NONE_WORDS:
            return None
        listy = s.startswith("[") or "," in s
        for member in members:
            if member is _NoneType or (_is_tuple(member) and not listy):
                continue  # in a union, a list must look like one ("7," for one element)
            try:
                return _parse_text(member, text)
            except _Bad:
                pass
        raise _Bad
    if tp is bool:
        if s.lower() not in BOOL_WORDS:
            raise _Bad
        return BOOL_WORDS[s.lower()]
    if tp is int:
        if not _INT.fullmatch(s):
            raise _Bad
        return int(s)
    if tp is float:
        try:
            x = float(s)
        except ValueError:
            raise _Bad from None
        if not math.isfinite(x):
            raise _Bad
        return x
    if tp is str:
        return text
    if tp is _NoneType:
        if s.lower() not in NONE_WORDS:
            raise _Bad
        return None
    origin = typing.get_origin(tp)
    if _is_tuple(tp):
        if s.startswith("["):
            try:
                items = _json(s)
            except json.JSONDecodeError:
                raise _Bad from None
            return _coerce(tp, items)
        parts = [p.strip() for p in s.split(",")] if s else []
        if parts and parts[-1] == "":
            parts.pop()  # "7," is a one-element list
        if any(p == "" for p in parts):
            raise _Bad
        types_ = _elements(tp, len(parts))
        return tuple(_legacy(p) if t is Any else _parse_text(t, p) for t, p in zip(types_, parts))
    if origin is typing.Literal:
        for choice in typing.get_args(tp):
            if str(choice) == s:
                return choice
        raise _Bad
    return _legacy(text)


def _coerce(tp: Any, value: Any) -> Any:
    """Check and convert a JSON-decoded value to type ``tp`` (raises ``_Bad`` when it does not fit)."""
    members = _union_members(tp)
    if members is not None:
        if value is None and _NoneType in members:
            return None
        for member in members:
            if member is _NoneType:
                continue
            try:
                return _coerce(member, value)
            except _Bad:
                pass
        raise _Bad
    if tp is bool:
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.strip().lower() in BOOL_WORDS:
            return BOOL_WORDS[value.strip().lower()]
        raise _Bad
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise _Bad
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise _Bad
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise _Bad
        return value
    if tp is _NoneType:
        if value is not None:
            raise _Bad
        return None
    if _is_tuple(tp):
        if not isinstance(value, (list, tuple)):
            raise _Bad
        return tuple(_coerce(t, v) for t, v in zip(_elements(tp, len(value)), value))
    return _tuples(value)


def _resolve(cls: type, name: str, where: str, top: bool) -> str:
    """The field ``name`` means in ``cls`` (aliases resolved); raises ``ValueError`` on an unknown key."""
    aliases = _aliases(cls, top)
    field_name = aliases.get(name, name)
    fields = _field_types(cls)
    if field_name not in fields:
        also = (
            f" (aliases: {', '.join(f'{a} -> {k}' for a, k in sorted(aliases.items()))})" if aliases else ""
        )
        raise ValueError(
            f"unknown --set key {_shown(where + name)} for {cls.__name__}; allowed keys: {sorted(fields)}{also}"
        )
    return field_name


def _merge(old: Any, new: Any) -> Any:
    """``new`` over ``old``; two dicts merge key by key (recursively)."""
    if isinstance(old, dict) and isinstance(new, dict):
        out = dict(old)
        for k, v in new.items():
            out[k] = _merge(out.get(k), v)
        return out
    return new


def _object(cls: type, value: Any, where: str) -> dict[str, Any]:
    """Check a JSON object given for sub-config ``cls`` key by key (values converted by field type)."""
    out: dict[str, Any] = {}
    for key, item in value.items():
        name = _resolve(cls, str(key), where, top=False)
        sub = _nested(cls).get(name)
        tp = _field_types(cls)[name]
        if sub is not None and isinstance(item, dict):
            out[name] = _object(sub, item, f"{where}{name}.")
            continue
        try:
            out[name] = _coerce(tp, item)
        except _Bad:
            raise ValueError(f"--set {where + name}: expected {_describe(tp)}, got {_shown(item)}") from None
    return out


def _leaf(cls: type, name: str, text: str, where: str) -> Any:
    """Parse the value of field ``name`` of ``cls`` from the command line."""
    tp = _field_types(cls)[name]
    sub = _nested(cls).get(name)
    key = where + name
    if sub is None:
        try:
            return _parse_text(tp, text)
        except _Refused as exc:
            raise ValueError(f"--set {key}: {exc}") from None
        except _Bad:
            raise ValueError(f"--set {key}: expected {_describe(tp)}, got {_shown(text)}") from None
    members = _union_members(tp) or [tp]
    if _NoneType in members and text.strip().lower() in NONE_WORDS:
        return None
    try:
        value = _json(text)
    except json.JSONDecodeError:
        value = None
    except _Refused as exc:
        raise ValueError(f"--set {key}: {exc}") from None
    if not isinstance(value, dict):
        none = " or none" if _NoneType in members else ""
        raise ValueError(
            f'--set {key}: expected a JSON object of {sub.__name__} fields{none} (e.g. {key}={{"field": 1}}) '
            f"or dotted keys ({key}.FIELD=VALUE), got {_shown(text)}"
        )
    return _object(sub, value, f"{key}.")


def _assign(cls: type, target: dict[str, Any], path: list[str], text: str, where: str, top: bool) -> None:
    """Parse ``text`` for the dotted ``path`` below ``cls`` and merge it into ``target``."""
    name = _resolve(cls, path[0], where, top)
    if len(path) == 1:
        target[name] = _merge(target.get(name), _leaf(cls, name, text, where))
        return
    sub = _nested(cls).get(name)
    if sub is None:
        subs = sorted(_nested(cls))
        raise ValueError(
            f"--set {where + '.'.join(path)}: {where + name!r} is not a sub-config of {cls.__name__}; "
            f"sub-configs: {subs}"
        )
    child = target.get(name)
    if not isinstance(child, dict):
        child = target[name] = {}
    _assign(sub, child, path[1:], text, f"{where}{name}.", top=False)


def parse_set(config_cls: type, pairs: Iterable[str]) -> dict[str, Any]:
    """Parse ``--set KEY=VALUE`` pairs into config values, each by the type of the field it sets.

    Args:
        config_cls: The scenario's config dataclass (``scenario_class(name).config_cls``); its ``nested``
            ClassVar names the sub-config fields, its ``aliases`` ClassVar the alias keys.
        pairs: ``KEY=VALUE`` strings; ``KEY`` may be dotted (``body.radius``) to set one field of a sub-config.
            Later pairs override earlier ones; a sub-config's dotted keys and JSON objects merge.

    Returns:
        Config values by field name (aliases resolved, sub-configs as dicts of their fields), ready for
        ``agentsim_env.make(name, **values)``.

    Raises:
        ValueError: On a pair without ``=``, an unknown key (listing the allowed ones), an alias given with
            its field, or a value that does not fit the field's type (naming the key, the value and what
            the field accepts).
    """
    out: dict[str, Any] = {}
    spelled: dict[str, str] = {}  # field -> the top-level key that set it (to catch alias + field)
    for pair in pairs:
        key, sep, text = pair.partition("=")
        key = key.strip()
        path = key.split(".")
        if not sep or not key or any(not p for p in path):
            raise ValueError(
                f"--set expects KEY=VALUE (e.g. n_agents=8 or body.radius=1.0), got {_shown(pair)}"
            )
        name = _resolve(config_cls, path[0], "", top=True)
        if spelled.setdefault(name, path[0]) != path[0]:
            raise ValueError(
                f"--set: give {name!r} under one name only, got {spelled[name]!r} and {path[0]!r}"
            )
        _assign(config_cls, out, path, text, "", top=True)
    return out


def canonical(values: Mapping[str, Any]) -> str:
    """A stable text of parsed ``--set`` values (sorted keys, tuples as lists) for naming outputs."""
    return json.dumps(values, sort_keys=True, default=str, separators=(",", ":"))

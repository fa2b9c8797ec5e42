"""The command line's ``--set KEY=VALUE`` pairs, each value converted by the declaration of the field it sets.

The value of a key is converted by pydantic from the declared type of the config field it sets (its
annotation and bounds, read from the config class): this module has no rules of its own for any type, so a
field declared with a new type is parsed as declared. The text is tried, in this order, as:

1. ``None`` when it is ``none`` or ``null`` (any case) and the field takes ``None``;
2. JSON (``8``, ``0.1``, ``true``, ``[12, 20]``, ``{"a": 1}``) of the field's JSON type (pydantic's strict
   JSON mode: ``2e6`` is a number, not an integer);
3. comma-separated values (``12,20``; one value: ``7,``), each part JSON when it parses, for list fields;
4. the text itself, converted by pydantic's lax rules.

The first that the field's declaration accepts is the value. What that gives for the usual declarations:

=====================  ==============================================================================
declared type          accepted values
=====================  ==============================================================================
``Flag`` (bool)        ``true``/``false``/``1``/``0``/``yes``/``no``/``on``/``off``/``t``/``f``/``y``/``n``
                       (any case), nothing else
``Int``                integers (``8``, ``-1``, ``1_000``; ``1.0`` is 1; not ``1.5`` or ``2e6``)
``Real``               finite numbers (``0.1``, ``2``, ``1e-3``)
``Text``               the text as given (a JSON string ``"x"`` loses its quotes)
``Literal[...]``       one of the choices
``tuple[...]``         a JSON list (``[12, 20]``) or comma-separated values (``12,20``; one value: ``7,``)
``X | None``           ``none`` or ``null`` (any case), or a value of ``X``
sub-config             a JSON object of its fields (``body={"radius": 1.0}``), or dotted keys
                       (``body.radius=1.0``), merged into one dict per sub-config
``Any``                JSON when it parses, else the text
=====================  ==============================================================================

Lists in the values are returned as tuples. Bounds declared on the field (``Field(ge=0)``, ``ordered``, ...)
are checked here too; the config class checks them again at construction, with the rules across fields.

Sub-configs are the fields named in the config class's ``nested`` ClassVar (field name -> sub-config
dataclass); dotted keys recurse into them, and a JSON object's values are converted (lax) by the sub-config's
declarations. Alias keys (the class's ``aliases`` ClassVar, e.g. ``n_uavs`` -> ``n_agents``, and PettingZoo's
``max_cycles`` -> ``max_steps``) are resolved before the declaration is looked up. An unknown key raises
``ValueError`` listing the allowed keys; a value the declaration refuses raises ``ValueError`` naming the
dotted key, the value and what is accepted.

JSON values refuse a key given twice and nesting deeper than ``MAX_JSON_DEPTH`` (32) levels, and an error
quotes at most about 80 characters of the value it refuses (an argument may be 100 KB long).

This module imports nothing from the package: it reads whatever config class it is given.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import typing
from collections.abc import Iterable, Mapping
from typing import Annotated, Any

import pydantic

__all__ = ["MAX_JSON_DEPTH", "NONE_WORDS", "TOP_ALIASES", "canonical", "parse_set"]

#: Accepted spellings of ``None`` for fields that take it (compared lower-case).
NONE_WORDS: tuple[str, ...] = ("none", "null")
#: Aliases every scenario config accepts (PettingZoo's name for the episode length).
TOP_ALIASES: dict[str, str] = {"max_cycles": "max_steps"}


class _Refused(Exception):
    """JSON that parses but is refused (a duplicate key, nesting too deep); ``str()`` says why."""


#: Most levels of lists and objects in a JSON value (configs nest a few levels; Python's parser recurses).
MAX_JSON_DEPTH = 32
#: Characters of a command-line value quoted in an error (an argument may be 100 KB long).
_SHOWN = 80
#: Pydantic error kinds that mean "not of the declared type" (the rest: a value of the type broke a rule).
_TYPE_ERRORS = frozenset(
    {"literal_error", "int_from_float", "finite_number", "too_short", "too_long", "missing", "json_invalid"}
    | {"none_required", "is_instance_of", "union_tag_invalid", "enum", "json_type", "unexpected_positional"}
)


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
def _annotations(cls: type) -> dict[str, Any]:
    """Field name -> declared type of a config class, bounds included (``Any`` where none can be read)."""
    declared = getattr(cls, "__pydantic_fields__", None)
    if declared is not None:
        return {n: Annotated[(f.annotation, *f.metadata)] if f.metadata else f.annotation for n, f in declared.items()}
    try:
        hints = typing.get_type_hints(cls, include_extras=True)
    except Exception:  # an annotation that does not evaluate: such a field takes any value
        hints = {}
    return {f.name: hints.get(f.name, Any) for f in dataclasses.fields(cls)}


@functools.cache
def _adapter(cls: type, name: str) -> pydantic.TypeAdapter[Any]:
    """Pydantic's validator of field ``name`` of ``cls`` (built once per field)."""
    tp = _annotations(cls)[name]
    try:
        return pydantic.TypeAdapter(tp, config=pydantic.ConfigDict(arbitrary_types_allowed=True))
    except pydantic.PydanticUserError:  # a dataclass or model: it has a config of its own
        return pydantic.TypeAdapter(tp)


_WORDS = {
    "boolean": "one of true/false/1/0/yes/no/on/off/t/f/y/n (any case)",
    "integer": "an integer",
    "number": "a finite number",
    "string": "text",
    "null": "none/null",
    "object": "a JSON object",
}
_PLURAL = {"integer": "integers", "number": "numbers", "boolean": "booleans", "string": "strings"}


def _words(schema: Mapping[str, Any]) -> str:
    """What a field accepts on the command line, in words, read from its JSON schema."""
    if "anyOf" in schema:
        return " or ".join(_words(s) for s in schema["anyOf"])
    if "enum" in schema or "const" in schema:
        return "one of " + "/".join(str(c) for c in schema.get("enum", [schema.get("const")]))
    kind = schema.get("type")
    if kind == "array":
        items = schema.get("prefixItems") or [schema.get("items") or {}]
        what = _PLURAL.get(items[0].get("type"), "values")
        lo, hi = schema.get("minItems"), schema.get("maxItems")
        n = f"{lo} " if lo is not None and lo == hi else f"{lo or 0} to {hi} " if hi is not None else ""
        return f"a list of {n}{what} (JSON [a, b] or a,b)"
    return _WORDS.get(kind, "a value") if isinstance(kind, str) else "a value"


@functools.cache
def _accepts(cls: type, name: str) -> str:
    """What field ``name`` of ``cls`` accepts, in words (``"a value"`` when its schema cannot be written)."""
    try:
        return _words(_adapter(cls, name).json_schema())
    except Exception:  # a type without a JSON schema (an arbitrary class)
        return "a value"


def _tuples(value: Any) -> Any:
    """Lists as tuples (recursively)."""
    if isinstance(value, list | tuple):
        return tuple(_tuples(v) for v in value)
    if isinstance(value, dict):
        return {k: _tuples(v) for k, v in value.items()}
    return value


def _or_text(part: str) -> Any:
    """One comma-separated part: its JSON value when it is JSON, else the text."""
    try:
        return json.loads(part)
    except ValueError:
        return part


def _problem(error: Mapping[str, Any]) -> str:
    """One pydantic error of a value of the right type as ``must be ..., got ...``."""
    msg = str(error["msg"])
    if msg.startswith("Input should"):
        return f"must{msg[len('Input should') :]}, got {_shown(error.get('input'))}"
    return msg


def _convert(cls: type, name: str, text: str, key: str) -> Any:
    """The value of field ``name`` of ``cls`` that ``text`` means (see the module docstring for the order)."""
    adapter, s = _adapter(cls, name), text.strip()
    tries: list[tuple[Any, bool | None]] = []  # (input, strict); strict None: JSON text
    if s.lower() in NONE_WORDS:
        tries.append((None, False))
    try:
        _json(s)
        tries.append((s, None))
    except ValueError:
        pass
    except _Refused as exc:
        raise ValueError(f"--set {key}: {exc}") from None
    if "," in s and not s.startswith("["):
        parts = [p.strip() for p in s.split(",")]
        if parts[-1] == "":
            parts.pop()  # "7," is a one-element list
        if parts and all(parts):
            tries += [([_or_text(p) for p in parts], False), (parts, False)]
    tries += [(text, False)] + ([(s, False)] if s != text else [])
    broken: Mapping[str, Any] | None = None  # the first rule a value of the right type broke
    for value, strict in tries:
        try:
            if strict is None:
                return _tuples(adapter.validate_json(value, strict=True))
            return _tuples(adapter.validate_python(value, strict=strict))
        except pydantic.ValidationError as exc:
            rule = [e for e in exc.errors(include_url=False) if not _is_type_error(e["type"])]
            broken = broken or (rule[0] if rule else None)
    if broken is not None:
        raise ValueError(f"--set {key}: {_problem(broken)}")
    raise ValueError(f"--set {key}: expected {_accepts(cls, name)}, got {_shown(text)}")


def _is_type_error(kind: str) -> bool:
    """Whether a pydantic error kind says the value is not of the declared type."""
    return kind.endswith(("_type", "_parsing", "_parsing_size")) or kind in _TYPE_ERRORS


def _aliases(cls: type, top: bool) -> dict[str, str]:
    """Alias -> field name for ``cls`` (the top-level config also takes ``max_cycles``)."""
    own = dict(getattr(cls, "aliases", None) or {})
    return {**TOP_ALIASES, **own} if top else own


def _nested(cls: type) -> dict[str, type]:
    """Sub-config fields of ``cls``: field name -> sub-config dataclass."""
    return dict(getattr(cls, "nested", None) or {})


def _resolve(cls: type, name: str, where: str, top: bool) -> str:
    """The field ``name`` means in ``cls`` (aliases resolved); raises ``ValueError`` on an unknown key."""
    aliases = _aliases(cls, top)
    field_name = aliases.get(name, name)
    fields = _annotations(cls)
    if field_name not in fields:
        also = f" (aliases: {', '.join(f'{a} -> {k}' for a, k in sorted(aliases.items()))})" if aliases else ""
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


def _object(cls: type, value: Mapping[str, Any], where: str) -> dict[str, Any]:
    """A JSON object given for sub-config ``cls``, key by key (values converted by the declarations, lax)."""
    out: dict[str, Any] = {}
    for key, item in value.items():
        name = _resolve(cls, str(key), where, top=False)
        sub = _nested(cls).get(name)
        if sub is not None and isinstance(item, dict):
            out[name] = _object(sub, item, f"{where}{name}.")
            continue
        try:
            out[name] = _tuples(_adapter(cls, name).validate_python(item, strict=False))
        except pydantic.ValidationError as exc:
            rule = [e for e in exc.errors(include_url=False) if not _is_type_error(e["type"])]
            problem = _problem(rule[0]) if rule else f"expected {_accepts(cls, name)}, got {_shown(item)}"
            raise ValueError(f"--set {where + name}: {problem}") from None
    return out


def _leaf(cls: type, name: str, text: str, where: str) -> Any:
    """Parse the value of field ``name`` of ``cls`` from the command line."""
    sub = _nested(cls).get(name)
    key = where + name
    if sub is None:
        return _convert(cls, name, text, key)
    takes_none = _takes_none(cls, name)
    if takes_none and text.strip().lower() in NONE_WORDS:
        return None
    try:
        value = _json(text)
    except ValueError:
        value = None
    except _Refused as exc:
        raise ValueError(f"--set {key}: {exc}") from None
    if not isinstance(value, dict):
        none = " or none" if takes_none else ""
        raise ValueError(
            f'--set {key}: expected a JSON object of {sub.__name__} fields{none} (e.g. {key}={{"field": 1}}) '
            f"or dotted keys ({key}.FIELD=VALUE), got {_shown(text)}"
        )
    return _object(sub, value, f"{key}.")


def _takes_none(cls: type, name: str) -> bool:
    """Whether field ``name`` of ``cls`` is declared to take ``None``."""
    try:
        _adapter(cls, name).validate_python(None)
    except pydantic.ValidationError:
        return False
    return True


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
    """Parse ``--set KEY=VALUE`` pairs into config values, each by the declaration of the field it sets.

    Args:
        config_cls: The scenario's config class (``scenario_class(name).config_cls``); its ``nested``
            ClassVar names the sub-config fields, its ``aliases`` ClassVar the alias keys.
        pairs: ``KEY=VALUE`` strings; ``KEY`` may be dotted (``body.radius``) to set one field of a sub-config.
            Later pairs override earlier ones; a sub-config's dotted keys and JSON objects merge.

    Returns:
        Config values by field name (aliases resolved, sub-configs as dicts of their fields), ready for
        ``agentsim_env.make(name, **values)``.

    Raises:
        ValueError: On a pair without ``=``, an unknown key (listing the allowed ones), an alias given with
            its field, or a value the field's declaration refuses (naming the dotted key, the value and what
            the field accepts or the rule it breaks).
    """
    out: dict[str, Any] = {}
    spelled: dict[str, str] = {}  # field -> the top-level key that set it (to catch alias + field)
    for pair in pairs:
        key, sep, text = pair.partition("=")
        key = key.strip()
        path = key.split(".")
        if not sep or not key or any(not p for p in path):
            raise ValueError(f"--set expects KEY=VALUE (e.g. n_agents=8 or body.radius=1.0), got {_shown(pair)}")
        name = _resolve(config_cls, path[0], "", top=True)
        if spelled.setdefault(name, path[0]) != path[0]:
            raise ValueError(f"--set: give {name!r} under one name only, got {spelled[name]!r} and {path[0]!r}")
        _assign(config_cls, out, path, text, "", top=True)
    return out


def canonical(values: Mapping[str, Any]) -> str:
    """A stable text of parsed ``--set`` values (sorted keys, tuples as lists) for naming outputs."""
    return json.dumps(values, sort_keys=True, default=str, separators=(",", ":"))

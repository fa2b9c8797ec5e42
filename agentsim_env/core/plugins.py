"""Name registries for what a user's own package adds: scenarios, policies and release strategies.

A :class:`Registry` maps a name to an object or to a ``"module:attribute"`` reference, imported on first
:meth:`Registry.get`. It holds three kinds of entries:

* built-ins, given when the registry is made (references to the library's own modules);
* registrations, from :meth:`Registry.register` (``agentsim_env.register_scenario`` and friends);
* entry points of the registry's group in installed distributions (``[project.entry-points."<group>"]`` in a
  ``pyproject.toml``), read once, on first use (:meth:`Registry.refresh` reads them again).

A name belongs to one entry: a registration may not take a built-in's or an earlier registration's name
unless ``replace=True``; an entry point that repeats a taken name is skipped with a ``RuntimeWarning``.

An installed plug-in that cannot be used (its module raises on import, the attribute is missing, the object is
of the wrong kind, or a caller's check of it fails) harms only its own name: :meth:`Registry.get` raises a
:class:`PluginLoadError` naming it, and the listings that load plug-ins (:meth:`Registry.usable_names`) leave
it out with one :class:`PluginLoadWarning` per process. :meth:`Registry.names` loads nothing.

The three registries: :data:`SCENARIOS` (group ``agentsim_env.scenarios``: ``Scenario`` subclasses),
:data:`POLICIES` (group ``agentsim_env.policies``: policy classes with ``for_env``, ``reset`` and ``act``) and
:data:`STRATEGIES` (group ``agentsim_env.strategies``: release strategy classes or factories).
``docs/extending.md`` shows a plug-in package using all three.

This module imports nothing of the package (core, layer 0); ``importlib.metadata`` loads on first use.
"""

from __future__ import annotations

import importlib
import re
import warnings
from collections.abc import Callable, Iterable, Iterator
from typing import Any

__all__ = [
    "POLICIES",
    "SCENARIOS",
    "STRATEGIES",
    "PluginLoadError",
    "PluginLoadWarning",
    "Registry",
    "check_name",
    "load_ref",
    "policy_scenarios",
    "register_policy",
    "register_scenario",
    "register_strategy",
]

_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}")
_DOTTED = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*")
_WARNED: set[tuple[str, str, str]] = set()  # (group, name, reference) of the plug-ins warned about


class PluginLoadWarning(UserWarning):
    """An installed plug-in cannot be used and is left out of a listing (warned once per process per plug-in)."""


class PluginLoadError(ValueError):
    """An installed plug-in cannot be used: its entry point does not load, or the object it names is refused.

    Args:
        kind, name, ref, group, dist: What it is ("policy", ...), its entry point's name, ``"module:attribute"``
            and group, and the distribution that provides it.
        error: The original exception (raised ``from`` it).
        loaded: Whether the object loaded (and a caller's check of it failed).
    """

    def __init__(self, kind: str, name: str, ref: str, group: str, dist: str, error: Exception, loaded: bool) -> None:
        self.kind, self.name, self.ref, self.group, self.dist, self.error = kind, name, ref, group, dist, error
        what = "loads but cannot be used" if loaded else "cannot be loaded"
        super().__init__(
            f"{kind} plug-in {name!r} = {ref!r} (entry-point group {group!r} of {dist}) {what}: "
            f"{type(error).__name__}: {error}; reinstall or uninstall the package that provides it"
        )


def check_name(kind: str, name: Any) -> str:
    """``name`` if it is a valid registry name, else a ``ValueError`` naming the kind and the rule.

    Args:
        kind: What is named ("scenario", "policy", ...), for the message.
        name: The name: 1 to 64 characters, letters, digits, ``_``, ``-`` and ``.``, starting with a letter
            or a digit.

    Returns:
        The name.
    """
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ValueError(
            f"{kind} name must be 1 to 64 characters of letters, digits, '_', '-' and '.', starting with a "
            f"letter or a digit; got {name!r}"
        )
    return name


def _check_ref(kind: str, ref: str) -> tuple[str, str]:
    """The module and attribute of ``"module:attribute"``, or a ``ValueError`` naming the reference."""
    module, sep, attr = ref.partition(":")
    if not sep or not _DOTTED.fullmatch(module) or not _DOTTED.fullmatch(attr):
        raise ValueError(
            f"{kind} reference {ref!r} must be 'package.module:attribute' (dotted Python names around one colon)"
        )
    return module, attr


def load_ref(kind: str, ref: str, check: Callable[[Any], bool] | None = None, expected: str = "") -> Any:
    """Import ``"package.module:attribute"`` and return the attribute (a dotted attribute is followed).

    Args:
        kind: What the reference names ("scenario", ...), for the messages.
        ref: The reference.
        check: Tells whether the loaded object is of the right kind (None: anything goes).
        expected: What ``check`` accepts, for the message.

    Returns:
        The object.

    Raises:
        ValueError: The reference is malformed, its module is not installed, the attribute is missing, or the
            object fails ``check`` (the message names the reference and what was expected).
    """
    module, attr = _check_ref(kind, ref)
    try:
        obj: Any = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        # only the named module (or a package above it) missing is a bad reference; a module that fails on
        # an import of its own raises as it is
        if exc.name is None or not (module == exc.name or module.startswith(exc.name + ".")):
            raise
        raise ValueError(f"{kind} reference {ref!r}: no module named {exc.name!r}") from None
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise ValueError(f"{kind} reference {ref!r}: {module!r} has no attribute {attr!r}")
        obj = getattr(obj, part)
    if check is not None and not check(obj):
        raise ValueError(f"{kind} reference {ref!r} is {_describe(obj)}, expected {expected}")
    return obj


def _describe(obj: Any) -> str:
    """``obj`` in a few words for an error message ("the class Foo", "a function", "an int")."""
    if isinstance(obj, type):
        return f"the class {obj.__qualname__}"
    kind = type(obj).__name__
    return f"{'an' if kind[:1] in 'aeiouAEIOU' else 'a'} {kind}"


class Registry:
    """Names -> objects or ``"module:attribute"`` references, with entry points of one group (module docstring).

    Args:
        kind: What an entry is ("scenario", "policy", "strategy"), for messages.
        group: The entry-point group read from installed distributions.
        builtins: Built-in entries, name -> object or reference.
        check: Tells whether an object is of the right kind (applied on registration and on loading).
        expected: What ``check`` accepts, in words, for messages.
    """

    def __init__(
        self,
        kind: str,
        group: str,
        builtins: dict[str, Any] | None = None,
        check: Callable[[Any], bool] | None = None,
        expected: str = "",
    ) -> None:
        self.kind, self.group, self.check, self.expected = kind, group, check, expected or "an object"
        self._builtins: dict[str, Any] = {}
        for name, entry in (builtins or {}).items():
            self._builtins[check_name(kind, name)] = self._checked_entry(name, entry)
        self._registered: dict[str, Any] = {}
        self._entry_points: dict[str, Any] | None = None  # name -> reference; read on first use
        self._origin: dict[str, str] = {}  # entry-point name -> where it comes from, for messages
        self._dist: dict[str, str] = {}  # entry-point name -> distribution, for messages
        self._loaded: dict[str, Any] = {}  # name -> object loaded from a reference
        self._failed: dict[str, tuple[Exception, bool]] = {}  # entry-point name -> (its error, it loaded)

    # -------------------------------------------------------------------------------- registration
    def register(self, name: str, obj: Any, *, replace: bool = False) -> None:
        """Register ``obj`` (an object or a ``"module:attribute"`` reference, loaded on first use) as ``name``.

        Args:
            name: The name (see :func:`check_name`).
            obj: The object, or its reference.
            replace: Take the name even when a built-in, an earlier registration or an installed entry point
                holds it.

        Raises:
            ValueError: A bad name, a malformed reference, an object of the wrong kind, or a name already taken
                (the message says by what) without ``replace``.
        """
        check_name(self.kind, name)
        entry = self._checked_entry(name, obj)
        if not replace and name in self:
            raise ValueError(
                f"{self.kind} name {name!r} is already taken ({self.origin(name)}); pick another name or "
                "pass replace=True"
            )
        self._registered[name] = entry
        self._loaded.pop(name, None)

    def unregister(self, name: str) -> None:
        """Remove a registration made with :meth:`register` (built-ins and entry points stay).

        Raises:
            ValueError: ``name`` was not registered with :meth:`register`.
        """
        if name not in self._registered:
            raise ValueError(
                f"{self.kind} {name!r} was not registered with register(); registered: {sorted(self._registered)}"
            )
        del self._registered[name]
        self._loaded.pop(name, None)

    def _checked_entry(self, name: str, obj: Any) -> Any:
        """``obj`` if it is a well-formed reference or an object that passes ``check``, else a ValueError."""
        if isinstance(obj, str):
            _check_ref(self.kind, obj)
        elif self.check is not None and not self.check(obj):
            raise ValueError(
                f"{self.kind} {name!r} must be {self.expected} or a 'module:attribute' "
                f"reference to one, got {_describe(obj)}"
            )
        return obj

    # ------------------------------------------------------------------------------------- lookup
    def _eps(self) -> dict[str, Any]:
        """Entry points of the group not shadowed by built-ins (read once; duplicates warn)."""
        if self._entry_points is None:
            from importlib.metadata import entry_points

            found: dict[str, Any] = {}
            for ep in sorted(entry_points(group=self.group), key=lambda e: (e.name, e.value)):
                dist = getattr(getattr(ep, "dist", None), "name", None) or "an installed distribution"
                if not _NAME.fullmatch(ep.name):
                    warnings.warn(
                        f"skipping {self.kind} entry point {ep.name!r} of {dist} (group {self.group!r}): "
                        "not a valid name (letters, digits, '_', '-', '.')",
                        RuntimeWarning,
                        stacklevel=3,
                    )
                    continue
                if ep.name in self._builtins or ep.name in found:
                    if found.get(ep.name) == ep.value:  # the same distribution seen twice on sys.path
                        continue
                    taken = "a built-in" if ep.name in self._builtins else self._origin[ep.name]
                    warnings.warn(
                        f"skipping {self.kind} entry point {ep.name!r} = {ep.value!r} of {dist}: the name is "
                        f"taken by {taken}",
                        RuntimeWarning,
                        stacklevel=3,
                    )
                    continue
                found[ep.name] = ep.value
                self._origin[ep.name] = f"entry point {ep.value!r} of {dist}"
                self._dist[ep.name] = dist
            self._entry_points = found
        return self._entry_points

    def refresh(self) -> None:
        """Read the installed entry points again (after installing or removing a plug-in in this process)."""
        importlib.invalidate_caches()
        for name in self._entry_points or {}:
            self._loaded.pop(name, None)
        self._entry_points = None
        self._origin, self._dist, self._failed = {}, {}, {}

    def names(self) -> list[str]:
        """Every name: built-ins, registrations and entry points, sorted (nothing is loaded)."""
        return sorted({*self._builtins, *self._registered, *self._eps()})

    def is_plugin(self, name: str) -> bool:
        """Whether ``name`` is an installed entry point's (no registration or built-in of that name)."""
        return name not in self._registered and name not in self._builtins and name in self._eps()

    def load_error(self, name: str, validate: Callable[[str], object] | None = None) -> PluginLoadError | None:
        """Why installed plug-in ``name`` cannot be used (kept: :meth:`get` raises it until :meth:`refresh`), or
        None, also for a built-in, a registration or an unknown name (only plug-ins are loaded here).

        Args:
            name: The name.
            validate: Called with ``name`` once the plug-in loads; an exception it raises makes the plug-in
                unusable (a policy that names no scenario, a strategy class of another name, ...).
        """
        if not self.is_plugin(name):
            return None
        if name not in self._failed:
            try:
                self.get(name)
                if validate is not None:
                    validate(name)
            except PluginLoadError:
                pass  # get kept it
            except Exception as exc:  # the plug-in's own code may raise anything
                self._loaded.pop(name, None)
                self._failed[name] = (exc, True)
        return self._plugin_error(name) if name in self._failed else None

    def usable_names(self, validate: Callable[[str], object] | None = None) -> list[str]:
        """:meth:`names` less the installed plug-ins that cannot be used, each left out with one
        :class:`PluginLoadWarning` per process (plug-ins are loaded here; see :meth:`load_error`)."""
        names = []
        for name in self.names():
            error = self.load_error(name, validate)
            if error is None:
                names.append(name)
            elif (key := (self.group, name, error.ref)) not in _WARNED:
                _WARNED.add(key)
                warnings.warn(f"{error}; it is left out of the {self.kind} names", PluginLoadWarning, stacklevel=3)
        return names

    def builtin_names(self) -> list[str]:
        """The built-in names, sorted."""
        return sorted(self._builtins)

    def origin(self, name: str) -> str:
        """Where the entry ``name`` comes from, in words ("built-in", "registered", "entry point ... of ...")."""
        if name in self._registered:
            return "registered"
        if name in self._builtins:
            return "built-in"
        if name in self._eps():
            return self._origin[name]
        raise ValueError(self._unknown(name))

    def __contains__(self, name: object) -> bool:
        """Whether ``name`` is known (without loading it)."""
        return name in self._registered or name in self._builtins or name in self._eps()

    def __iter__(self) -> Iterator[str]:
        """The names, sorted."""
        return iter(self.names())

    def _unknown(self, name: str) -> str:
        return f"unknown {self.kind} {name!r}; known: {self.names()}"

    def _plugin_error(self, name: str) -> PluginLoadError:
        """A new :class:`PluginLoadError` of entry point ``name`` (one of ``_failed``)."""
        error, loaded = self._failed[name]
        return PluginLoadError(self.kind, name, self._eps()[name], self.group, self._dist[name], error, loaded)

    def get(self, name: str) -> Any:
        """The object registered as ``name`` (a reference is imported and checked on first use, then kept).

        Raises:
            PluginLoadError: ``name`` is an installed plug-in that cannot be used (its import raised, or
                :meth:`load_error` refused it); raised from the original exception.
            ValueError: An unknown name (the message lists the known ones) or a reference of a built-in or a
                registration that does not load (it names the reference and what was expected).
        """
        if name in self._loaded:
            return self._loaded[name]
        if name in self._failed and self.is_plugin(name):
            raise self._plugin_error(name) from self._failed[name][0]
        for table in (self._registered, self._builtins, self._eps()):
            if name in table:
                entry = table[name]
                break
        else:
            raise ValueError(self._unknown(name))
        if not isinstance(entry, str):
            return entry
        if table is self._entry_points:
            try:
                obj = load_ref(self.kind, entry, self.check, self.expected)
            except Exception as exc:  # a plug-in's module may raise anything on import
                self._failed[name] = (exc, False)
                raise self._plugin_error(name) from exc
        else:
            obj = load_ref(self.kind, entry, self.check, self.expected)
        self._loaded[name] = obj
        return obj

    def items(self, names: Iterable[str] | None = None) -> list[tuple[str, Any]]:
        """``(name, object)`` pairs of ``names`` (default: :meth:`usable_names`), loading references."""
        return [(n, self.get(n)) for n in (self.usable_names() if names is None else names)]


def _is_scenario_class(obj: Any) -> bool:
    """A class with the Scenario contract's attributes (``scenarios.registry`` checks the base class too)."""
    return isinstance(obj, type) and all(hasattr(obj, a) for a in ("config_cls", "make_world", "observe"))


def _is_policy_class(obj: Any) -> bool:
    """A class with ``for_env``, ``reset`` and ``act`` (the ``Policy`` protocol and its constructor)."""
    return isinstance(obj, type) and all(callable(getattr(obj, a, None)) for a in ("for_env", "reset", "act"))


SCENARIOS = Registry(
    "scenario",
    "agentsim_env.scenarios",
    {
        "navigation": "agentsim_env.scenarios.navigation:SCENARIO",
        "relay": "agentsim_env.scenarios.relay:SCENARIO",
        "rendezvous": "agentsim_env.scenarios.rendezvous:SCENARIO",
        "uav_release": "agentsim_env.uav.scenario:SCENARIO",
    },
    _is_scenario_class,
    "a Scenario subclass",
)
"""Scenarios by name (``agentsim_env.scenarios.registry`` builds them)."""

POLICIES = Registry("policy", "agentsim_env.policies", None, _is_policy_class, "a policy class (for_env, reset, act)")
"""Policies added to the scripted baselines (``agentsim_env.policies.registry`` lists the built-in ones); each
serves the scenarios given to :func:`register_policy`, else those of its class attribute ``scenarios``."""

_SHIPPED_STRATEGIES = {
    "B0_uniform": "B0Uniform",
    "B1_inverse_cdf": "B1InverseCdf",
    "B1LD_sunflower": "B1LDSunflower",
    "B2_rings": "B2Rings",
    "B3_spiral": "B3Spiral",
    "B4_boustrophedon": "B4Boustrophedon",
    "B5_cvt": "B5Cvt",
    "B6_drop_clusters": "B6DropClusters",
    "B7_ergodic": "B7Ergodic",
    "B8_teleport": "B8Teleport",
}
STRATEGIES = Registry(
    "strategy",
    "agentsim_env.strategies",
    {name: f"agentsim_env.policies.release.baselines:{cls}" for name, cls in _SHIPPED_STRATEGIES.items()},
    lambda obj: isinstance(obj, type),
    "a ReleaseStrategy subclass",
)
"""Release strategies: the shipped B0-B8 (built-in references) and those registered or installed as plug-ins;
``agentsim_env.policies.release.registry`` reads it and checks each class (``docs/release_strategies.md``)."""

_POLICY_SCENARIOS: dict[str, tuple[str, ...]] = {}  # policy name -> scenarios given to register_policy


def _scenario_tuple(where: str, value: Any) -> tuple[str, ...]:
    """``value`` (a name or names) as a tuple of valid scenario names, or a ValueError naming ``where``."""
    names = (value,) if isinstance(value, str) else value
    if not isinstance(names, (tuple, list)) or not names:
        raise ValueError(f"{where} must be a scenario name or a non-empty tuple of them, got {value!r}")
    return tuple(check_name("scenario", n) for n in names)


def register_scenario(name: str, scenario: Any, *, replace: bool = False) -> None:
    """Make scenario ``name`` available to ``agentsim_env.make``, ``list_scenarios`` and the CLI.

    Args:
        name: The scenario's name; it must equal the class's ``name`` attribute.
        scenario: A ``Scenario`` subclass, or its ``"module:Class"`` reference (imported on first use).
        replace: Take the name even when a built-in, an earlier registration or an entry point holds it.

    Raises:
        ValueError: A bad name or reference, an object that is no scenario class, or a taken name.
    """
    SCENARIOS.register(name, scenario, replace=replace)


def register_policy(
    name: str, policy: Any, *, scenario: str | tuple[str, ...] | None = None, replace: bool = False
) -> None:
    """Make policy ``name`` available to ``make_policy``, ``baseline_names`` and ``agentsim run --policy``.

    Args:
        name: The policy's name; it may not repeat a built-in baseline of a scenario it serves.
        policy: A policy class (``for_env`` classmethod, ``reset``, ``act``: the ``Policy`` protocol), or its
            ``"module:Class"`` reference (imported on first use).
        scenario: The scenario (or scenarios) it serves; None: those of the class attribute ``scenarios``.
        replace: Take the name even when an earlier registration or an entry point holds it.

    Raises:
        ValueError: A bad name, reference, scenario name or object, or a taken name.
    """
    served = None if scenario is None else _scenario_tuple("scenario", scenario)
    POLICIES.register(name, policy, replace=replace)
    if served is None:
        _POLICY_SCENARIOS.pop(name, None)
    else:
        _POLICY_SCENARIOS[name] = served


def policy_scenarios(name: str) -> tuple[str, ...]:
    """The scenarios policy ``name`` of :data:`POLICIES` serves (loads a reference to read ``scenarios``).

    Raises:
        ValueError: An unknown policy, or one that names no scenario (neither ``register_policy(...,
            scenario=)`` nor a class attribute ``scenarios``).
    """
    if name in _POLICY_SCENARIOS and POLICIES.origin(name) == "registered":
        return _POLICY_SCENARIOS[name]
    served = getattr(POLICIES.get(name), "scenarios", None)
    if served is None:
        raise ValueError(
            f"policy {name!r} ({POLICIES.origin(name)}) names no scenario: give register_policy(..., "
            "scenario='...') or a class attribute scenarios = ('my_scenario',)"
        )
    return _scenario_tuple(f"policy {name!r}: class attribute scenarios", served)


def register_strategy(name: str, strategy: Any, *, replace: bool = False) -> None:
    """Make release strategy ``name`` available (``docs/release_strategies.md``).

    Args:
        name: The strategy's name.
        strategy: A ``ReleaseStrategy`` subclass whose ``name`` is ``name``, or its ``"module:attribute"``
            reference (imported on first use).
        replace: Take the name even when an earlier registration or an entry point holds it.

    Raises:
        ValueError: A bad name or reference, an object that is not a class, or a taken name.
    """
    STRATEGIES.register(name, strategy, replace=replace)

"""Loading YAML configs with bounded work: the one YAML reader of the package.

``yaml.safe_load`` builds no arbitrary objects, but it still takes a few hundred bytes of anchors and aliases
that expand to billions of values (each alias is a reference, and whatever walks the result walks every one),
nesting deep enough to exhaust Python's recursion, and a key given twice (the last one wins, silently). A
config file is small, plain data, so it is held to these bounds, each refused with one line naming the file
and the line:

=========================  ===========================================================================
bound                      refused
=========================  ===========================================================================
``MAX_CONFIG_BYTES``       a file over 1 MiB (at most that plus one byte is read), and anything that is
                           not a regular file (a folder, ``/dev/zero``, a FIFO)
``MAX_DEPTH``              lists and mappings nested more than 32 levels deep, aliases expanded
``MAX_NODES``              more than 10,000 values in all (keys, values and list items) once every alias
                           is expanded: anchors and aliases stay usable for sharing a section, never for
                           multiplying one; an alias inside the node it names (a recursive structure)
duplicate keys             a key given twice in one mapping (``<<`` merge keys may still be overridden)
big integers               an integer of more than 4,300 digits (Python's own bound on converting text)
=========================  ===========================================================================

The text must be UTF-8 and hold one document.
"""

from __future__ import annotations

import os
import sys
from typing import Any

import yaml
from yaml.events import MappingStartEvent, SequenceStartEvent
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from agentsim_env.core.files import read_regular
from agentsim_env.core.validation import short_repr

__all__ = [
    "MAX_CONFIG_BYTES",
    "MAX_DEPTH",
    "MAX_NODES",
    "YAMLConfigError",
    "load_yaml_file",
    "load_yaml_text",
]

#: Largest config file read, in bytes.
MAX_CONFIG_BYTES = 1 << 20
#: Most levels of nested lists and mappings (the document's top mapping is level 1).
MAX_DEPTH = 32
#: Most values (scalars, lists and mappings) in a document once every alias is expanded.
MAX_NODES = 10_000

_MERGE_TAG = "tag:yaml.org,2002:merge"


class YAMLConfigError(ValueError):
    """A config file that is not YAML or is outside the bounds above; the message names the file and line."""


def load_yaml_file(path: str | os.PathLike[str], name: str | None = None) -> Any:
    """Read and parse a YAML config file within the module's bounds.

    Args:
        path: The file (a regular file of at most ``MAX_CONFIG_BYTES`` bytes of UTF-8 text).
        name: How the file is named in errors (default: the path).

    Returns:
        The parsed document (``None`` for an empty file).

    Raises:
        YAMLConfigError: On a file that is not YAML, not UTF-8, or outside the bounds.
        ValueError: On a folder, a device, a FIFO or a file over ``MAX_CONFIG_BYTES`` (from ``read_regular``).
        OSError: When the file cannot be opened or read.
    """
    label = str(path) if name is None else name
    data = read_regular(path, MAX_CONFIG_BYTES, "a YAML config")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise YAMLConfigError(
            f"{label}: not UTF-8 text (byte {data[exc.start]:#04x} at position {exc.start:,}); "
            "re-save the file as UTF-8"
        ) from None
    return load_yaml_text(text, label)


def load_yaml_text(text: str, name: str) -> Any:
    """Parse YAML text within the module's bounds (see the module docstring).

    Args:
        text: The YAML text.
        name: What the text is (a file name), at the start of every error.

    Returns:
        The parsed document (``None`` for an empty one).

    Raises:
        YAMLConfigError: Naming the file, the line and the bound or the YAML error, on one line.
    """
    if len(text) > MAX_CONFIG_BYTES:
        raise YAMLConfigError(f"{name}: {len(text):,} characters; a YAML config is at most {MAX_CONFIG_BYTES:,}")
    loader = _BoundedLoader(text, name)
    try:
        return loader.get_single_data()
    except yaml.MarkedYAMLError as exc:
        raise YAMLConfigError(f"{name}: not valid YAML: {_one_line(exc)}") from None
    except yaml.YAMLError as exc:
        raise YAMLConfigError(f"{name}: not valid YAML: {' '.join(str(exc).split())}") from None
    finally:
        loader.dispose()


def _one_line(exc: yaml.MarkedYAMLError) -> str:
    """A YAML error as one line: what, and where (PyYAML's own text spans several lines and quotes the file)."""
    parts = [p for p in (exc.context, exc.problem) if p]
    mark = exc.problem_mark or exc.context_mark
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return " ".join(" ".join(parts).split()) + where


def _line(node_or_mark: Any) -> int:
    """The 1-based line of a node or mark."""
    mark = getattr(node_or_mark, "start_mark", node_or_mark)
    return int(mark.line) + 1


class _BoundedLoader(yaml.SafeLoader):
    """``SafeLoader`` that counts and bounds while composing, then checks the node graph before building it."""

    def __init__(self, stream: str, name: str) -> None:
        super().__init__(stream)
        self.name = name
        self.depth = 0  # lists and mappings open around the node being composed
        self.composed = 0

    def compose_node(self, parent: Node | None, index: Any) -> Node:
        """Compose one node, refusing the ``MAX_NODES + 1``-th node and nesting past ``MAX_DEPTH``."""
        event = self.peek_event()
        self.composed += 1
        if self.composed > MAX_NODES:  # before the graph pass: a flat list of 10**6 items is never composed
            raise YAMLConfigError(
                f"{self.name}: more than {MAX_NODES:,} values (line {_line(event)}); a config "
                f"holds at most {MAX_NODES:,}, aliases expanded"
            )
        nested = isinstance(event, (SequenceStartEvent, MappingStartEvent))
        if nested and self.depth >= MAX_DEPTH:  # before Python's recursion limit: three frames per level
            raise _too_deep(self.name, event)
        self.depth += nested
        try:
            return super().compose_node(parent, index)  # type: ignore[no-any-return]
        finally:
            self.depth -= nested

    def get_single_node(self) -> Node | None:
        """The document's node graph, checked (sizes with aliases expanded, depth, cycles, duplicate keys)."""
        node = super().get_single_node()
        if node is not None:
            _Graph(self).check(node)
        return node  # type: ignore[no-any-return]

    def construct_yaml_int(self, node: ScalarNode) -> int:
        """An integer, or one clear error where Python refuses to convert that many digits."""
        try:
            return super().construct_yaml_int(node)  # type: ignore[no-any-return]
        except ValueError:
            digits = sum(c.isdigit() for c in str(node.value))
            raise YAMLConfigError(
                f"{self.name}: the integer at line {_line(node)} has {digits:,} digits; at "
                f"most {sys.get_int_max_str_digits():,} are allowed"
            ) from None


_BoundedLoader.add_constructor("tag:yaml.org,2002:int", _BoundedLoader.construct_yaml_int)


def _too_deep(name: str, where: Any) -> YAMLConfigError:
    return YAMLConfigError(
        f"{name}: nested deeper than {MAX_DEPTH} levels (line {_line(where)}); a config is "
        f"at most {MAX_DEPTH} levels of lists and mappings deep, aliases expanded"
    )


class _Graph:
    """One walk over a composed document: every node once, its expanded size and height remembered.

    Aliases make the composed document a graph (an alias is the node it names), so the walk remembers each node
    and the work stays linear in the file whatever the aliases expand to. The walk recurses along the
    expanded depth, which it refuses past ``MAX_DEPTH``, so it never nears the recursion limit.
    """

    def __init__(self, loader: _BoundedLoader) -> None:
        self.loader = loader
        self.size: dict[int, int] = {}  # id(node) -> values under it, itself included, aliases expanded
        self.height: dict[int, int] = {}  # id(node) -> levels of lists and mappings from it down
        self.on_path: set[int] = set()

    def check(self, root: Node) -> None:
        self.visit(root, 0)

    def visit(self, node: Node, depth: int) -> None:
        """Size and height of ``node``, met below ``depth`` levels of lists and mappings."""
        key = id(node)
        if key in self.on_path:
            raise YAMLConfigError(
                f"{self.loader.name}: the alias to the node at line {_line(node)} is inside that "
                "node (a recursive structure); a config is a tree"
            )
        if key not in self.size:
            if isinstance(node, ScalarNode):
                self.size[key], self.height[key] = 1, 0
            else:
                self.on_path.add(key)
                if depth + 1 > MAX_DEPTH:
                    raise _too_deep(self.loader.name, node)
                children = self.children(node)
                size, height = 1, 0
                for child in children:
                    self.visit(child, depth + 1)
                    size += self.size[id(child)]
                    height = max(height, self.height[id(child)])
                    if size > MAX_NODES:
                        raise YAMLConfigError(
                            f"{self.loader.name}: aliases expand the node at line {_line(node)} "
                            f"to more than {MAX_NODES:,} values; a config holds at most "
                            f"{MAX_NODES:,}, aliases expanded"
                        )
                if isinstance(node, MappingNode):
                    self.check_keys(node)
                self.size[key], self.height[key] = size, height + 1
                self.on_path.discard(key)
        if depth + self.height[key] > MAX_DEPTH:  # a node met again, deeper, through an alias
            raise _too_deep(self.loader.name, node)

    @staticmethod
    def children(node: Node) -> list[Node]:
        if isinstance(node, SequenceNode):
            return list(node.value)
        return [n for pair in node.value for n in pair]

    def check_keys(self, node: MappingNode) -> None:
        """Refuse a scalar key given twice in one mapping (merge keys ``<<`` aside)."""
        seen: dict[Any, ScalarNode] = {}
        for key_node, _ in node.value:
            if not isinstance(key_node, ScalarNode) or key_node.tag == _MERGE_TAG:
                continue
            key = self.loader.construct_object(key_node, deep=True)  # 1, 0x1 and 1.0 are one key to a dict
            try:
                first = seen.setdefault(key, key_node)
            except TypeError:  # unhashable: the constructor reports it
                continue
            if first is not key_node:
                raise YAMLConfigError(
                    f"{self.loader.name}: duplicate key {short_repr(key, 60)} at line "
                    f"{_line(key_node)} (first at line {_line(first)}); each key may be given "
                    "once"
                )

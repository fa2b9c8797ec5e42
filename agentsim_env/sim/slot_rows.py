"""Per-slot hand-over rows: every per-slot array of a world's agent, packed for some slots and written back.

A shard that takes an agent over from another needs all of that agent's state, not a hand-picked list that a
new field silently misses. The arrays are found generically: every numpy array attribute whose first dimension
is the slot count S, on the world's per-slot owners and the objects they hold (recursively, objects of this
package only, below the roots):

| root       | what it holds per slot                                                              |
|------------|-------------------------------------------------------------------------------------|
| `state`    | `AgentState`: position, velocity, heading, online, group, energy, limits...         |
| `motion`   | the motion stage and its `MotionState` (primitive, parameters, waypoints, clock)   |
| `task`     | the scenario's `SlotState` (its ``per_world`` fields are not per slot: skipped)     |
| `groups`   | the group controller: last heartbeat answer, timed-out flag                         |
| `comms`    | the comms stack's counters, the bus's per-sender counters, the inbox rows, ranges   |
| `payloads` | the payload stage's per-slot arrays (scenarios with payloads)                       |
| `sensors.<name>`, `readings.<name>` | each sensor's per-slot state and its latest reading        |

Left out (``EXCLUDED``): scratch buffers (rewritten before they are read), state rebuilt from positions every
step (the comms range graph), and tables whose rows are not slots (messages in flight, overlay floods, per-code
counters); these belong to whole worlds and travel with the bus and overlay exchanges, not with an agent.
An array of a world with as many worlds as slots (one agent per world) would look per-slot: such worlds are
not split into shards.

Rows are keyed by the attribute path (``"state.pos"``, ``"comms.bus.inbox.payload"``); an array reachable
under two paths (the controller's ``group`` is the state's) is packed once.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from typing import Any

import numpy as np

from agentsim_env.sim.world import World

EXCLUDED: frozenset[str] = frozenset(
    {
        "comms.graph",  # range graph: rebuilt from positions every step
        "comms.events",  # the last step's events, not state
        "comms._inbox_out",  # observation output buffer
        "comms._no_near",  # constant lookup filler
        "comms.bus._queue",  # messages in flight: rows per message (the bus exchange carries them)
        "comms.bus._ctl_codes",  # per control code, not per slot
        "comms.bus._ctl_counts",
        "comms.bus.inbox._newest",  # push scratch, zero between pushes
        "comms.bus.inbox._taken",
        "comms.overlay._scratch",  # flood kernel scratch
        # the overlay's flood table: rows per flood, not per slot (the coordinator keeps floods)
        "comms.overlay._rd_start",
        "comms.overlay._rd_len",
        "comms.overlay._pool",
        "comms.overlay._origin",
        "comms.overlay._limit",
        "comms.overlay._hops",
        "comms.overlay._created",
        "comms.overlay._payload",
        "comms.overlay._active",
        "comms.overlay._free",
        "comms.overlay._front_f",
        "comms.overlay._front_n",
        "sensors.proximity._out",  # the scan's output buffer (its reading is carried under readings.proximity)
        "sensors.proximity.directions",  # ray directions (K, 3): per ray, not per slot
    }
)
"""Attribute paths that are not carried (see the module docstring)."""

_MAX_DEPTH = 4


def _attributes(obj: Any) -> Iterator[tuple[str, Any]]:
    seen: set[str] = set()
    d = getattr(obj, "__dict__", None)
    if d is not None:
        seen.update(d)
        yield from d.items()
    for cls in type(obj).__mro__:
        for name in getattr(cls, "__slots__", ()):
            if name in seen or name.startswith("__"):
                continue
            seen.add(name)
            if hasattr(obj, name):
                yield name, getattr(obj, name)


def _per_world_fields(obj: Any) -> set[str]:
    if not dataclasses.is_dataclass(obj):
        return set()
    return {f.name for f in dataclasses.fields(obj) if f.metadata.get("per_world")}


def _walk(path: str, obj: Any, n_slots: int, depth: int, seen: set[int], out: dict[str, np.ndarray]) -> None:
    if path in EXCLUDED or id(obj) in seen:
        return
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        if obj.ndim >= 1 and obj.shape[0] == n_slots:
            out[path] = obj
        return
    if depth >= _MAX_DEPTH or (depth and not type(obj).__module__.startswith("agentsim_env.")):
        return  # a root is walked whatever its module (a scenario's SlotState may live outside the package)
    skip = _per_world_fields(obj)
    for name, value in _attributes(obj):
        if name not in skip and (isinstance(value, np.ndarray) or type(value).__module__.startswith("agentsim_env.")):
            _walk(f"{path}.{name}", value, n_slots, depth + 1, seen, out)


def slot_arrays(world: World) -> dict[str, np.ndarray]:
    """Every per-slot array of ``world`` by attribute path (the arrays themselves, not copies).

    Args:
        world: The world.

    Returns:
        ``{path: array}`` with ``array.shape[0] == world.state.n_slots``, in a fixed order.
    """
    n = world.state.n_slots
    roots: list[tuple[str, Any]] = [
        ("state", world.state),
        ("motion", world.motion_stage),
        ("task", world.task),
        ("groups", world.groups),
        ("comms", world.comms),
        ("payloads", world.payloads),
    ]
    roots += [(f"sensors.{s.name}", s) for s in world.sensors]
    roots += [(f"readings.{k}", v) for k, v in world.readings.items()]
    out: dict[str, np.ndarray] = {}
    seen: set[int] = set()
    for path, obj in roots:
        if obj is not None:
            _walk(path, obj, n, 0, seen, out)
    return out


def _slots(world: World, slots: np.ndarray) -> np.ndarray:
    s = np.asarray(slots)
    if s.size and not np.issubdtype(s.dtype, np.integer):
        raise ValueError(f"slots must be integers, got dtype {s.dtype}")
    s = s.astype(np.int64).reshape(-1)
    n = world.state.n_slots
    if s.size and (s.min() < 0 or s.max() >= n):
        raise ValueError(f"slots must be in [0, {n}), got min {int(s.min())} max {int(s.max())}")
    return s


def pack_slot_rows(world: World, slots: np.ndarray) -> dict[str, np.ndarray]:
    """The rows of ``slots`` of every per-slot array of ``world`` (fresh arrays, safe to send).

    Args:
        world: The world the agents leave.
        slots: Slot indices ``(k,)``.

    Returns:
        ``{path: array[slots]}`` (see :func:`slot_arrays`).

    Raises:
        ValueError: When a slot is out of range.
    """
    s = _slots(world, slots)
    return {path: arr[s] for path, arr in slot_arrays(world).items()}


def unpack_slot_rows(world: World, slots: np.ndarray, rows: dict[str, np.ndarray]) -> None:
    """Write rows packed by :func:`pack_slot_rows` into ``slots`` of ``world`` (in place).

    The world must be built from the same scenario config as the one packed (the same per-slot arrays).
    Derived state (the agent grid, the comms range graph) is rebuilt by the next step as usual.

    Args:
        world: The world the agents join.
        slots: Slot indices ``(k,)``, in the order they were packed.
        rows: The packed rows.

    Raises:
        ValueError: When a slot is out of range, or the two worlds' per-slot arrays differ (naming them).
    """
    s = _slots(world, slots)
    arrays = slot_arrays(world)
    if arrays.keys() != rows.keys():
        missing, extra = sorted(arrays.keys() - rows.keys()), sorted(rows.keys() - arrays.keys())
        raise ValueError(
            f"the rows do not match this world's per-slot arrays: missing {missing}, unknown {extra} "
            f"(pack and unpack worlds of one scenario config)"
        )
    for path, arr in arrays.items():
        row = rows[path]
        if row.shape != (s.size, *arr.shape[1:]):
            raise ValueError(f"rows of {path!r} have shape {row.shape}, expected {(s.size, *arr.shape[1:])}")
        arr[s] = row

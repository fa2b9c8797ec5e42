"""The step API's rows between the driver and the shards on its own machine, through shared memory.

The step API brings every acting agent's observation row back to the driver each step (73 MB at 100,000 agents
in ``navigation`` with comms). Returned through Ray, each shard's rows are copied into Ray's object store after
the shard's step (~20-30 ms a step at 100,000 agents on 2 CPUs, measured) and read from there by the driver. A
shard on the driver's node instead writes its rows straight into its region of a segment that the driver created
(``ObsSegment``), and replies with their count; the driver scatters them into its observation array as it does
with rows returned through Ray. The segment also holds two arrays of every slot's row (``ObsSegment.full``) that
the array front end hands out as the step's observations, in turn: a step told to fill one of them has each such
shard write its rows straight at their slots' rows there, and the driver copies nothing (73 MB a step at 100,000
agents). An array is handed out again only once the caller let it go and it is not the one the previous step
filled (whose rows stand in for the agents of a shard lost in a step). Actions go the other way the same way: the
driver writes such a shard's acting slots and action rows into its region of a second segment (``RowSegment``)
before the call, which then carries only their count instead of 8.8 MB through the object store. The reply's
other per-agent rows (rewards, terminations, infos of the acting agents; every own agent's kinematics for the
driver's mirror: ~5 MB a shard at 100,000 agents, ~4 ms more a call through the object store, measured) come back
through two more such segments (``reply_layouts``), so the reply itself is a few hundred bytes. A shard on
another node keeps Ray for all of it.

Region ``k`` belongs to shard ``k`` and holds up to every slot of the world (a shard may come to own them all);
a segment is a file of ``/dev/shm`` whose pages exist only once written, so it occupies about one row per acting
agent, not ``K`` times the world. The driver reads a region only after its shard answered the step, and never the
region of a shard that failed: a shard killed while writing leaves nothing half-written behind in what the driver
keeps. A shard lost in a step told to fill a full array may have written part of its rows there, and may still be
writing until its process is gone: the driver takes that step's rows from a copy made after the step (its agents'
rows those of the previous step) and never hands that array out again. A shard copies the slots it reads; it
reads the action rows during the call, before the driver writes the next step's.

Security: the segments are created with mode 0600 (their owner only) under random names that only the driver
and, through Ray, its shards know; a shard checks a segment's size before it maps rows. The driver unlinks them
when the env closes (and Python's resource tracker does if the driver dies); shards map them without taking
ownership.
"""

from __future__ import annotations

import mmap
import os
import secrets
import sys
from multiprocessing import resource_tracker
from multiprocessing.shared_memory import SharedMemory
from typing import Any

import numpy as np

from agentsim_env.distributed.row_kernels import gather_rows

ROW_BYTES = 4  # float32


def _region_bytes(n_slots: int, obs_dim: int) -> int:
    return int(n_slots) * int(obs_dim) * ROW_BYTES


def _create(kind: str, size: int) -> SharedMemory:
    # mode 0600 (the module's default), a name nobody can guess
    return SharedMemory(name=f"agentsim-{kind}-{secrets.token_hex(12)}", create=True, size=max(1, int(size)))


def _attach(name: str, need: int, what: str) -> SharedMemory:
    # map a segment the driver owns: this process's resource tracker must not unlink it when the shard exits
    try:
        shm = SharedMemory(name=name, track=False)  # type: ignore[call-arg]  # Python >= 3.13
    except TypeError:
        shm = SharedMemory(name=name)
        resource_tracker.unregister(shm._name, "shared_memory")  # type: ignore[attr-defined]
    if shm.size < need:
        shm.close()
        raise ValueError(f"the {what} segment {name!r} holds {shm.size} bytes, needs {need}")
    return shm


def _release(shm: SharedMemory | None, unlink: bool) -> None:
    # unmap (a caller may still hold a view: the mapping then goes with it) and, for the owner, remove the name
    if shm is None:
        return
    try:
        shm.close()
    except BufferError:
        pass
    if unlink:
        try:
            shm.unlink()
        except FileNotFoundError:
            pass


N_FULL = 2  # the full arrays after the shards' regions: one handed out, the other the previous step's


def _full_views(shm: SharedMemory, n_shards: int, n_slots: int, obs_dim: int) -> tuple[np.ndarray, ...]:
    # Arrays a caller may keep past ``close``: mapped on their own, each a view of a 1-D array that numpy holds as
    # a buffer export of that mapping, so the mapping lives as long as one of them does (views built on
    # ``shm.buf`` would point into unmapped memory once the segment is closed: a crash when read). Views of them
    # refer to that 1-D array (numpy collapses a view's base onto it): ``_in_use`` counts both.
    size = _region_bytes(n_slots, obs_dim)
    mm = mmap.mmap(shm._fd, (n_shards + N_FULL) * size)  # type: ignore[attr-defined]
    return tuple(
        np.frombuffer(mm, dtype=np.float32, count=n_slots * obs_dim, offset=(n_shards + b) * size).reshape(
            n_slots, obs_dim
        )
        for b in range(N_FULL)
    )


def _in_use(full: tuple[np.ndarray, ...], b: int) -> bool:
    # free: referenced by the tuple only (and getrefcount's argument); its 1-D base by it only (and the argument)
    return sys.getrefcount(full[b]) != 2 or sys.getrefcount(full[b].base) != 2


class ObsSegment:
    """The driver's segment: ``n_shards`` regions of ``(n_slots, obs_dim)`` float32 rows, then ``N_FULL`` arrays
    of every slot's row (``full``).

    Args:
        n_shards: Number of shards K (one region each).
        n_slots: Slots in the world (a region's capacity in rows).
        obs_dim: Length of a flat observation row.
    """

    def __init__(self, n_shards: int, n_slots: int, obs_dim: int) -> None:
        self.n_shards, self.n_slots, self.obs_dim = int(n_shards), int(n_slots), int(obs_dim)
        size = (self.n_shards + N_FULL) * _region_bytes(self.n_slots, self.obs_dim)
        self._shm: SharedMemory | None = _create("obs", size)
        self.name = self._shm.name.lstrip("/")
        self.full: tuple[np.ndarray, ...] = _full_views(self._shm, self.n_shards, self.n_slots, self.obs_dim)
        """The arrays of every slot's row ``(n_slots, obs_dim)`` the shards can fill at their slots' rows."""
        self.retired: set[int] = set()
        """The full arrays not handed out again (a shard lost while it may have been writing into them)."""

    def free_full(self, avoid: np.ndarray | None = None) -> np.ndarray | None:
        """A full array nobody else references (the caller let it go), neither ``avoid`` nor retired; or None."""
        for b in range(len(self.full)):
            if b not in self.retired and self.full[b] is not avoid and not _in_use(self.full, b):
                return self.full[b]
        return None

    def full_index(self, out: np.ndarray | None) -> int:
        """Which full array ``out`` is (-1: none of them)."""
        for b, a in enumerate(self.full):
            if out is a:
                return b
        return -1

    def rows(self, k: int, n: int) -> np.ndarray:
        """The first ``n`` rows shard ``k`` wrote this step (a view: copy or scatter them before the next step)."""
        if self._shm is None:
            raise RuntimeError("the observation segment is closed")
        if not (0 <= k < self.n_shards and 0 <= n <= self.n_slots):
            raise ValueError(f"shard must be in [0, {self.n_shards}) and rows in [0, {self.n_slots}], got {k}, {n}")
        at = k * _region_bytes(self.n_slots, self.obs_dim)
        return np.ndarray((n, self.obs_dim), dtype=np.float32, buffer=self._shm.buf, offset=at)

    def close(self) -> None:
        """Unmap and remove the segment (idempotent; a full array the caller still holds stays readable)."""
        shm, self._shm = self._shm, None
        self.full = ()
        _release(shm, unlink=True)


class ObsWriter:
    """A shard's view of its region of the driver's segment (mapped, never owned: the driver unlinks it).

    Args:
        name: The segment's name (``ObsSegment.name``).
        region: This shard's region index.
        n_shards: Regions in the segment.
        n_slots: A region's capacity in rows.
        obs_dim: Length of a row.

    Raises:
        ValueError: When the segment is smaller than ``n_shards`` regions of that shape.
    """

    def __init__(self, name: str, region: int, n_shards: int, n_slots: int, obs_dim: int) -> None:
        if not 0 <= region < n_shards:
            raise ValueError(f"the observation segment has regions 0..{n_shards - 1}, got {region}")
        need = (int(n_shards) + N_FULL) * _region_bytes(n_slots, obs_dim)
        self._shm = shm = _attach(name, need, "observation")
        self.array: np.ndarray = np.ndarray(
            (int(n_slots), int(obs_dim)),
            dtype=np.float32,
            buffer=shm.buf,
            offset=int(region) * _region_bytes(n_slots, obs_dim),
        )
        self.full: tuple[np.ndarray, ...] = _full_views(shm, int(n_shards), int(n_slots), int(obs_dim))
        """The driver's arrays of every slot's row (``ObsSegment.full``): a step may have rows written there."""

    def close(self) -> None:
        """Unmap the region (the segment stays for the driver)."""
        self.array = np.zeros((0, 0), dtype=np.float32)
        self.full = ()
        _release(self._shm, unlink=False)


def _row_bytes(n_slots: int, layout: tuple[tuple[str, int, str], ...]) -> list[int]:
    # byte offsets within a region: the slots (int64), then each part's rows, each block 64-byte aligned
    offsets, at = [], 0
    for nbytes in [int(n_slots) * 8] + [int(n_slots) * size * np.dtype(dt).itemsize for _, size, dt in layout]:
        offsets.append(at)
        at += -(-nbytes // 64) * 64
    offsets.append(at)
    return offsets


class _Regions:
    """Views of the action regions of a segment (``layout``: each part's name, row size and dtype)."""

    def __init__(self, buf: Any, n_slots: int, layout: tuple[tuple[str, int, str], ...]) -> None:
        self.n_slots, self.layout = int(n_slots), layout
        self.offsets = _row_bytes(n_slots, layout)
        self._buf = buf

    @property
    def region_bytes(self) -> int:
        """Bytes of one shard's region."""
        return self.offsets[-1]

    def views(self, k: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Region ``k``: its slots ``(S,)`` int64 and each part's rows ``(S, size)``."""
        base = k * self.region_bytes
        slots = np.ndarray((self.n_slots,), dtype=np.int64, buffer=self._buf, offset=base + self.offsets[0])
        parts = {
            name: np.ndarray(
                (self.n_slots, size), dtype=np.dtype(dt), buffer=self._buf, offset=base + self.offsets[i + 1]
            )
            for i, (name, size, dt) in enumerate(self.layout)
        }
        return slots, parts


def reply_layouts(n_info: int) -> tuple[tuple[tuple[str, int, str], ...], tuple[tuple[str, int, str], ...]]:
    """The layouts of a step reply's per-agent rows: the acting agents' (reward, termination and the scenario's
    ``n_info`` info values, carried as float64: exact for its bools, ints and floats) and every own agent's
    kinematics (for the driver's mirror)."""
    acted = (("rewards", 1, "<f8"), ("terminated", 1, "|b1"), *((f"info{i}", 1, "<f8") for i in range(n_info)))
    own = (("pos", 3, "<f8"), ("vel", 3, "<f8"), ("heading", 1, "<f8"), ("online", 1, "|b1"))
    return acted, own


SHM_DIR = "/dev/shm"


def shm_room() -> int | None:
    """Bytes free in ``/dev/shm`` (where the segments' pages live), or ``None`` where it cannot be read."""
    try:
        st = os.statvfs(SHM_DIR)
    except OSError:
        return None
    return int(st.f_bavail) * int(st.f_frsize)


def rows_bytes(n_slots: int, obs_dim: int, act_layout: tuple[tuple[str, int, str], ...], n_info: int) -> int:
    """The pages the step API's segments come to hold when every slot's rows are written once (the regions of
    all shards together: each slot is one shard's at a time; the full arrays whole)."""
    acted, own = reply_layouts(n_info)
    return (1 + N_FULL) * _region_bytes(n_slots, obs_dim) + sum(
        _row_bytes(n_slots, lay)[-1] for lay in (act_layout, acted, own)
    )


class RowSegment:
    """A driver's segment of rows by slot: per shard, a list of slots and their rows of each part (the step API's
    actions, written by the driver; the replies' per-agent rows, written by the shards: ``reply_layouts``).

    Args:
        n_shards: Number of shards K (one region each).
        n_slots: Slots in the world (a region's capacity).
        layout: Each part's name, row size and dtype (``np.dtype.str``), in order.
        kind: What it holds, in its name (``act``, ``acted``, ``own``).
    """

    def __init__(
        self, n_shards: int, n_slots: int, layout: tuple[tuple[str, int, str], ...], kind: str = "act"
    ) -> None:
        self.n_shards, self.n_slots, self.layout = int(n_shards), int(n_slots), tuple(layout)
        self._shm: SharedMemory | None = _create(kind, self.n_shards * _row_bytes(self.n_slots, self.layout)[-1])
        self.name = self._shm.name.lstrip("/")
        self._regions = _Regions(self._shm.buf, self.n_slots, self.layout)

    def rows(self, k: int, n: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """The first ``n`` slots and rows of region ``k`` (views: read them before the shard's next call)."""
        if self._shm is None:
            raise RuntimeError("the row segment is closed")
        if not (0 <= k < self.n_shards and 0 <= n <= self.n_slots):
            raise ValueError(f"shard must be in [0, {self.n_shards}) and rows in [0, {self.n_slots}], got {k}, {n}")
        slots, parts = self._regions.views(k)
        return slots[:n], {name: rows[:n] for name, rows in parts.items()}

    def write(self, k: int, slots: np.ndarray, parts: dict[str, np.ndarray]) -> int:
        """Shard ``k``'s acting ``slots`` and their rows of ``parts`` (``(S, size)`` each) into its region; their
        count (what the call then carries)."""
        if self._shm is None:
            raise RuntimeError("the action segment is closed")
        n = int(slots.shape[0])
        into, rows = self._regions.views(k)
        into[:n] = slots
        for name, _, _ in self.layout:
            gather_rows(parts[name], slots, rows[name][:n])
        return n

    def close(self) -> None:
        """Unmap and remove the segment (idempotent)."""
        shm, self._shm = self._shm, None
        self._regions = _Regions(memoryview(b""), 0, ())
        _release(shm, unlink=True)


class RowReader:
    """A shard's view of its region of a driver's row segment (mapped, never owned).

    Raises:
        ValueError: When the segment is smaller than ``n_shards`` regions of that layout.
    """

    def __init__(
        self,
        name: str,
        region: int,
        n_shards: int,
        n_slots: int,
        layout: tuple[tuple[str, int, str], ...],
        what: str = "action",
    ) -> None:
        if not 0 <= region < n_shards:
            raise ValueError(f"the {what} segment has regions 0..{n_shards - 1}, got {region}")
        self._shm = shm = _attach(name, int(n_shards) * _row_bytes(n_slots, layout)[-1], what)
        self.n_slots = int(n_slots)
        self._slots, self._parts = _Regions(shm.buf, n_slots, tuple(layout)).views(int(region))

    def write(self, slots: np.ndarray, parts: dict[str, np.ndarray] | None) -> int:
        """``slots`` and the rows ``parts[name][slots]`` of every part of the layout (full-length arrays, 1-D for
        a part of row size 1; ``None``: the slots only) into the region; their count (what the reply then
        carries).

        Raises:
            ValueError: For more slots than the region holds.
        """
        n = int(slots.shape[0])
        if n > self.n_slots:
            raise ValueError(f"the region holds {self.n_slots} rows, got {n}")
        self._slots[:n] = slots
        if parts is None:
            return n
        for name, rows in self._parts.items():
            src = parts[name]
            if src.ndim == 1:
                np.take(src, slots, out=rows[:n, 0])
            else:
                gather_rows(src, slots, rows[:n])
        return n

    def read(self, n: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """The ``n`` acting slots the driver wrote (a copy) and their action rows (views, valid during the call)."""
        if not 0 <= n <= self.n_slots:
            raise ValueError(f"the action rows must number 0..{self.n_slots}, got {n}")
        return self._slots[:n].copy(), {name: rows[:n] for name, rows in self._parts.items()}

    def close(self) -> None:
        """Unmap the region (the segment stays for the driver)."""
        self._slots, self._parts = np.zeros(0, dtype=np.int64), {}
        _release(self._shm, unlink=False)

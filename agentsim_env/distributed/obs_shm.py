"""Observation rows from shards on the driver's own machine through one shared-memory segment.

The step API brings every acting agent's observation row back to the driver each step (73 MB at 100,000 agents
in ``navigation`` with comms). Returned through Ray, each shard's rows are copied into Ray's object store after
the shard's step (~30 ms a step at 100,000 agents on 2 CPUs, measured) and read from there by the driver. A shard
on the driver's node instead writes its rows straight into its region of one segment that the driver created
(``ObsSegment``), and replies with their count; the driver scatters them into its observation array as it does
with rows returned through Ray. A shard on another node keeps returning its rows through Ray.

Region ``k`` belongs to shard ``k`` and holds up to every slot of the world (a shard may come to own them all);
the segment is a file of ``/dev/shm`` whose pages exist only once written, so it occupies about one row per
acting agent, not ``K`` times the world. The driver reads a region only after its shard answered the step, and
never the region of a shard that failed: a shard killed while writing leaves nothing half-written behind in
what the driver keeps.

Security: the segment is created with mode 0600 (its owner only) under a random name that only the driver and,
through Ray, its shards know; a shard checks the segment's size before it maps rows. The driver unlinks it when
the env closes (and Python's resource tracker does if the driver dies); shards map it without taking ownership.
"""

from __future__ import annotations

import secrets
from multiprocessing import resource_tracker
from multiprocessing.shared_memory import SharedMemory

import numpy as np

ROW_BYTES = 4  # float32


def _region_bytes(n_slots: int, obs_dim: int) -> int:
    return int(n_slots) * int(obs_dim) * ROW_BYTES


class ObsSegment:
    """The driver's segment: ``n_shards`` regions of ``(n_slots, obs_dim)`` float32 rows.

    Args:
        n_shards: Number of shards K (one region each).
        n_slots: Slots in the world (a region's capacity in rows).
        obs_dim: Length of a flat observation row.
    """

    def __init__(self, n_shards: int, n_slots: int, obs_dim: int) -> None:
        self.n_shards, self.n_slots, self.obs_dim = int(n_shards), int(n_slots), int(obs_dim)
        size = max(1, self.n_shards * _region_bytes(self.n_slots, self.obs_dim))
        self._shm: SharedMemory | None = SharedMemory(name=f"agentsim-obs-{secrets.token_hex(12)}", create=True,
                                                      size=size)  # fmt: skip
        self.name = self._shm.name.lstrip("/")

    def rows(self, k: int, n: int) -> np.ndarray:
        """The first ``n`` rows shard ``k`` wrote this step (a view: copy or scatter them before the next step)."""
        if self._shm is None:
            raise RuntimeError("the observation segment is closed")
        if not (0 <= k < self.n_shards and 0 <= n <= self.n_slots):
            raise ValueError(f"shard must be in [0, {self.n_shards}) and rows in [0, {self.n_slots}], got {k}, {n}")
        at = k * _region_bytes(self.n_slots, self.obs_dim)
        return np.ndarray((n, self.obs_dim), dtype=np.float32, buffer=self._shm.buf, offset=at)

    def close(self) -> None:
        """Unmap and remove the segment (idempotent)."""
        shm, self._shm = self._shm, None
        if shm is None:
            return
        try:
            shm.close()
        except BufferError:  # a caller still holds a view: the mapping goes with it, the name goes now
            pass
        try:
            shm.unlink()
        except FileNotFoundError:
            pass


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
        try:
            shm = SharedMemory(name=name, track=False)  # type: ignore[call-arg]  # Python >= 3.13
        except TypeError:
            shm = SharedMemory(name=name)
            # the driver owns the segment: this process's tracker must not unlink it when the shard exits
            resource_tracker.unregister(shm._name, "shared_memory")  # type: ignore[attr-defined]
        need = int(n_shards) * _region_bytes(n_slots, obs_dim)
        if not 0 <= region < n_shards or shm.size < need:
            shm.close()
            raise ValueError(f"the observation segment {name!r} holds {shm.size} bytes, region {region} of "
                             f"{n_shards} needs {need}")  # fmt: skip
        self._shm = shm
        self.array: np.ndarray = np.ndarray((int(n_slots), int(obs_dim)), dtype=np.float32, buffer=shm.buf,
                                            offset=int(region) * _region_bytes(n_slots, obs_dim))  # fmt: skip

    def close(self) -> None:
        """Unmap the region (the segment stays for the driver)."""
        self.array = np.zeros((0, 0), dtype=np.float32)
        try:
            self._shm.close()
        except BufferError:
            pass

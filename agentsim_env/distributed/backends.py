"""How the coordinator reaches its shards: in process (``LocalShards``) or as Ray actors (``ray_backend``).

A backend runs one method on several shards at once and answers, per shard, either the shard's packed reply
or a :class:`Failure` (the shard died, missed the deadline, or raised). It never raises for a shard that failed:
the coordinator declares that shard offline and goes on. An exception raised by the shard's own code counts as a
failure too: the shard's state is unknown after it (a persistent fault would break every later call), so the
shard is dropped like a dead one and started anew at the next ``reset``; the exception travels in the
``Failure`` (the coordinator logs its traceback, and chains it when no shard is left).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from agentsim_env.distributed.shard import Packed, Shard


@dataclass(frozen=True, slots=True)
class Failure:
    """A shard that did not answer: why (``"died: ..."``, ``"missed the ... deadline"`` or ``"raised ..."``).

    Attributes:
        reason: One line for ``env.shards`` and the log.
        error: The exception the shard's code raised (``None`` for a shard that died or was late).
    """

    reason: str
    error: BaseException | None = None


def raised(error: BaseException) -> Failure:
    """The failure of a shard whose code raised ``error``."""
    return Failure(f"raised {type(error).__name__}: {error}", error)


class Backend(Protocol):
    """The calls a coordinator makes on its shards."""

    n_shards: int
    address: str  # where the shards run, for messages ("local", a cluster address)

    def call(
        self, method: str, calls: dict[int, tuple[Any, ...]], timeout_s: float
    ) -> dict[int, Packed | Failure]:
        """Run ``method(*args)`` on every shard named in ``calls``; wait at most ``timeout_s`` for all."""

    def restart(self, index: int) -> None:
        """Start shard ``index`` anew (its previous process is gone or abandoned)."""

    def kill(self, index: int) -> None:
        """Stop shard ``index`` at once (tests: a machine that dies)."""

    def close(self) -> None:
        """Stop every shard."""


class LocalShards:
    """Shards in this process, called one after another (debugging, tests, machines without Ray).

    Deadlines are checked after the fact (a call cannot be interrupted): a shard whose call took longer than
    the deadline is declared offline all the same, and its answer thrown away. A shard whose call raised is
    dropped (see the module docstring).

    Args:
        factory: Builds shard ``k``.
        n_shards: Number of shards K.
    """

    def __init__(self, factory: Callable[[int], Shard], n_shards: int) -> None:
        self.n_shards = int(n_shards)
        self._factory = factory
        self.shards: dict[int, Shard | None] = {k: factory(k) for k in range(self.n_shards)}
        self.address = "local"

    def call(
        self, method: str, calls: dict[int, tuple[Any, ...]], timeout_s: float
    ) -> dict[int, Packed | Failure]:
        """Run ``method`` on each named shard in turn (see :class:`Backend`)."""
        out: dict[int, Packed | Failure] = {}
        for k, args in calls.items():
            shard = self.shards.get(k)
            if shard is None:
                out[k] = Failure("died: the shard was stopped")
                continue
            t0 = time.perf_counter()
            try:
                reply = getattr(shard, method)(*args)
            except Exception as e:  # the shard's state is unknown now: drop it until a restart
                self.shards[k] = None
                out[k] = raised(e)
                continue
            took = time.perf_counter() - t0
            if took > timeout_s:
                self.shards[k] = None  # its answer came too late: it is offline until a restart
                out[k] = Failure(f"missed the {timeout_s:g} s deadline of {method} (took {took:.2f} s)")
            else:
                out[k] = reply
        return out

    def restart(self, index: int) -> None:
        """Build shard ``index`` anew."""
        self.shards[index] = self._factory(index)

    def kill(self, index: int) -> None:
        """Drop shard ``index`` (its next call answers a failure)."""
        self.shards[index] = None

    def set_delay(self, index: int, delay_s: float) -> None:
        """Test hook: shard ``index`` sleeps ``delay_s`` in every call."""
        shard = self.shards[index]
        if shard is not None:
            shard.set_delay(delay_s)

    def close(self) -> None:
        """Drop every shard."""
        self.shards = dict.fromkeys(self.shards)

"""Input checks of the message bus (``comms.bus``): each raises one ValueError naming the field."""

from __future__ import annotations

import numpy as np

from agentsim_env.comms.messages import ENV, GROUP, HEARTBEAT

__all__ = ["bool_mask", "int_vector", "validate_send", "world_arrays"]


def validate_send(
    kind: int,
    snd: np.ndarray,
    tgt: np.ndarray,
    world: np.ndarray | None,
    group: np.ndarray | None,
    n_worlds: int,
    n_agents: int,
) -> np.ndarray:
    """Check one ``MessageBus.send`` batch and return the world of every message.

    Args:
        kind: The batch's kind.
        snd: ``(k,)`` int64 senders.
        tgt: ``(k,)`` int64 targets.
        world: ``(k,)`` or scalar world per message, or None.
        group: ``(S,)`` group array to check GROUP targets against (None: GROUP batches raise).
        n_worlds: Worlds B.
        n_agents: Agents per world N.

    Returns:
        ``(k,)`` int64 world of each message.
    """
    n, k = n_agents, snd.shape[0]
    s_n = n_worlds * n
    if k and (snd.min() < -1 or snd.max() >= s_n):
        i = int(np.flatnonzero((snd < -1) | (snd >= s_n))[0])
        raise ValueError(f"sender must be -1 or a slot in [0, {s_n}), got {snd[i]} at row {i}")
    if kind == ENV and np.any(snd != -1):
        raise ValueError(f"sender of ENV messages must be -1 (the environment), got {snd[snd != -1][0]}")
    agent = snd >= 0
    wld = np.where(agent, snd // n, -1)
    if world is not None:
        w = np.broadcast_to(np.asarray(world, dtype=np.int64), (k,))
        if np.any((w < 0) | (w >= n_worlds)):
            raise ValueError(f"world must be in [0, {n_worlds}), got {w.min()}..{w.max()}")
        if np.any(agent & (w != wld)):
            i = int(np.flatnonzero(agent & (w != wld))[0])
            raise ValueError(f"world {w[i]} does not match the world {wld[i]} of sender agent {snd[i]}")
        wld = np.where(agent, wld, w)
    if kind == GROUP:
        _check_groups(snd, tgt, wld, agent, group, s_n, n)
        return wld
    to_ctrl = agent if kind == HEARTBEAT else np.zeros(k, dtype=bool)
    if np.any(tgt[to_ctrl] != -1):
        raise ValueError("target of an agent's HEARTBEAT must be -1 (the controller)")
    out = ~to_ctrl & ((tgt < 0) | (tgt >= s_n))
    if out.any():
        i = int(np.flatnonzero(out)[0])
        raise ValueError(f"target receiver slot {tgt[i]} out of range [0, {s_n}) (sender {snd[i]})")
    cross = ~to_ctrl & agent & (tgt // n != wld)
    if cross.any():
        i = int(np.flatnonzero(cross)[0])
        raise ValueError(
            f"target receiver slot {tgt[i]} (world {tgt[i] // n}) is not in the world {wld[i]} of sender agent {snd[i]}"
        )
    return np.where(~to_ctrl & ~agent, tgt // n, wld)


def _check_groups(snd, tgt, wld, agent, group, s_n, n) -> None:  # type: ignore[no-untyped-def]
    if np.any(~agent & (wld < 0)):
        raise ValueError("world is required for GROUP messages from the environment / controller (sender -1)")
    if group is None:
        raise ValueError("group: no group array to validate GROUP targets; bind one or pass group=")
    g = np.asarray(group)
    if g.shape != (s_n,):
        raise ValueError(f"group must have shape ({s_n},), got {g.shape}")
    if tgt.size == 0:
        return
    n_g = int(max(g.max(initial=-1), tgt.max())) + 1
    members = np.flatnonzero(g >= 0)
    known = np.isin(wld * n_g + tgt, (members // n) * n_g + g[members]) & (tgt >= 0)
    if not known.all():
        i = int(np.flatnonzero(~known)[0])
        raise ValueError(f"target: unknown group {tgt[i]} in world {wld[i]} (sender {snd[i]})")


def world_arrays(
    s_n: int, pos: np.ndarray, online: np.ndarray, group: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``pos`` ``(S, 3)`` float64, ``online`` ``(S,)`` bool (both C-contiguous) and ``group`` ``(S,)``, checked."""
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    online, group = np.ascontiguousarray(online, dtype=bool), np.asarray(group)
    if pos.shape != (s_n, 3) or online.shape != (s_n,) or group.shape != (s_n,):
        raise ValueError(
            f"pos must be ({s_n}, 3), online and group ({s_n},); got {pos.shape}, {online.shape}, {group.shape}"
        )
    return pos, online, group


def bool_mask(x: np.ndarray | None, name: str, s_n: int) -> np.ndarray | None:
    """``x`` as a C-contiguous ``(S,)`` bool array (None stays None); ValueError naming ``name`` otherwise."""
    if x is None:
        return None
    a = np.asarray(x)
    if a.shape != (s_n,) or a.dtype != bool:
        raise ValueError(f"{name} must be a bool array of shape ({s_n},), got {a.dtype} {a.shape}")
    return np.ascontiguousarray(a)


def int_vector(x: np.ndarray, name: str, k: int | None = None) -> np.ndarray:
    """``x`` as a 1-D int64 array (of length ``k`` when given); ValueError naming ``name`` otherwise."""
    a = np.asarray(x)
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim != 1 or not (np.issubdtype(a.dtype, np.integer) or a.size == 0):
        raise ValueError(f"{name} must be a 1-D integer array, got {a.dtype} with shape {a.shape}")
    if k is not None and a.shape[0] != k:
        raise ValueError(f"{name} must have length {k} (one per message), got {a.shape[0]}")
    return a.astype(np.int64, copy=False)

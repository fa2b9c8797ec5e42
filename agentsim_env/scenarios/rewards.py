"""The reward composer every scenario configures.

reward_i = task_weight * task_i
         + group_share * mean(task_j for j in i's group and world, j acting this step)
         - collision_penalty * collided_i
         - energy_weight * energy_i
         - message_cost * messages_sent_i
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from agentsim_env.core.validation import check_float, coerce_fields


@dataclass(frozen=True)
class RewardConfig:
    """Weights of the reward terms (all >= 0).

    Attributes:
        task_weight: Weight of the agent's own task reward.
        group_share: Weight of the mean task reward of the agent's group.
        collision_penalty: Subtracted once when the agent collides.
        energy_weight: Multiplies the energy spent this step (scenario units, e.g. J or a speed-squared proxy).
        message_cost: Subtracted per message the agent sent this step.
    """

    task_weight: float = 1.0
    group_share: float = 0.0
    collision_penalty: float = 10.0
    energy_weight: float = 0.0
    message_cost: float = 0.0

    def __post_init__(self) -> None:
        coerce_fields(self, "reward.")
        for name in ("task_weight", "group_share", "collision_penalty", "energy_weight", "message_cost"):
            check_float(f"reward.{name}", getattr(self, name), 0.0)


def group_mean(
    values: np.ndarray, group: np.ndarray, world: np.ndarray, mask: np.ndarray, n_groups: int
) -> np.ndarray:
    """Mean of ``values`` over the masked members of each (world, group), broadcast back to every slot.

    Slots with group -1 (no group) get their own value.
    """
    g = np.where(group >= 0, group, 0).astype(np.int64)
    key = world.astype(np.int64) * max(n_groups, 1) + g
    size = int(key.max()) + 1 if key.size else 0
    w = mask.astype(np.float64)
    sums = np.bincount(key, weights=values * w, minlength=size)
    cnt = np.bincount(key, weights=w, minlength=size)
    mean = sums[key] / np.maximum(cnt[key], 1.0)
    return np.where(group >= 0, mean, values)


_NONE = np.zeros(0)  # stands in for an absent term (the kernel never reads it)


@nb.njit(cache=True, error_model="numpy")
def _compose_kernel(task, group, world, acting, n_groups, collided, energy, sent, w, use):  # type: ignore[no-untyped-def]
    # One pass for the group sums, one for the terms. The sums run in slot order like np.bincount and the
    # terms are added in the order of the numpy expression, so the result is bit-identical to it.
    tw, gs, cp, ew, mc = w[0], w[1], w[2], w[3], w[4]
    use_group, use_coll, use_energy, use_sent = use
    s_n = task.shape[0]
    ng = max(n_groups, 1)
    key = np.empty(s_n, dtype=np.int64)
    size = 0
    for s in range(s_n):
        k = world[s] * ng + (group[s] if group[s] >= 0 else 0)
        key[s] = k
        size = max(size, k + 1)
    sums = np.zeros(size if use_group else 0)
    cnt = np.zeros(size if use_group else 0)
    if use_group:
        for s in range(s_n):
            m = 1.0 if acting[s] else 0.0
            sums[key[s]] += task[s] * m
            cnt[key[s]] += m
    out = np.empty(s_n)
    for s in range(s_n):
        if not acting[s]:
            out[s] = 0.0
            continue
        r = tw * task[s]
        if use_group:
            g = sums[key[s]] / max(cnt[key[s]], 1.0) if group[s] >= 0 else task[s]
            r = r + gs * g
        if use_coll:
            r = r - cp * collided[s]
        if use_energy:
            r = r - ew * energy[s]
        if use_sent:
            r = r - mc * sent[s]
        out[s] = r
    return out


def compose_rewards(
    cfg: RewardConfig,
    task: np.ndarray,
    *,
    group: np.ndarray,
    world: np.ndarray,
    acting: np.ndarray,
    n_groups: int,
    collided: np.ndarray | None = None,
    energy: np.ndarray | None = None,
    messages_sent: np.ndarray | None = None,
) -> np.ndarray:
    """Combine the terms into one reward per slot (zero for slots that were not acting).

    One numba pass (the composition runs every step); :func:`compose_rewards_reference` is the numpy
    statement of the same formula.

    Args:
        cfg: The weights.
        task: Task reward per slot ``(S,)``.
        group: Group id per slot.
        world: World id per slot.
        acting: Slots that acted this step (alive at its start).
        n_groups: Number of groups per world.
        collided: Slots that collided this step.
        energy: Energy spent this step per slot.
        messages_sent: Messages sent this step per slot.

    Returns:
        Rewards ``(S,)`` as float64 (a fresh array).
    """
    use = (
        bool(cfg.group_share) and task.shape[0] > 0,
        collided is not None and bool(cfg.collision_penalty),
        energy is not None and bool(cfg.energy_weight),
        messages_sent is not None and bool(cfg.message_cost),
    )
    w = (float(cfg.task_weight), float(cfg.group_share), float(cfg.collision_penalty), float(cfg.energy_weight),
         float(cfg.message_cost))  # fmt: skip
    return _compose_kernel(
        np.asarray(task, dtype=np.float64),
        np.asarray(group),
        np.asarray(world),
        np.asarray(acting, dtype=np.bool_),
        int(n_groups),
        _NONE if collided is None else np.asarray(collided, dtype=np.float64),
        _NONE if energy is None else np.asarray(energy, dtype=np.float64),
        _NONE if messages_sent is None else np.asarray(messages_sent),
        w,
        use,
    )


def compose_rewards_reference(
    cfg: RewardConfig,
    task: np.ndarray,
    *,
    group: np.ndarray,
    world: np.ndarray,
    acting: np.ndarray,
    n_groups: int,
    collided: np.ndarray | None = None,
    energy: np.ndarray | None = None,
    messages_sent: np.ndarray | None = None,
) -> np.ndarray:
    """Plain numpy statement of :func:`compose_rewards` (same arguments; used by the tests)."""
    r = cfg.task_weight * task
    if cfg.group_share:
        r = r + cfg.group_share * group_mean(task, group, world, acting, n_groups)
    if collided is not None and cfg.collision_penalty:
        r = r - cfg.collision_penalty * collided
    if energy is not None and cfg.energy_weight:
        r = r - cfg.energy_weight * energy
    if messages_sent is not None and cfg.message_cost:
        r = r - cfg.message_cost * messages_sent
    return np.where(acting, r, 0.0)

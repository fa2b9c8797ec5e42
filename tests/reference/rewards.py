"""Plain numpy statement of the reward composition (:func:`agentsim_env.scenarios.rewards.compose_rewards`)."""

from __future__ import annotations

import numpy as np

from agentsim_env.scenarios.rewards import RewardConfig, group_mean


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
    """Plain numpy statement of :func:`compose_rewards` (same arguments)."""
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

"""TorchRL adapter: a scenario as a ``torchrl.envs.PettingZooWrapper`` (the only torchrl importer).

All agents form one group, ``"agents"`` (TorchRL would otherwise group ``uav_0, uav_1...`` under ``"uav"`` by
name), so one network can serve them all and tensors are ``[..., n_agents, ...]``. Agents that end leave the
episode early, so the wrapper runs with ``use_mask=True`` (``("agents", "mask")`` is False for an agent that
ended; its observation is zeros and the actions TorchRL still sends for it are ignored) and
``done_on_any=False`` (the episode ends when every agent has). Observations and actions are the flat float32
Boxes by default (keys ``("agents", "observation")`` and ``("agents", "action")``); ``return_state=True`` adds
the global ``"state"`` for centralised critics. Install with ``pip install "agentsim-env[torchrl]"``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from agentsim_env.env.parallel_env import AgentSimParallelEnv, build_parallel_env

_HINT = 'the TorchRL adapter needs torchrl: pip install "agentsim-env[torchrl]"'
try:
    from torchrl.envs import PettingZooWrapper
    from torchrl.envs.utils import MarlGroupMapType
except ImportError as exc:  # pragma: no cover - depends on the installation
    raise ImportError(_HINT) from exc

GROUP = "agents"
"""The one group every agent belongs to."""


def parallel_env(scenario: str, **config: Any) -> AgentSimParallelEnv:
    """The ParallelEnv of ``scenario`` in flat formats unless ``obs_format`` / ``action_format`` say otherwise.

    Args:
        scenario: Scenario name.
        **config: ParallelEnv keys (``render_mode``, ``obs_format``, ``action_format``, ``check_finite``) and
            scenario config keys.

    Returns:
        The ParallelEnv.
    """
    return build_parallel_env(scenario, {"obs_format": "flat", "action_format": "flat"}, **config)


def torchrl_env(
    scenario: str = "navigation",
    *,
    seed: int | None = None,
    device: str = "cpu",
    return_state: bool = False,
    wrap: Callable[[Any], Any] | None = None,
    **config: Any,
) -> PettingZooWrapper:
    """A scenario as a TorchRL environment: one group of all agents, masked, done when every agent is.

    Args:
        scenario: Scenario name.
        seed: Seed of the first reset (``None``: fresh entropy).
        device: Torch device of the tensors.
        return_state: Add the global state (``"state"``) for centralised critics.
        wrap: Applied to the ParallelEnv before TorchRL wraps it, e.g. ``agentsim_env.wrappers.EpisodeMetrics``
            (whose tally of the infos TorchRL does not pass on); it must return a PettingZoo ``ParallelEnv``.
        **config: ParallelEnv and scenario config keys (see :func:`parallel_env`).

    Returns:
        The ``PettingZooWrapper``; ``env.group_map == {"agents": [every agent id]}``.
    """
    env = parallel_env(scenario, **config)
    return PettingZooWrapper(
        env=env if wrap is None else wrap(env),
        group_map=MarlGroupMapType.ALL_IN_ONE_GROUP,
        use_mask=True,
        done_on_any=False,
        categorical_actions=True,
        return_state=return_state,
        seed=seed,
        device=device,
    )

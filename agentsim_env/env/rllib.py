"""RLlib adapter: a scenario as an RLlib ``MultiAgentEnv`` with one policy shared by every agent (the only RLlib
importer; ``distributed`` uses ray core only).

The env is RLlib's ``ParallelPettingZooEnv`` over the ParallelEnv, with two corrections: the episode is over
(``"__all__"``) when no agent is left, whatever mix of terminations and truncations ended the agents (RLlib's
wrapper requires all of the last step's agents to be terminated, or all truncated), and ``render()`` calls the
ParallelEnv's (RLlib's passes it an argument it does not take). Observations stay the scenario's Dict (``self``,
``lidar``, ``task``...) and are flattened by RLlib's ``FlattenObservations`` env-to-module connector (the new API
stack); actions are the flat Box, one vector per agent for RLlib's default Gaussian action distribution.
``ppo_config`` puts it together: PPO, one shared policy ``"shared"``. RLlib builds the env from its class and
``env_config`` (``{"scenario": name, **config}``), so nothing needs registering. Install with
``pip install "agentsim-env[rllib]"``.
"""

from __future__ import annotations

from typing import Any

from agentsim_env.env.parallel_env import build_parallel_env

_HINT = 'the RLlib adapter needs ray[rllib]: pip install "agentsim-env[rllib]"'
try:
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.connectors.env_to_module import FlattenObservations
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
except ImportError as exc:  # pragma: no cover - depends on the installation
    raise ImportError(_HINT) from exc

SHARED_POLICY = "shared"
"""The id of the one policy (RLModule) every agent maps to."""


class AgentSimRLlibEnv(ParallelPettingZooEnv):
    """A scenario as an RLlib multi-agent env (``ParallelPettingZooEnv`` with the corrections above).

    Args:
        config: RLlib's ``env_config``: ``scenario`` (default ``"navigation"``), ParallelEnv keys
            (``obs_format`` default ``"dict"``, ``action_format`` default ``"flat"``, ``render_mode``,
            ``check_finite``) and scenario config keys.
    """

    def __init__(self, config: dict[str, Any] | None = None) -> None:
        cfg = dict(config or {})  # RLlib's EnvContext is a dict with worker attributes: copy the keys only
        scenario = cfg.pop("scenario", "navigation")
        super().__init__(build_parallel_env(scenario, {"obs_format": "dict", "action_format": "flat"}, **cfg))

    # RLlib's stubs type the ids as Hashable and the returns as gymnasium's single-agent tuple
    def step(self, action_dict: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:  # type: ignore[override]
        """Step the live agents; ``"__all__"`` is set when none is left."""
        obs, rewards, terms, truncs, infos = self.par_env.step(action_dict)
        over = not self.par_env.agents
        terms["__all__"] = over and all(terms.values())
        truncs["__all__"] = over and not terms["__all__"]
        return obs, rewards, terms, truncs, infos

    def render(self) -> Any:
        """The ParallelEnv's frame (``render_mode="rgb_array"``), or None."""
        return self.par_env.render()


def flatten_observations(env: Any = None, spaces: Any = None, device: Any = None) -> Any:
    """The env-to-module connector: RLlib's ``FlattenObservations`` over every agent's Dict observation."""
    return FlattenObservations(multi_agent=True)


def shared_policy(agent_id: str, episode: Any = None, **kwargs: Any) -> str:
    """The policy mapping: every agent to ``SHARED_POLICY``."""
    return SHARED_POLICY


def ppo_config(scenario: str = "navigation", **config: Any) -> PPOConfig:
    """An RLlib ``PPOConfig`` (new API stack) on ``scenario`` with one policy shared by all agents.

    The config samples in the driver process (``num_env_runners=0``) and learns there too; scale it with
    ``.env_runners(num_env_runners=...)`` and ``.learners(...)`` as usual. Change anything else (``.training``,
    ``.rl_module``) on the returned object.

    Args:
        scenario: Scenario name.
        **config: ``env_config`` keys for :class:`AgentSimRLlibEnv` (ParallelEnv and scenario config keys).

    Returns:
        The PPO config; ``config.build_algo()`` builds the algorithm.
    """
    env_config = {"scenario": scenario, **config}
    AgentSimRLlibEnv(env_config).close()  # fail here, naming the key, on a bad config (not inside a worker)
    connector = flatten_observations if env_config.get("obs_format", "dict") == "dict" else None
    return (
        PPOConfig()
        .environment(AgentSimRLlibEnv, env_config=env_config)
        .env_runners(num_env_runners=0, env_to_module_connector=connector)
        .multi_agent(policies={SHARED_POLICY}, policy_mapping_fn=shared_policy)  # type: ignore[arg-type]
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={SHARED_POLICY: RLModuleSpec()}))
    )

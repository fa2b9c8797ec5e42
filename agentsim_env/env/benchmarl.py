"""BenchMARL adapter: a scenario as a BenchMARL task (the only benchmarl importer).

``AgentSimTaskClass`` is a BenchMARL ``TaskClass`` whose environments are the TorchRL environments of
``agentsim_env.env.torchrl`` (one group ``"agents"``, ``use_mask=True``, ``done_on_any=False``, flat float32
observations and continuous actions in [-1, 1], the global ``"state"`` for centralised critics). BenchMARL
simulates vectorisation with a ``SerialEnv`` of copies (``on_policy_n_envs_per_worker``). Build one with
``agentsim_task("navigation", n_agents=4)`` and hand it to ``benchmarl.experiment.Experiment(task=...)``; any
algorithm for continuous actions works (MAPPO, IPPO, MASAC, ...). Install with
``pip install "agentsim-env[benchmarl]"`` (BenchMARL pins an older TorchRL than TorchRL's latest: give it its own
environment).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

from agentsim_env.scenarios.registry import make_scenario

_HINT = 'the BenchMARL adapter needs benchmarl: pip install "agentsim-env[benchmarl]"'
try:
    from benchmarl.environments.common import TaskClass
except ImportError as exc:  # pragma: no cover - depends on the installation
    raise ImportError(_HINT) from exc

from agentsim_env.env.parallel_env import ENV_KEYS  # noqa: E402
from agentsim_env.env.torchrl import GROUP, torchrl_env  # noqa: E402 - after the hint for benchmarl


def _keep(spec: Any, keep: str) -> Any:
    """A copy of an observation spec with, in each group, only the entry ``keep`` (and no global state)."""
    spec = spec.clone()
    for key in list(spec.keys()):
        if key == "state":
            del spec[key]
            continue
        group = spec[key]
        for sub in list(group.keys()):
            if sub != keep:
                del group[sub]
    return spec


class AgentSimTaskClass(TaskClass):
    """A scenario as a BenchMARL task.

    Args:
        name: The task's name in BenchMARL's logs and folders (``agentsim_task`` uses the scenario's, upper case).
        config: ``scenario`` (a scenario name), then ParallelEnv and scenario config keys, as for
            ``agentsim_env.env.torchrl.torchrl_env``.
    """

    def __init__(self, name: str, config: dict[str, Any]) -> None:
        super().__init__(name=name, config=config)
        cfg = dict(config)
        scenario = cfg.pop("scenario")
        for key in ENV_KEYS:
            cfg.pop(key, None)
        self._max_steps = make_scenario(scenario, **cfg).max_steps  # also checks the config, naming bad keys

    def get_env_fun(self, num_envs: int, continuous_actions: bool, seed: int | None, device: Any) -> Callable[[], Any]:
        """A function building one TorchRL environment (BenchMARL makes ``num_envs`` copies itself)."""
        if not continuous_actions:
            raise ValueError("agentsim scenarios have continuous actions only: pick an algorithm that supports them")
        cfg = copy.deepcopy(self.config)
        scenario = cfg.pop("scenario")
        return lambda: torchrl_env(scenario, seed=seed, device=device, return_state=True, **cfg)

    def supports_continuous_actions(self) -> bool:
        """Actions are continuous (a Box in [-1, 1])."""
        return True

    def supports_discrete_actions(self) -> bool:
        """No discrete actions."""
        return False

    def has_render(self, env: Any) -> bool:
        """Frames only with ``render_mode="rgb_array"`` in the config."""
        return self.config.get("render_mode") == "rgb_array"

    def max_steps(self, env: Any) -> int:
        """The scenario's episode length (``max_steps``)."""
        return int(self._max_steps)

    def group_map(self, env: Any) -> dict[str, list[str]]:
        """One group ``"agents"`` of every agent."""
        return {GROUP: list(env.group_map[GROUP])}

    def observation_spec(self, env: Any) -> Any:
        """Each agent's flat observation, ``("agents", "observation")``."""
        return _keep(env.observation_spec, "observation")

    def info_spec(self, env: Any) -> Any:
        """The scenario's per-agent infos, ``("agents", "info")``."""
        return _keep(env.observation_spec, "info")

    def state_spec(self, env: Any) -> Any:
        """The global state (``"state"``) for centralised critics."""
        spec = env.observation_spec.clone()
        for key in list(spec.keys()):
            if key != "state":
                del spec[key]
        return spec

    def action_spec(self, env: Any) -> Any:
        """The flat continuous action of each agent, ``("agents", "action")``."""
        return env.full_action_spec

    def action_mask_spec(self, env: Any) -> Any:
        """None: every action is always available."""
        return None

    @staticmethod
    def env_name() -> str:
        """The environment's name in BenchMARL's logs and folders."""
        return "agentsim"


def agentsim_task(scenario: str = "navigation", **config: Any) -> AgentSimTaskClass:
    """A BenchMARL task over ``scenario``.

    Args:
        scenario: Scenario name.
        **config: ParallelEnv and scenario config keys (``n_agents``, ``max_steps``, ...).

    Returns:
        The task, for ``Experiment(task=...)``.

    Raises:
        ValueError: A bad scenario name or config key.
    """
    return AgentSimTaskClass(name=scenario.upper(), config={"scenario": scenario, **config})

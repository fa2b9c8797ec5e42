"""Importing this module registers ``agentsim/<scenario>-v<version>`` with Gymnasium, for every scenario.

Gymnasium's own ways to reach an id then work unchanged (importing ``agentsim_env`` itself registers nothing)::

    env = gymnasium.make("agentsim_env.gymnasium_envs:agentsim/navigation-v0", n_agents=1)

    import agentsim_env.gymnasium_envs
    gymnasium.register_envs(agentsim_env.gymnasium_envs)
    env = gymnasium.make("agentsim/navigation-v0", n_agents=1)

Each id builds a ``SingleAgentEnv`` (``agentsim_env.env.single_agent``): one agent of the scenario with flat
Box observations and actions.
"""

from agentsim_env.env.single_agent import register_gymnasium_envs

IDS: list[str] = register_gymnasium_envs()
"""The registered ids."""

__all__ = ["IDS"]

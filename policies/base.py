"""The Policy protocol shared by scripted behaviours, release strategies and trained policies."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class Policy(Protocol):
    """Maps a dict of observations (agent id -> observation) to a dict of actions.

    A policy may keep state across steps (e.g. a planned route); ``reset`` starts a new episode. The registry
    (``agentsim_env.policies.registry``) builds a policy with the class method ``for_env`` and then calls only
    ``reset`` and ``act``; a plug-in policy class (``agentsim_env.register_policy`` or an entry point, see
    ``docs/extending.md``) implements these three. A policy may also act on rows of arrays (``act_rows``, the
    ``ArrayPolicy`` protocol of ``agentsim_env.env.rollout``); without it, ``env.rollout`` goes through ``act``.
    """

    @classmethod
    def for_env(cls, env: Any, **options: Any) -> Policy:
        """The policy configured for ``env`` (an ``AgentSimParallelEnv`` or an object with its ``scenario``,
        ``possible_agents``, ``obs_format`` and ``action_format``).

        Args:
            env: The env the policy will drive; ``env.scenario.config`` holds the scenario's config.
            **options: The registry's options for this entry (e.g. a release policy's ``strategy``); a plug-in
                policy is built with none.

        Returns:
            A new policy.
        """
        ...

    def reset(self, seed: int | None = None) -> None:
        """Start a new episode (``seed`` drives any randomness the policy uses)."""
        ...

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        """Actions for every agent present in ``observations``."""
        ...

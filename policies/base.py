"""The Policy protocol shared by scripted behaviours, release strategies and trained policies."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class Policy(Protocol):
    """Maps a dict of observations (agent id -> observation) to a dict of actions.

    A policy may keep state across steps (e.g. a planned route); ``reset`` starts a new episode.
    """

    def reset(self, seed: int | None = None) -> None:
        """Start a new episode (``seed`` drives any randomness the policy uses)."""
        ...

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        """Actions for every agent present in ``observations``."""
        ...

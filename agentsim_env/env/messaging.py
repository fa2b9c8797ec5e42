"""The ParallelEnv's calls beside ``step``: messages sent from code and group changes (comms scenarios)."""

from __future__ import annotations

from typing import Any

import numpy as np

from agentsim_env.env.guard import CallGuard
from agentsim_env.scenarios.base import Scenario
from agentsim_env.sim.world import World


class MessageCalls:
    """``send_message`` and ``assign_group`` of a ParallelEnv (mixed into ``AgentSimParallelEnv``).

    The env provides ``world``, ``scenario``, ``_index`` (agent id -> slot) and ``_guard`` (one call at a time).
    """

    world: World
    scenario: Scenario
    _index: dict[str, int]
    _guard: CallGuard

    def _comms(self) -> Any:
        if self.world.comms is None:
            raise ValueError(f"scenario {self.scenario.name!r} has no communication: set its comms config")
        return self.world.comms

    def _live_slot(self, agent: str, what: str) -> int:
        if agent not in self._index:
            raise ValueError(f"{what}: unknown agent id {agent!r}")
        slot = self._index[agent]
        if not self.world.state.online[slot]:
            raise ValueError(f"{what}: agent {agent!r} is offline")
        return slot

    def send_message(self, sender: str, payload: Any, *, to: str | None = None, group: int | None = None) -> bool:
        """Send a bus message from code (besides the ``comm`` action): to one agent or to a group.

        Args:
            sender: Sending agent id (must be live).
            payload: ``D`` finite floats.
            to: Receiver agent id (unicast), or
            group: Group id (the sender's world), exactly one of the two.

        Returns:
            Whether the bus accepted it (False: over the sender's bandwidth this step).

        Raises:
            ValueError: Unknown or offline agent, unknown group, wrong payload width, NaN payload.
        """
        with self._guard.hold("send_message"):
            comms = self._comms()
            s, target, to_group, pay = self._message(sender, payload, to, group)
            if to_group:
                return bool(comms.to_group(s, target, pay, self.world.tick))
            return bool(comms.unicast(s, target, pay, self.world.tick))

    def _message(
        self, sender: str, payload: Any, to: str | None, group: int | None
    ) -> tuple[int, int, bool, np.ndarray]:
        """A checked code message: sender slot, target (receiver slot or group id), to a group, payload ``(D,)``.

        Raises:
            ValueError: As ``send_message`` says.
        """
        comms = self._comms()
        s = self._live_slot(sender, "sender")
        if (to is None) == (group is None):
            raise ValueError("give exactly one of to= (an agent id) or group= (a group id)")
        pay = np.asarray(payload, dtype=np.float64).reshape(1, -1)
        d = comms.cfg.payload_dim
        if pay.shape[1] != d:
            raise ValueError(f"payload must have {d} values (comms.payload_dim), got {pay.shape[1]}")
        if not np.isfinite(pay).all():
            raise ValueError(f"payload must be finite, got {pay.ravel().tolist()}")
        if group is None:
            return s, self._live_slot(str(to), "receiver"), False, pay[0]
        known = np.unique(self.world.state.group[self.world.state.group >= 0]).tolist()
        if group not in known:
            raise ValueError(f"group: unknown group {group!r}; groups are {known}")
        return s, int(group), True, pay[0]

    def assign_group(self, agent: str, group: int) -> None:
        """Move ``agent`` to ``group`` for the rest of the episode (-1: no group); the change is logged as an event.

        Group ids run from -1 to ``n_agents - 1`` (at most one group per agent); ``reset`` returns every agent to
        the group the scenario dealt it.
        """
        with self._guard.hold("assign_group"):
            self._comms()
            slot = self._live_slot(agent, "agent")
            n = self.scenario.n_agents
            if isinstance(group, bool) or not isinstance(group, (int, np.integer)) or not -1 <= group < n:
                raise ValueError(f"group must be an integer in -1..{n - 1} (-1 = no group), got {group!r}")
            assert self.world.groups is not None
            self.world.groups.assign(np.array([slot]), int(group), self.world.tick)

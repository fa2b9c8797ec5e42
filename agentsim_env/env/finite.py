"""The ``check_finite`` debug switch of the env front ends: fail fast on the first NaN or inf an agent would
receive, naming the part, the agent, the world and the step.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from agentsim_env.scenarios.base import Scenario, StepResult

CHECK_FINITE_ENV = "AGENTSIM_CHECK_FINITE"
"""Environment variable that switches ``check_finite`` on by default (``1``, ``true`` or ``yes``)."""


def check_finite_default(value: bool | None) -> bool:
    """``value`` when given (it must be a bool), else whether ``AGENTSIM_CHECK_FINITE`` switches the check on."""
    if value is None:
        return os.environ.get(CHECK_FINITE_ENV, "").strip().lower() in ("1", "true", "yes")
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"check_finite must be True, False or None, got {value!r}")
    return bool(value)


def assert_finite(
    scenario: Scenario[Any],
    rows: np.ndarray,
    step: int,
    obs: dict[str, np.ndarray],
    result: StepResult | None = None,
) -> None:
    """The ``check_finite`` debug switch: fail fast on the first NaN or inf an agent would receive.

    Args:
        scenario: The scenario (names the agents).
        rows: ``(S,)`` bool, the slots whose values are handed out (live agents).
        step: The step number, for the message.
        obs: Observation parts ``{part: (S, ...)}``.
        result: The step's rewards and infos (``None`` at reset).

    Raises:
        FloatingPointError: Naming the observation part, reward or info key, the agent, the world and the step.
    """
    named = [(f"observation part {k!r}", v) for k, v in obs.items()]
    if result is not None:
        named.append(("reward", result.rewards))
        named += [(f"info {k!r}", v) for k, v in result.info.items() if np.issubdtype(v.dtype, np.floating)]
    for what, arr in named:
        bad = ~np.isfinite(arr.reshape(arr.shape[0], -1)).all(axis=1) & rows
        if bad.any():
            s = int(np.flatnonzero(bad)[0])
            w, i = divmod(s, scenario.n_agents)
            row = np.asarray(arr[s]).ravel()
            values = row[~np.isfinite(row)][:3].tolist()
            raise FloatingPointError(
                f"{what} of agent '{scenario.agent_prefix}_{i}' (world {w}) is not finite at step {step}: "
                f"{values}, in {int(bad.sum())} agent(s) (check_finite is on; scenario {scenario.name!r})"
            )

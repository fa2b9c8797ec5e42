"""Inbox encoders: a stable-baselines3 features extractor that reads the inbox as a set of message rows.

A flat observation row is the scenario's parts in layout order (``agentsim_env.env.spaces.flat_layout``); with
comms it holds ``inbox``, ``M`` rows of ``F`` features (row layout in ``agentsim_env.comms.messages``: feature 0 is
the valid flag), then the ``comms`` counters. The plain MLP sees the M rows as M x F unrelated inputs, so a
message means something else in each row it can land in. ``InboxEncoder`` instead encodes every row with one
shared small MLP and pools the codes over the valid rows:

=============  ===========================================================================================
``mean``       mean of the valid rows' codes (zeros when the inbox is empty)
``max``        feature-wise maximum over the valid rows (zeros when empty)
``attention``  one head with a learned query: softmax over the valid rows of ``q . k_i / sqrt(H)``, the
               weighted sum of ``v_i`` (zeros when empty)
=============  ===========================================================================================

The pooled code (``hidden`` values) is concatenated to the observation without the inbox rows; the policy's
``net_arch`` layers follow. All three are invariant to the order of the inbox rows (the row's age feature still
tells newer from older). ``ppo.inbox_encoder`` selects one (``none``: the plain MLP, as before); the offsets come
from the scenario (:func:`inbox_layout`) and are saved with the model, so a saved model reloads as it was trained.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

__all__ = ["POOLS", "InboxEncoder", "InboxLayout", "inbox_layout"]

#: Pooling modes of ``InboxEncoder`` (``ppo.inbox_encoder`` also takes ``none``).
POOLS = ("mean", "max", "attention")


@dataclass(frozen=True, slots=True)
class InboxLayout:
    """Where the inbox sits in a flat observation row.

    Attributes:
        start: Column of the first inbox value.
        rows: Inbox rows (``comms.inbox_size``).
        features: Values per row (``11 + comms.payload_dim``).
        obs_size: Length of the whole flat observation.
    """

    start: int
    rows: int
    features: int
    obs_size: int


def inbox_layout(scenario: str, env: dict[str, Any]) -> InboxLayout:
    """The inbox's place in the flat observation of ``scenario`` built with config keys ``env``.

    Raises:
        ValueError: The scenario has no inbox (no ``comms`` in its config).
    """
    from agentsim_env.env.spaces import flat_layout
    from agentsim_env.scenarios.registry import make_scenario

    parts = make_scenario(scenario, **dict(env)).obs_parts()
    if "inbox" not in parts:
        raise ValueError(f"scenario {scenario!r} has no inbox with this env config (set env.comms to give it one)")
    rows, features = parts["inbox"].shape
    return InboxLayout(flat_layout(parts)["inbox"].start, rows, features, sum(p.size for p in parts.values()))


class InboxEncoder(BaseFeaturesExtractor):
    """Encode the inbox rows with one shared MLP, pool them, concatenate with the rest of the observation.

    Args:
        observation_space: The flat Box the policy sees.
        inbox_start: Column of the first inbox value (:func:`inbox_layout`).
        inbox_rows: Inbox rows M.
        row_features: Values per row F (feature 0 is the valid flag).
        pool: ``mean``, ``max`` or ``attention``.
        hidden: Width of the row code, 1..1024.
    """

    def __init__(
        self,
        observation_space: spaces.Box,
        inbox_start: int,
        inbox_rows: int,
        row_features: int,
        pool: str = "mean",
        hidden: int = 32,
    ) -> None:
        size = int(observation_space.shape[0])
        end = inbox_start + inbox_rows * row_features
        if pool not in POOLS:
            raise ValueError(f"pool must be one of {list(POOLS)}, got {pool!r}")
        if inbox_start < 0 or inbox_rows < 1 or row_features < 1 or end > size:
            raise ValueError(
                f"the inbox ({inbox_rows} rows x {row_features} from column {inbox_start}) does not fit an "
                f"observation of {size} values"
            )
        super().__init__(observation_space, features_dim=size - (end - inbox_start) + hidden)
        self.start, self.end, self.rows, self.row_features = inbox_start, end, inbox_rows, row_features
        self.pool = pool
        self.row_mlp = nn.Sequential(nn.Linear(row_features, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh())
        if pool == "attention":
            self.query = nn.Parameter(torch.zeros(hidden))  # starts as the mean over valid rows
            self.key = nn.Linear(hidden, hidden)
            self.value = nn.Linear(hidden, hidden)

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        """``(batch, obs_size)`` -> ``(batch, features_dim)``."""
        rows = observations[:, self.start : self.end].reshape(-1, self.rows, self.row_features)
        rest = torch.cat([observations[:, : self.start], observations[:, self.end :]], dim=1)
        valid = rows[..., 0] > 0.5  # an empty row is all zeros, a message has valid = 1
        return torch.cat([rest, self.pooled(self.row_mlp(rows), valid)], dim=1)

    def pooled(self, codes: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        """Pool ``codes`` ``(batch, M, H)`` over the rows where ``valid`` ``(batch, M)``; zeros where none is."""
        mask = valid.unsqueeze(-1).to(codes.dtype)
        if self.pool == "mean":
            return (codes * mask).sum(dim=1) / mask.sum(dim=1).clamp(min=1.0)
        if self.pool == "max":
            best = codes.masked_fill(~valid.unsqueeze(-1), -math.inf).amax(dim=1)
            return torch.where(valid.any(dim=1, keepdim=True), best, torch.zeros_like(best))
        scores = (self.key(codes) @ self.query) / math.sqrt(codes.shape[-1])
        # -1e9, not -inf: a row of only empty messages would give NaN; its weights are zeroed by the mask below
        weights = torch.softmax(scores.masked_fill(~valid, -1e9), dim=1).unsqueeze(-1) * mask
        return (weights * self.value(codes)).sum(dim=1)

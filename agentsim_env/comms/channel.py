"""The bus's channel model (``ChannelConfig``) and the declared types of its fields, shared by the comms config.

What each field does to a message is in ``comms.bus``'s rules; this module only declares the settings.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from agentsim_env.core.config_model import Int, Real, config

__all__ = ["Bandwidth", "ChannelConfig", "Latency", "Probability", "Range"]

Latency = Annotated[Int, Field(ge=0)]
"""Steps between send and delivery, >= 0."""
Probability = Annotated[Real, Field(ge=0.0, le=1.0)]
"""A probability, in [0, 1]."""
Bandwidth = Annotated[Int, Field(ge=0)]
"""Messages per agent and step, >= 0 (0: unlimited)."""
Range = Annotated[Real, Field(gt=0.0)]
"""A distance in metres, > 0."""


@config("comms")
class ChannelConfig:
    """Channel model of a bus.

    Attributes:
        latency: Steps between send and delivery (>= 0; 0 = delivered in the step it was sent).
        loss: Probability that a (message, receiver) pair is lost, in [0, 1] (1 = dead channel).
        bandwidth: Messages an agent may send per step (>= 0; 0 = unlimited).
        max_range: Largest sender-receiver distance in metres (> 0), or None for no limit.
    """

    latency: Latency = 0
    loss: Probability = 0.0
    bandwidth: Bandwidth = 0
    max_range: Range | None = None

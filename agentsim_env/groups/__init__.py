"""Groups: ids, run-time reassignment, group broadcast, heartbeats and timeouts."""

from agentsim_env.groups.controller import GroupController, GroupEvents, GroupStepEvents

__all__ = ["GroupController", "GroupEvents", "GroupStepEvents"]

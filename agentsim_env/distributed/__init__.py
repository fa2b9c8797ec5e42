"""One simulation over several processes or machines: spatial shards on Ray (the only Ray importer).

``make(name, shards=K, ray_address=None, **config)`` returns the scenario's PettingZoo ``ParallelEnv`` with its
steps run over K shards (``DistributedBatchedEnv`` is the array front end); ``env.rollout(policy, steps)`` runs
the policy inside the shards. The map is cut into strips; each shard runs the whole step pipeline for the agents
of its strips, with the ghosts of its halo, and meets the others at a few exchanges routed by the coordinator
(hand-overs and ghosts, bus messages across shards, per-group sums), so results do not depend on the split.
See docs/distributed.md.
"""

from agentsim_env.distributed.coordinator import Coordinator, ShardInfo
from agentsim_env.distributed.env import DistributedBatchedEnv, DistributedParallelEnv, check_shardable, make
from agentsim_env.distributed.partition import Strips, halo_width

__all__ = [
    "Coordinator",
    "DistributedBatchedEnv",
    "DistributedParallelEnv",
    "ShardInfo",
    "Strips",
    "check_shardable",
    "halo_width",
    "make",
]

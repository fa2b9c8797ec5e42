"""Wrapper bases: one for the ParallelEnv, one for the batched env, each forwarding the env's API explicitly.

A wrapper derives from :class:`ParallelEnvWrapper` or :class:`BatchedEnvWrapper` and overrides only what it adds
(the recorder's hooks, the video capture, an evaluation's tally of an episode: ``EpisodeMetrics``); every other
public method and attribute of the wrapped env is a written method or property of the base, so nothing is forwarded
by ``__getattr__`` or by copying the env's ``__dict__``. Wrappers nest, and ``unwrapped`` is always the innermost
env.

The package sits below ``render`` (whose ``RecordVideo`` derives from the ParallelEnv base) and above ``scenarios``:
it never imports the env package, so the wrapped env is typed by what the bases read of it.
"""

from agentsim_env.wrappers.batched import BatchedEnvWrapper
from agentsim_env.wrappers.metrics import EpisodeMetrics
from agentsim_env.wrappers.parallel import ParallelEnvWrapper

__all__ = ["BatchedEnvWrapper", "EpisodeMetrics", "ParallelEnvWrapper"]

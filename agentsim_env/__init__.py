"""agentsim-env: a vectorised multi-agent simulator exposed as a PettingZoo ParallelEnv."""

__version__ = "0.1.0"

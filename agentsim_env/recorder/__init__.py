"""The embedded data store: runs, agent states, messages, events and sensors recorded to SQLite.

``record(env, "run.db")`` records a ParallelEnv, a BatchedEnv or a World (the recorder is the world's stage-10
step hook); ``agentsim_env.recorder.read`` reads a store back as pandas DataFrames and exports it to CSV or
Parquet. The schema is in ``agentsim_env.recorder.schema`` and ``docs/store.md``.
"""

from agentsim_env.recorder.schema import SCHEMA_VERSION, StoreError, connect
from agentsim_env.recorder.wrappers import RecordedBatchedEnv, RecordedParallelEnv, record
from agentsim_env.recorder.writer import Recorder

__all__ = [
    "SCHEMA_VERSION",
    "RecordedBatchedEnv",
    "RecordedParallelEnv",
    "Recorder",
    "StoreError",
    "connect",
    "record",
]

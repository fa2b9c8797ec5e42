"""Deprecated: this package moved to ``agentsim_env.uav.evaluation``.

The old path works for one release: importing it warns and re-exports the new package's public names.

Its submodules are shims too (``agentsim_env.evaluation.NAME`` -> ``agentsim_env.uav.evaluation.NAME``).
"""

import warnings

from agentsim_env.uav.evaluation import *  # noqa: F403

warnings.warn(
    "agentsim_env.evaluation is deprecated: import agentsim_env.uav.evaluation instead "
    "(this path is removed in the next release)",
    DeprecationWarning,
    stacklevel=2,
)

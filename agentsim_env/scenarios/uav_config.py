"""Deprecated: this module moved to ``agentsim_env.uav.config``.

The old path works for one release: importing it warns and re-exports the new module's public names.
"""

import warnings

from agentsim_env.uav.config import *  # noqa: F403

warnings.warn(
    "agentsim_env.scenarios.uav_config is deprecated: import agentsim_env.uav.config instead "
    "(this path is removed in the next release)",
    DeprecationWarning,
    stacklevel=2,
)

"""Deprecated: this package moved to ``agentsim_env.uav.wsn``.

The old path works for one release: importing it warns and re-exports the new package's public names.

Its submodules are shims too (``agentsim_env.wsn.NAME`` -> ``agentsim_env.uav.wsn.NAME``).
"""

import warnings

from agentsim_env.uav.wsn import *  # noqa: F403

warnings.warn(
    "agentsim_env.wsn is deprecated: import agentsim_env.uav.wsn instead (this path is removed in the next release)",
    DeprecationWarning,
    stacklevel=2,
)

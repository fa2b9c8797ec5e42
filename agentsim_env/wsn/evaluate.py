"""Deprecated: this module moved to ``agentsim_env.uav.wsn.evaluate``.

The old path works for one release: importing it warns and re-exports the new module's public names.
"""

import warnings

from agentsim_env.uav.wsn.evaluate import *  # noqa: F403

warnings.warn(
    "agentsim_env.wsn.evaluate is deprecated: import agentsim_env.uav.wsn.evaluate instead "
    "(this path is removed in the next release)",
    DeprecationWarning,
    stacklevel=2,
)

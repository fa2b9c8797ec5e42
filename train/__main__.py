"""``python -m agentsim_env.train``: the same command as ``agentsim train``."""

from agentsim_env.train.cli import main

raise SystemExit(main())

"""Where a page's server listens: the ``--host`` / ``--port`` / ``--open`` options of the commands that serve one
(``agentsim view``, ``agentsim zones design``), their checks, and the warning for an address other machines reach.

Only the standard library: registering the options imports no web dependency.
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["LOCAL_HOSTS", "check_network", "network_options", "warn_host"]

#: Addresses reachable from this machine only (no warning).
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


def network_options(p: argparse.ArgumentParser) -> None:
    """Add ``--host``, ``--port`` and ``--open`` to a command's parser.

    Args:
        p: The command's parser.
    """
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to bind; anything but 127.0.0.1 is reachable from other machines (a warning is printed)",
    )
    p.add_argument("--port", type=int, default=0, help="port (0: a free one)")
    p.add_argument("--open", action="store_true", help="open the page in the default browser")


def check_network(args: argparse.Namespace) -> None:
    """Check ``--host`` and ``--port`` before a server starts.

    Args:
        args: Parsed arguments holding ``host`` and ``port``.

    Raises:
        ValueError: If ``port`` is not in 0..65535 or ``host`` is empty.
    """
    if not isinstance(args.port, int) or not 0 <= args.port <= 65535:
        raise ValueError(f"--port must be an integer in 0..65535 (0: a free port), got {args.port}")
    if not args.host:
        raise ValueError("--host must be an address such as 127.0.0.1 (this machine only) or 0.0.0.0")


def warn_host(host: str, what: str = "watch and control the simulation") -> None:
    """Warn on stderr when ``host`` is reachable from other machines (the pages have no authentication).

    Args:
        host: The bound address.
        what: What a visitor could do, for the warning.
    """
    if host not in LOCAL_HOSTS:
        print(
            f"agentsim: WARNING: serving on {host}: any machine that reaches it can {what} (there is no "
            "authentication)",
            file=sys.stderr,
        )

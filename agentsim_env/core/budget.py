"""Memory budget: sizes are checked against the machine before anything is allocated.

A config that asks for more memory than the machine can give fails at construction with an error naming the
fields, the estimate and the limit, instead of a ``MemoryError`` (or the kernel's OOM killer) in the middle of
allocating. The limit is ``AGENTSIM_MEMORY_LIMIT_GB`` when set, otherwise 80 % of the memory available now
(``MemAvailable`` on Linux, the physical memory elsewhere).
"""

from __future__ import annotations

import os

MEMORY_ENV = "AGENTSIM_MEMORY_LIMIT_GB"
"""Environment variable overriding the memory limit, in GiB (e.g. ``"4"`` or ``"0.5"``)."""

_GIB = 1 << 30


def format_bytes(n: float) -> str:
    """``n`` bytes in a readable unit (``"1.5 GiB"``)."""
    for unit in ("B", "KiB", "MiB", "GiB"):
        if abs(n) < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"  # pragma: no cover - unreachable


def _available_bytes() -> int:
    """Memory available to a new allocation now (Linux ``MemAvailable``), else the physical memory."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):  # pragma: no cover - platforms without sysconf
        return 8 * _GIB


def memory_limit() -> tuple[int, str]:
    """The memory limit in bytes and where it comes from (for error messages).

    Raises:
        ValueError: When ``AGENTSIM_MEMORY_LIMIT_GB`` is set but not a positive number.
    """
    raw = os.environ.get(MEMORY_ENV)
    if raw:
        try:
            gb = float(raw)
        except ValueError:
            gb = float("nan")
        if not gb > 0 or gb == float("inf"):
            raise ValueError(f"{MEMORY_ENV} must be a positive number of GiB, got {raw!r}")
        return int(gb * _GIB), f"{MEMORY_ENV}={raw}"
    avail = _available_bytes()
    return int(0.8 * avail), f"80 % of the {format_bytes(avail)} available; set {MEMORY_ENV} to change it"


def check_memory(what: str, estimate: int, hint: str) -> None:
    """Raise unless ``estimate`` bytes fit in the memory limit.

    Args:
        what: What needs the memory, naming the fields (``"navigation with n_agents=10000000 x n_worlds=1"``).
        estimate: Estimated bytes.
        hint: What to change (``"lower n_agents or n_worlds"``).

    Raises:
        ValueError: Naming ``what``, the estimate, the limit and ``hint``.
    """
    limit, source = memory_limit()
    if estimate > limit:
        raise ValueError(
            f"{what} needs about {format_bytes(estimate)} of memory, over the limit of {format_bytes(limit)} "
            f"({source}); {hint}"
        )


__all__ = ["MEMORY_ENV", "check_memory", "format_bytes", "memory_limit"]

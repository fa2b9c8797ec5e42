"""Whether a UAV fleet can carry the sensors a zone set asks for, in numbers and in one line of text.

A zone file does not know the fleet, so its capacity is checked where the zones are made and where they meet
a fleet: ``agentsim zones check FILE [--set ...]`` and the designer page report it for the scenario's default
fleet (``default_fleet``) or the ``--set`` values, and ``UavReleaseConfig`` refuses zones its fleet cannot
carry (``uav_zones.validate_against_payload``). The advice names the ``uav_release`` config keys a user can
change: ``n_uavs`` (alias of ``n_agents``) and ``payload`` (sensors per UAV).
"""

from __future__ import annotations

from typing import Any

from agentsim_env.uav.zones import ZoneSet

__all__ = ["MAX_N_UAVS", "MAX_PAYLOAD", "capacity_text", "default_fleet", "fleet_capacity"]

#: Upper bounds of ``n_uavs`` and ``payload`` in ``UavReleaseConfig`` (a suggestion beyond them is left out).
MAX_N_UAVS = 1024
MAX_PAYLOAD = 100_000


def default_fleet() -> tuple[int, int]:
    """The ``uav_release`` default fleet: ``(n_uavs, payload)`` from ``UavReleaseConfig``'s field defaults."""
    from agentsim_env.uav.config import UavReleaseConfig

    f = UavReleaseConfig.__dataclass_fields__
    n_uavs, payload = f["n_agents"].default, f["payload"].default
    assert isinstance(n_uavs, int) and isinstance(payload, int)  # plain int defaults, no factories
    return n_uavs, payload


def _ceil_div(a: int, b: int) -> int:
    return -(-a // b)


def fleet_capacity(zs: ZoneSet, n_uavs: int, payload: int) -> dict[str, Any]:
    """How the sensors the zones need compare with what ``n_uavs`` UAVs carrying ``payload`` each hold.

    Args:
        zs: The zone set.
        n_uavs: UAVs in the fleet (>= 1).
        payload: Sensors each UAV carries (>= 1).

    Returns:
        ``{"n_uavs", "payload", "capacity", "needed", "carried", "spare", "n_uavs_needed", "payload_needed"}``:
        ``spare`` is ``capacity - needed`` (negative when short); ``n_uavs_needed`` and ``payload_needed`` are
        the smallest fleet at this payload and the smallest payload for this fleet that carry the zones.
    """
    n, p, need = int(n_uavs), int(payload), int(zs.n_sensors)
    cap = n * p
    return {
        "n_uavs": n,
        "payload": p,
        "capacity": cap,
        "needed": need,
        "carried": need <= cap,
        "spare": cap - need,
        "n_uavs_needed": _ceil_div(need, max(p, 1)),
        "payload_needed": _ceil_div(need, max(n, 1)),
    }


def capacity_text(cap: dict[str, Any], fleet: str = "fleet") -> str:
    """One line for a ``fleet_capacity`` result, e.g. ``default fleet: 4 UAVs x 40 sensors = 160; the zones
    need 150: carried (10 spare)``; when short, how many sensors are left behind and what to ``--set``.

    Args:
        cap: ``fleet_capacity``'s result.
        fleet: How the fleet is named at the start of the line.
    """
    n, p = cap["n_uavs"], cap["payload"]
    head = f"{fleet}: {n} UAV{'' if n == 1 else 's'} x {p} sensors = {cap['capacity']}; the zones need {cap['needed']}"
    if cap["carried"]:
        return f"{head}: carried ({cap['spare']} spare)"
    fixes = [
        f"--set {k}={cap[k + '_needed']}"
        for k, top in (("n_uavs", MAX_N_UAVS), ("payload", MAX_PAYLOAD))
        if cap[k + "_needed"] <= top
    ]
    advice = f" ({' or '.join(fixes)})" if fixes else ""
    return f"{head}: cannot carry {-cap['spare']} of them; raise n_uavs or payload{advice}, or lower n_sensors"

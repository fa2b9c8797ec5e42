"""Hot-zone designer: the handlers behind ``static/designer.html`` and ``run_designer`` (``agentsim zones design``).

The page draws zones on a top-down map, edits them in a form and asks the server for previews; the server
validates with the zone file's own validator (``uav_zones.zones_from_dict``), so every message the page shows is
the one ``load_zones`` would give. Messages (JSON objects, ``cmd`` names the request):

* ``{"cmd": "zones.preview", "zones": {zone file}, "id": n}`` -> ``{"type": "zones.preview", "ok": true, "zones":
  [...], "overlaps": [[i, j], ...], "fleet": {...}, "id": n}`` (``fleet``: whether the default fleet carries the
  sensors, see ``preview``), or ``{"ok": false, "error": message, "id": n}`` when the zone file
  is invalid (``id`` optional, echoed). Computed on a worker thread, one at a time per page; a request that waits
  meanwhile is replaced by a newer one (no reply), so the newest is always answered.
* ``{"cmd": "zones.save", "zones": {zone file}}`` -> ``{"type": "zones.saved", "path", "n_zones"}``; writes only the
  file the designer was started with, never a path named by the page: atomically, through a symbolic link to the
  file it names, keeping an existing file's mode and owner (a new file follows the umask), and refusing (with
  the reason, for the page) a file the process may not write or that is not a regular file.
* ``{"cmd": "zones.load"}`` -> ``{"type": "zones.loaded", "zones": {zone file}, "path"}``.

Malformed messages raise ``ClientError`` (sent to the page as ``{"type": "error", "message": ...}``).
"""

from __future__ import annotations

import threading
import webbrowser
from pathlib import Path
from typing import Any

import numpy as np

from agentsim_env.core.files import write_atomically
from agentsim_env.render.web.server import Background, ClientError, Handler, WebServer
from agentsim_env.uav import zones as uav_zones
from agentsim_env.uav.capacity import capacity_text, default_fleet, fleet_capacity
from agentsim_env.uav.wsn.profiles import PROFILE_KINDS
from agentsim_env.uav.zones import (
    DENSITY_SAMPLES,
    ZoneSet,
    load_zones,
    zones_from_dict,
    zones_to_dict,
    zones_to_json,
)

__all__ = [
    "DENSITY_SAMPLES",
    "MAX_POINTS_PER_ZONE",
    "MAX_POINTS_TOTAL",
    "STATIC_DIR",
    "designer_handlers",
    "designer_hello",
    "preview",
    "run_designer",
]

#: Most layout points of each kind (B1, B8) sent per zone, and over all zones together.
MAX_POINTS_PER_ZONE = 2000
MAX_POINTS_TOTAL = 40_000

#: The designer page's own files (``designer.html``, its script and style sheet), served by its ``WebServer``.
STATIC_DIR = Path(__file__).resolve().parent / "static"

_KEYS = {"zones.preview": ("cmd", "zones", "id"), "zones.save": ("cmd", "zones"), "zones.load": ("cmd",)}


def _check_message(msg: Any, cmd: str) -> dict[str, Any]:
    """Validate a message's shape: an object with exactly the keys ``cmd`` takes and, where taken, a zone file."""
    if not isinstance(msg, dict):
        raise ClientError(f"{cmd}: a message must be a JSON object, got {type(msg).__name__}")
    if "path" in msg:
        raise ClientError(
            f"{cmd}: the page cannot choose the file ('path' is not accepted); the designer writes only "
            "the file it was started with"
        )
    unknown = sorted(str(k) for k in msg if k not in _KEYS[cmd])
    if unknown:
        raise ClientError(f"{cmd}: unknown key(s) {unknown}; allowed keys: {list(_KEYS[cmd])}")
    if "zones" in _KEYS[cmd]:
        if "zones" not in msg:
            raise ClientError(f"{cmd}: missing 'zones' (the zone file object)")
        if not isinstance(msg["zones"], dict):
            raise ClientError(f"{cmd}: 'zones' must be a zone file object, got {type(msg['zones']).__name__}")
    return msg


def _validate(d: dict[str, Any]) -> ZoneSet:
    """``zones_from_dict`` whose every failure is a ``ValueError`` (the validator's own message when it is one)."""
    try:
        return zones_from_dict(d)
    except ValueError:
        raise
    except Exception as exc:  # a malformed object must never escape as a server crash
        raise ValueError(f"invalid zone file: {type(exc).__name__}: {exc}") from exc


def _point_count(n_sensors: int, n_zones: int) -> int:
    """Points of each kind shown for a zone: all of them up to the per-zone and total caps."""
    return min(n_sensors, MAX_POINTS_PER_ZONE, max(1, MAX_POINTS_TOTAL // max(n_zones, 1)))


def _rounded(points: np.ndarray) -> list[list[float]]:
    """Points as JSON lists, to the millimetre."""
    return np.round(points, 3).tolist()


def preview(zs: ZoneSet) -> dict[str, Any]:
    """The preview of a zone set: density curves, expected layouts and overlapping pairs.

    For each zone: ``density`` is the areal density at ``DENSITY_SAMPLES`` radii evenly spaced over
    ``0 .. radius``, scaled to a maximum of 1 (a power law's infinite centre takes the value half a step out);
    ``b1`` are random points (B1, inverse-CDF sampling, ``np.random.default_rng(0)`` per zone, so a preview is
    stable) and ``b8`` the sunflower set (B8, ``RadialProfile.low_discrepancy(n_sensors)``), both in absolute
    map metres. When a zone has more than ``shown`` sensors, ``b1`` holds ``shown`` draws and ``b8`` every
    ``n_sensors / shown``-th sunflower point (so the picture keeps its extent).

    Args:
        zs: A validated zone set.

    Returns:
        ``{"type": "zones.preview", "ok": True, "zones": [...], "overlaps": [[i, j], ...], "fleet": {...}}``;
        ``fleet`` is ``uav_capacity.fleet_capacity`` for the default ``uav_release`` fleet plus its ``text``
        (the line ``agentsim zones check`` prints), so the page shows whether the fleet carries the zones.
    """
    out = []
    for z in zs.zones:
        prof = z.radial_profile()
        dens = z.density_curve(DENSITY_SAMPLES)
        n, shown = z.n_sensors, _point_count(z.n_sensors, len(zs.zones))
        centre = np.asarray(z.centre, dtype=np.float64)
        b1 = prof.sample(shown, np.random.default_rng(0)) + centre
        idx = np.unique(np.round(np.linspace(0, n - 1, shown)).astype(np.int64))  # all n when shown == n
        b8 = prof.low_discrepancy(n, idx) + centre
        out.append(
            {
                "density": np.round(dens, 6).tolist(),
                "b1": _rounded(b1),
                "b8": _rounded(b8),
                "shown": int(len(idx)),
                "n_sensors": n,
            }
        )
    pairs = [[i, j] for i, j in uav_zones.overlaps(zs)]
    cap = fleet_capacity(zs, *default_fleet())
    fleet = {**cap, "text": capacity_text(cap, "default fleet")}
    return {"type": "zones.preview", "ok": True, "zones": out, "overlaps": pairs, "fleet": fleet}


def _write_atomically(zs: ZoneSet, path: Path) -> None:
    """Replace ``path`` (or the file its link names) with ``zs``; see ``core.files.write_atomically``."""
    write_atomically(path, zones_to_json(zs).encode("utf-8"))


def designer_handlers(path: Path | None) -> dict[str, Handler]:
    """The designer's message handlers for ``WebServer(handlers=...)``.

    Args:
        path: The zone file the designer reads and writes, or ``None`` (saving is then refused).

    Returns:
        ``{"zones.preview": fn, "zones.save": fn, "zones.load": fn}``; the preview is a ``Background`` handler
        (tenths of a second at the largest zone files): the server runs it on a worker thread, one at a time per
        page, the newest waiting request next, so other pages are answered meanwhile.
    """
    target = None if path is None else Path(path)
    lock = threading.Lock()

    def on_preview(msg: dict[str, Any]) -> dict[str, Any]:
        """Validate the page's zone file and return its preview, or the validator's message (with its ``id``)."""
        d = _check_message(msg, "zones.preview")["zones"]
        rid = msg.get("id")
        if "id" in msg and (isinstance(rid, bool) or not isinstance(rid, int)):
            raise ClientError(f"zones.preview: 'id' must be an integer (echoed in the reply), got {type(rid).__name__}")
        echo = {} if rid is None else {"id": rid}  # the page tells from it which request a reply answers
        try:
            zs = _validate(d)
        except ValueError as exc:
            return {"type": "zones.preview", "ok": False, "error": str(exc), **echo}
        return {**preview(zs), **echo}

    def on_save(msg: dict[str, Any]) -> dict[str, Any]:
        """Validate and write the zone file to ``path`` (only there)."""
        d = _check_message(msg, "zones.save")["zones"]
        if target is None:
            raise ClientError(
                "started without a file: nothing is written; use Download, or start `agentsim zones design FILE`"
            )
        try:
            zs = _validate(d)
        except ValueError as exc:
            raise ClientError(str(exc)) from exc
        with lock:
            try:
                _write_atomically(zs, target)
            except OSError as exc:
                raise ClientError(f"cannot write {target}: {exc.strerror or exc}") from exc
        return {"type": "zones.saved", "path": str(target), "n_zones": len(zs.zones)}

    def on_load(msg: dict[str, Any]) -> dict[str, Any]:
        """Re-read ``path`` and return its zones."""
        _check_message(msg, "zones.load")
        if target is None:
            raise ClientError("started without a file: there is nothing to load; start `agentsim zones design FILE`")
        if not target.exists():
            raise ClientError(f"{target} does not exist yet: Save creates it")
        try:
            with lock:
                zs = load_zones(target)
        except (ValueError, OSError) as exc:
            raise ClientError(str(exc)) from exc
        return {"type": "zones.loaded", "zones": zones_to_dict(zs), "path": str(target)}

    return {"zones.preview": Background(on_preview), "zones.save": on_save, "zones.load": on_load}


def _limits() -> dict[str, Any]:
    """Field limits for the page's form (the validator's, restated; the validator has the last word)."""
    return {
        "radius": [0.5, uav_zones.MAX_MAP_SIDE],
        "n_sensors": [1, uav_zones.MAX_SENSORS_PER_ZONE],
        "alpha": [0.0, 2.0],
        "sigma_over_radius": [1e-3, 1e3],
        "floor": [0.0, 1.0],
        "weight": [1e-3, 1e3],
        "altitude": [0.0, uav_zones.MAX_ALTITUDE],
        "map_side": [0.0, uav_zones.MAX_MAP_SIDE],
        "max_zones": uav_zones.MAX_ZONES,
    }


def designer_hello(path: Path | None) -> list[dict[str, Any]]:
    """The messages sent to each page when it connects.

    The first is ``{"type": "zones.hello", "zones": {zone file}, "path", "source", "can_save",
    "profile_kinds", "limits", "defaults", "fleet"}`` (``fleet``: the default ``uav_release`` fleet's
    ``n_uavs``, ``payload`` and ``capacity``): the zones come from ``path`` when it exists and is valid
    (``source`` "file"), else from the package's default file (``source`` "default"). When ``path`` exists but
    is invalid, a second message ``{"type": "error", "message": ...}`` gives the loader's message.

    Args:
        path: The designer's zone file, or ``None``.

    Returns:
        The messages, in order.
    """
    target = None if path is None else Path(path)
    messages: list[dict[str, Any]] = []
    zs, source = None, "default"
    if target is not None and target.exists():
        try:
            zs, source = load_zones(target), "file"
        except (ValueError, OSError) as exc:
            messages.append({"type": "error", "message": f"{exc} (showing the default zones instead)"})
    if zs is None:
        zs = load_zones(uav_zones.default_zones_path())
    n_uavs, payload = default_fleet()
    hello = {
        "type": "zones.hello",
        "zones": zones_to_dict(zs),
        "path": None if target is None else str(target),
        "source": source,
        "can_save": target is not None,
        "profile_kinds": list(PROFILE_KINDS),
        "limits": _limits(),
        "defaults": {"n_sensors": 50, "profile": "gauss", "alpha": 1.0, "floor": 0.0, "weight": 1.0},
        "fleet": {"n_uavs": n_uavs, "payload": payload, "capacity": n_uavs * payload},
    }
    return [hello, *messages]


def _wait_forever() -> None:
    """Block the calling thread until it is interrupted (Ctrl-C raises ``KeyboardInterrupt`` here)."""
    threading.Event().wait()


def run_designer(path: str | None, host: str = "127.0.0.1", port: int = 0, open_browser: bool = False) -> None:
    """Serve the designer until Ctrl-C.

    Args:
        path: The zone file to edit (read when it exists, written by Save), or ``None`` (Download only).
        host: Interface to listen on.
        port: TCP port (0: any free port).
        open_browser: Open the page in the default browser.

    Raises:
        ValueError: If ``path`` exists but is not a valid zone file, or is a folder.
    """
    target = None if path is None else Path(path)
    if target is not None:
        if target.is_dir():
            raise ValueError(f"{target}: is a folder, not a zone file")
        if target.exists():
            load_zones(target)  # refuse to start on a file the designer would overwrite unseen
        elif not target.parent.is_dir():
            raise ValueError(f"{target}: the folder {target.parent} does not exist")
    srv = WebServer(
        page="designer.html",
        host=host,
        port=port,
        title="Hot-zone designer",
        handlers=designer_handlers(target),
        on_connect=lambda: designer_hello(target),
        static_dir=STATIC_DIR,
    )
    url = srv.start()
    try:
        print(f"hot-zone designer at {url}")
        if target is None:
            print("no file given: Save is off (use Download); `agentsim zones design FILE` edits FILE")
        else:
            print(f"Save writes {target.resolve()}" + ("" if target.exists() else " (a new file)"))
        print("press Ctrl-C to stop")
        if open_browser:
            webbrowser.open(url)
        _wait_forever()
    except KeyboardInterrupt:
        print("\nstopped")
    finally:
        srv.stop()

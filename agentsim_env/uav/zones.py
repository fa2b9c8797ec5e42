"""Circular hot zones for the UAV sensor-release case study, and the zone designer's JSON format.

A zone is a disc over which sensors are released with a radial density profile (denser toward the centre);
a zone set is the zones of one map plus the UAV base. Coordinates are metres in the map frame: origin at the
map's south-west corner, x east, y north; the map spans ``[0, width] x [0, height]``.

JSON format (one object; UTF-8; see docs/zones.md for a complete example)::

    {
      "version": 1,                      optional; must be 1 when present
      "description": "free text",        optional; ignored by the loader and not kept
      "map_size": [width, height],       required; two numbers in (0, 100000] (m)
      "base": [x, y],                    optional; UAV take-off point inside the map, or null
      "zones": [ {zone}, ... ]           required; 1 to 1,000 zones
    }

Each ``{zone}`` object:

============ ======== ======== ======================================================================
field        type     default  meaning
============ ======== ======== ======================================================================
centre       [x, y]   required centroid (m); the whole disc must lie inside the map
radius       number   required disc radius (m), 0.5..100000
n_sensors    integer  required sensors allotted to the zone, 1..100,000
profile      string   "gauss"  one of ``PROFILE_KINDS``: "uniform", "power", "gauss", "linear"
alpha        number   1.0      power-law exponent, 0 <= alpha < 2 (``power`` only; 1 is R-random)
sigma        number   null     Gaussian width (m), radius / 1000 .. 1000 x radius; null: radius / 2 (gauss)
floor        number   0.0      uniform share of the mass, 0 <= floor < 1 (keeps the rim connected)
weight       number   1.0      priority used to allocate UAVs across zones, 0.001..1000
altitude     number   null     release altitude (m AGL), 0 < altitude <= 120; null: scenario default
name         string   null     label used in messages, logs and plots
============ ======== ======== ======================================================================

A file is a regular file (not a device or FIFO) of at most 16 MiB of UTF-8 JSON, with no key given twice in
one object and at most ``MAX_JSON_DEPTH`` levels of nesting. Text (``name``, ``description``) must be printable:
control characters, bidirectional overrides and unpaired surrogates are refused. Unknown fields, missing required
fields, wrong types (a boolean is not a number; an integer is accepted for
a number) and out-of-range values raise ``ValueError`` naming the zone (``zones[i]`` and its name) and the
field.
Overlapping zones are allowed (see ``overlaps``); the payload check is separate (``validate_against_payload``)
because the fleet is part of the scenario config, not of the zone file.
"""

from __future__ import annotations

import difflib
import json
import os
from dataclasses import fields
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field

from agentsim_env.core.config_model import Choice, FieldError, Int, Real, Text, config, in_range
from agentsim_env.core.files import json_depth, parse_json, read_regular
from agentsim_env.core.validation import check_float, check_int, check_text, short_repr
from agentsim_env.uav.wsn.profiles import RadialProfile

__all__ = [
    "DENSITY_SAMPLES",
    "FORMAT_VERSION",
    "MAX_ALTITUDE",
    "MAX_FILE_BYTES",
    "MAX_JSON_DEPTH",
    "MAX_MAP_SIDE",
    "MAX_SENSORS_PER_ZONE",
    "MAX_ZONES",
    "Zone",
    "ZoneFieldError",
    "ZoneSet",
    "default_zones_path",
    "load_zones",
    "overlaps",
    "save_zones",
    "tiny_zones_path",
    "validate_against_payload",
    "zones_from_dict",
    "zones_to_dict",
    "zones_to_json",
]

FORMAT_VERSION = 1
#: Altitude cap (m above ground) of the usual small-UAS rules (EU Open category, US Part 107).
MAX_ALTITUDE = 120.0

#: Most zones in one set, sensors in one zone, and map side (m); a zone file is at most ``MAX_FILE_BYTES``.
MAX_ZONES = 1000
MAX_SENSORS_PER_ZONE = 100_000
MAX_MAP_SIDE = 1e5
MAX_FILE_BYTES = 16 << 20
#: Most levels of JSON objects and lists in a zone file (the format itself uses 4: file, zones, zone, centre).
MAX_JSON_DEPTH = 16

_REQUIRED = ("centre", "radius", "n_sensors")
_TOP_FIELDS = ("version", "description", "map_size", "base", "zones")


#: A side of the map (m).
Side = Annotated[Real, Field(gt=0.0, le=MAX_MAP_SIDE)]

#: Radii at which a zone's density curve is sampled for the viewer and the designer.
DENSITY_SAMPLES = 64


def _pair(label: str, value: Any) -> tuple[float, float]:
    """Validate a 2-vector of finite numbers (a JSON list or a tuple)."""
    if not isinstance(value, (list, tuple, np.ndarray)) or len(value) != 2:
        raise ValueError(f"{label} must be a list of two numbers [x, y], got {short_repr(value)}")
    for v in value:
        check_float(label, v)
    return float(value[0]), float(value[1])


def _zone_label(index: int | None, name: Any) -> str:
    """``zones[3] 'north'``-style label used in every zone error."""
    head = "zone" if index is None else f"zones[{index}]"
    return head if name is None else f"{head} {short_repr(name, 60)}"


_Z = TypeVar("_Z")


class ZoneFieldError(ValueError):
    """A bad field of one zone: ``<label>: field '<name>' <problem>`` (``field`` and ``problem`` kept).

    Not a ``FieldError``: a config holding a zone file reports it whole (``zones: zones[0] 'a': ...``).
    """

    def __init__(self, label: str, field: str, problem: str) -> None:
        name, bracket, rest = field.partition("[")
        item = f" (item {rest.rstrip(']')})" if bracket else ""
        super().__init__(f"{label}: field {name!r}{item} {problem}")
        self.label, self.field, self.problem = label, field, problem


def _labelled(cls: type[_Z]) -> type[_Z]:
    """Zone errors name the zone (``zone 'north'``) and the field in the zone file's words."""
    init = cls.__init__
    at = [f.name for f in fields(cls)].index("name")  # type: ignore[arg-type]

    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
        try:
            init(self, *args, **kwargs)
        except FieldError as exc:
            name = args[at] if len(args) > at else kwargs.get("name")
            raise ZoneFieldError(_zone_label(None, name), exc.field, exc.problem) from None

    __init__.__doc__ = init.__doc__
    cls.__init__ = __init__  # type: ignore[method-assign]
    return cls


#: Radial density kinds a zone takes (``PROFILE_KINDS``).
Profile = Annotated[Literal["uniform", "power", "gauss", "linear"], Choice]


@_labelled
@config()
class Zone:
    """One circular hot zone (bounds as in the module docstring's table; errors name the zone and the field).

    Attributes:
        centre: Centroid ``(x, y)`` in map metres.
        radius: Disc radius in metres, ``[0.5, 100000]``.
        n_sensors: Sensors allotted to the zone, ``[1, 100000]``.
        profile: Radial density kind, one of ``PROFILE_KINDS``.
        alpha: Power-law exponent in ``[0, 2)`` (``"power"`` only).
        sigma: Gaussian width in metres, ``radius / 1000 .. 1000 x radius``, or ``None`` for ``radius / 2``
            (``"gauss"`` only).
        floor: Uniform share of the mass in ``[0, 1)``.
        weight: Allocation priority, ``[0.001, 1000]``.
        altitude: Release altitude in m AGL, ``(0, 120]``, or ``None`` for the scenario default.
        name: Optional label (printable text).
    """

    centre: tuple[Real, Real]
    radius: Annotated[Real, Field(ge=0.5, le=MAX_MAP_SIDE)]
    n_sensors: Annotated[Int, Field(ge=1, le=MAX_SENSORS_PER_ZONE)]
    profile: Profile = "gauss"
    alpha: Annotated[Real, Field(ge=0.0, lt=2.0)] = 1.0
    sigma: Real | None = None
    floor: Annotated[Real, Field(ge=0.0, lt=1.0)] = 0.0
    weight: Annotated[Real, Field(ge=1e-3, le=1e3)] = 1.0
    altitude: Annotated[Real, Field(gt=0.0, le=MAX_ALTITUDE)] | None = None
    name: Text | None = None

    def __post_init__(self) -> None:
        """The Gaussian width against the radius (a narrower or wider one is a point or a uniform disc)."""
        if self.sigma is not None:
            in_range("sigma", self.sigma, self.radius / 1000.0, 1000.0 * self.radius)

    def radial_profile(self) -> RadialProfile:
        """The zone's normalised radial density (``RadialProfile``) over its disc."""
        return RadialProfile(self.profile, self.radius, alpha=self.alpha, sigma=self.sigma, floor=self.floor)

    def density_curve(self, samples: int = DENSITY_SAMPLES) -> np.ndarray:
        """The areal density at ``samples`` radii from the centre to the rim, scaled to a maximum of 1.

        What the viewer and the designer draw. A power law is infinite at the centre: the first sample takes the
        value half a step out.
        """
        prof = self.radial_profile()
        r = np.linspace(0.0, self.radius, samples)
        d = np.asarray(prof.density(r), dtype=np.float64)
        if not np.isfinite(d[0]):
            d[0] = float(prof.density(0.5 * r[1]))
        top = float(d.max())
        return d / top if top > 0.0 and np.isfinite(top) else np.ones_like(d)


@config()
class ZoneSet:
    """The hot zones of one map, the map extent and the UAV base.

    Attributes:
        zones: The zones (1 to ``MAX_ZONES``); a zone's id is its index here.
        map_size: ``(width, height)`` in metres, each in ``(0, 100000]``; the map spans
            ``[0, width] x [0, height]``.
        base: UAV take-off point ``(x, y)`` inside the map, or ``None``.
    """

    zones: Annotated[tuple[Zone, ...], Field(min_length=1, max_length=MAX_ZONES)]
    map_size: tuple[Side, Side]
    base: tuple[Real, Real] | None = None

    def __post_init__(self) -> None:
        """Check that every zone lies fully inside the map, and the base too."""
        width, height = self.map_size
        for i, z in enumerate(self.zones):
            _check_inside(_zone_label(i, z.name), z, width, height)
        if self.base is not None:
            bx, by = self.base
            if not (0.0 <= bx <= width and 0.0 <= by <= height):
                raise ValueError(f"base ({bx}, {by}) must lie inside the map [0, {width}] x [0, {height}]")

    @property
    def n_sensors(self) -> int:
        """Total sensors over all zones."""
        return sum(z.n_sensors for z in self.zones)

    def centres(self) -> NDArray[np.float64]:
        """Zone centroids ``(K, 2)``."""
        return np.array([z.centre for z in self.zones], dtype=np.float64)

    def radii(self) -> NDArray[np.float64]:
        """Zone radii ``(K,)``."""
        return np.array([z.radius for z in self.zones], dtype=np.float64)

    def weights(self) -> NDArray[np.float64]:
        """Zone weights ``(K,)``."""
        return np.array([z.weight for z in self.zones], dtype=np.float64)

    def zone_index(self, xy: ArrayLike) -> NDArray[np.int64]:
        """Zone containing each point, or -1 outside every zone.

        Where zones overlap, the zone in whose disc the point is relatively deepest (smallest
        ``distance / radius``) wins, ties going to the lower index.

        Args:
            xy: Points ``(n, 2)`` in map metres.

        Returns:
            Zone indices ``(n,)``.
        """
        pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        rel = np.linalg.norm(pts[:, None, :] - self.centres()[None, :, :], axis=2) / self.radii()[None, :]
        best = np.argmin(rel, axis=1)
        inside = rel[np.arange(pts.shape[0]), best] <= 1.0
        return np.where(inside, best, -1).astype(np.int64)


def _check_inside(label: str, z: Zone, width: float, height: float) -> None:
    """Raise unless the zone's disc lies inside the map, saying on which side and by how much."""
    cx, cy = z.centre
    excess = {
        "left edge (x = 0)": z.radius - cx,
        f"right edge (x = {width:g})": cx + z.radius - width,
        "bottom edge (y = 0)": z.radius - cy,
        f"top edge (y = {height:g})": cy + z.radius - height,
    }
    bad = [f"{d:.3g} m beyond the {side}" for side, d in excess.items() if d > 1e-9]
    if bad:
        raise ValueError(
            f"{label}: field 'centre'/'radius': the disc (centre ({cx:g}, {cy:g}), radius {z.radius:g}) "
            f"is not fully inside the {width:g} x {height:g} m map: it extends {', '.join(bad)}"
        )


def _check_keys(label: str, d: dict[str, Any], allowed: tuple[str, ...], required: tuple[str, ...]) -> None:
    """Raise on unknown or missing keys, suggesting the closest allowed spelling (a misspelt required field,
    such as ``center``, is named as unknown with its correct spelling rather than reported missing)."""
    for key in d:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), allowed, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ValueError(f"{label}: unknown field {short_repr(key, 60)}{hint}; allowed fields: {list(allowed)}")
    missing = [k for k in required if k not in d]
    if missing:
        raise ValueError(f"{label}: missing required field(s) {missing}; required: {list(required)}")


def zones_from_dict(d: dict[str, Any]) -> ZoneSet:
    """Build and validate a ``ZoneSet`` from the JSON object described in the module docstring.

    Args:
        d: The decoded JSON object.

    Returns:
        The validated zone set.

    Raises:
        ValueError: On any structural or value error; the message names the zone (index and name) and
            the field.
    """
    if not isinstance(d, dict):
        raise ValueError(f"the zone file must hold a JSON object, got {type(d).__name__}")
    if json_depth(d, MAX_JSON_DEPTH) > MAX_JSON_DEPTH:
        raise ValueError(
            f"the zone file is nested more than {MAX_JSON_DEPTH} levels deep; at most {MAX_JSON_DEPTH} are allowed"
        )
    _check_keys("zone file", d, _TOP_FIELDS, ("map_size", "zones"))
    if "description" in d:  # not kept, but checked like every other text of the file
        check_text("field 'description'", d["description"], allow_newlines=True)
    if "version" in d and (isinstance(d["version"], bool) or d["version"] != FORMAT_VERSION):
        raise ValueError(f"field 'version' must be {FORMAT_VERSION}, got {short_repr(d['version'])}")
    raw = d["zones"]
    if not isinstance(raw, list) or not raw:
        raise ValueError(f"field 'zones' must be a non-empty list of zone objects, got {short_repr(raw)}")
    if len(raw) > MAX_ZONES:
        raise ValueError(f"field 'zones' holds {len(raw):,} zones; at most {MAX_ZONES:,} are allowed")
    zone_fields = tuple(fl.name for fl in fields(Zone))
    zones = []
    for i, zd in enumerate(raw):
        if not isinstance(zd, dict):
            raise ValueError(f"zones[{i}] must be a JSON object, got {short_repr(zd)}")
        label = _zone_label(i, zd.get("name"))
        _check_keys(label, zd, zone_fields, _REQUIRED)
        try:
            zones.append(Zone(**zd))
        except ZoneFieldError as exc:  # named again with the index (the zone's own message has its name only)
            raise ZoneFieldError(label, exc.field, exc.problem) from None
    base = d.get("base")
    return ZoneSet(
        zones=tuple(zones),
        map_size=_pair("field 'map_size'", d["map_size"]),
        base=None if base is None else _pair("field 'base'", base),
    )


def zones_to_dict(zs: ZoneSet) -> dict[str, Any]:
    """Encode a zone set as the JSON object read by ``zones_from_dict`` (``None`` fields are left out).

    Args:
        zs: The zone set.

    Returns:
        A JSON-serialisable dict; ``zones_from_dict(zones_to_dict(zs)) == zs``.
    """
    zones = []
    for z in zs.zones:
        entry: dict[str, Any] = {}
        for fl in fields(Zone):
            value = getattr(z, fl.name)
            if value is not None:
                entry[fl.name] = list(value) if fl.name == "centre" else value
        zones.append(entry)
    out: dict[str, Any] = {"version": FORMAT_VERSION, "map_size": list(zs.map_size)}
    if zs.base is not None:
        out["base"] = list(zs.base)
    out["zones"] = zones
    return out


def load_zones(path: str | os.PathLike[str]) -> ZoneSet:
    """Read and validate a zone file.

    Args:
        path: Path of the JSON file.

    Returns:
        The validated zone set.

    Raises:
        ValueError: On a folder, device, FIFO or socket (only a regular file is read, and at most
            ``MAX_FILE_BYTES + 1`` bytes of it), a file over ``MAX_FILE_BYTES``, non-UTF-8 text, malformed JSON,
            a key given twice in one object, nesting past ``MAX_JSON_DEPTH`` or invalid content; the message
            starts with the path.
        OSError: When the file cannot be opened or read.
    """
    if not str(path):
        raise ValueError("zones: the zone file path is empty")
    raw = read_regular(path, MAX_FILE_BYTES, "a zone file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(
            f"{path}: not UTF-8 text (byte {exc.object[exc.start]:#04x} at position {exc.start}); "
            "zone files are UTF-8 JSON: re-save the file as UTF-8"
        ) from None
    try:
        data = parse_json(text, MAX_JSON_DEPTH)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON: {exc}") from exc
    except ValueError as exc:  # a duplicate key, or nesting past MAX_JSON_DEPTH
        raise ValueError(f"{path}: {exc}") from None
    try:
        return zones_from_dict(data)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from exc


def zones_to_json(zs: ZoneSet) -> str:
    """A zone set as the indented JSON text that ``save_zones`` writes and ``load_zones`` reads.

    Args:
        zs: The zone set.

    Returns:
        The text, ending with a newline.
    """
    return json.dumps(zones_to_dict(zs), indent=2) + "\n"


def save_zones(zs: ZoneSet, path: str | os.PathLike[str]) -> None:
    """Write a zone set as indented JSON (the format read by ``load_zones``).

    Args:
        zs: The zone set.
        path: Destination file (overwritten).
    """
    Path(path).write_text(zones_to_json(zs), encoding="utf-8")


def validate_against_payload(zs: ZoneSet, n_uavs: int, payload_per_uav: int) -> None:
    """Raise when the fleet cannot carry every sensor the zones ask for.

    Args:
        zs: The zone set.
        n_uavs: Number of UAVs (>= 1).
        payload_per_uav: Sensors each UAV carries (>= 0).

    Raises:
        ValueError: If ``zs.n_sensors > n_uavs * payload_per_uav`` (the message gives the numbers and names the
            ``uav_release`` config keys to raise: ``n_uavs`` and ``payload``).
    """
    check_int("n_uavs", n_uavs, 1)
    check_int("payload_per_uav", payload_per_uav, 0)
    capacity = n_uavs * payload_per_uav
    if zs.n_sensors > capacity:
        per_zone = ", ".join(f"{_zone_label(i, z.name)}: {z.n_sensors}" for i, z in enumerate(zs.zones))
        # the advice names the scenario's config keys (what a user can --set), not this function's arguments
        fleet = -(-zs.n_sensors // payload_per_uav) if payload_per_uav > 0 else None
        more = f" (--set n_uavs={fleet})" if fleet is not None else ""
        raise ValueError(
            f"the zones need {zs.n_sensors} sensors ({per_zone}) but {n_uavs} UAV(s) x {payload_per_uav} "
            f"sensors carry only {capacity}; raise n_uavs or payload (sensors per UAV){more}, or lower the "
            "zones' n_sensors"
        )


def overlaps(zs: ZoneSet) -> list[tuple[int, int]]:
    """Pairs of zones whose discs overlap (touching discs do not count).

    Args:
        zs: The zone set.

    Returns:
        Index pairs ``(i, j)`` with ``i < j``, sorted.
    """
    c, r = zs.centres(), zs.radii()
    dist = np.linalg.norm(c[:, None, :] - c[None, :, :], axis=2)
    hit = dist < (r[:, None] + r[None, :]) * (1.0 - 1e-12)
    i, j = np.nonzero(np.triu(hit, k=1))
    return [(int(a), int(b)) for a, b in zip(i, j, strict=True)]


def _data_path(name: str) -> Path:
    """Filesystem path of a packaged data file."""
    return Path(str(resources.files("agentsim_env.uav").joinpath("data", name)))


def default_zones_path() -> Path:
    """Path of the packaged default zone file (3 zones, 150 sensors, 600 x 400 m map)."""
    return _data_path("zones_default.json")


def tiny_zones_path() -> Path:
    """Path of the packaged tiny zone file (1 zone, 20 sensors) for fast tests."""
    return _data_path("zones_tiny.json")

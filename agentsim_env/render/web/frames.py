"""What the viewer sends: the scene message, packed binary state frames and log lines (docs/viewer.md).

Everything here reads a ``World`` (one world ``w`` of it) and returns plain data; nothing here knows about
sockets. A frame is ``b"ASF1"``, a uint32 header length, a JSON header naming each array's dtype, shape and
offset, then the arrays, each 8-byte aligned, so the page makes typed-array views without copying.
"""

from __future__ import annotations

import json
import struct
from typing import Any

import numpy as np

from agentsim_env.comms.messages import AGENT, ENV, GROUP, HEARTBEAT, KIND_NAMES, OVERLAY
from agentsim_env.sim.world import StepEvents, World

MAGIC = b"ASF1"
_DTYPES = {np.dtype("<f4"): "f4", np.dtype("<i4"): "i4", np.dtype("<i2"): "i2", np.dtype("u1"): "u1"}
#: Page-side message kind codes (``msg_kind``) by bus kind: agent 0, group 1, environment 2, overlay 3.
MSG_KIND = {AGENT: 0, GROUP: 1, ENV: 2, OVERLAY: 3}
_PAGE_KIND = np.zeros(max(KIND_NAMES) + 1, np.uint8)  # any other kind (heartbeats) draws as an agent message
for _k, _v in MSG_KIND.items():
    _PAGE_KIND[_k] = _v
LOG_KINDS = (
    "collision",
    "timeout",
    "group",
    "release",
    "landing",
    "terminated",
    "episode",
    "message",
    "broadcast",
    "heartbeat",
    "overlay",
)
#: Log kinds the page hides until its filter box is ticked: periodic traffic that would flood the log (the
#: controller's heartbeats, GROUP broadcasts such as the UAVs' HELLO heartbeats every few steps, and the overlay's
#: per-step hop summary, one line every step while a flood spreads).
LOG_HIDDEN = ("broadcast", "heartbeat", "overlay")
#: The log kind of a delivered bus message, by bus kind (AGENT and ENV unicasts are "message").
_MESSAGE_LOG_KIND = {GROUP: "broadcast", HEARTBEAT: "heartbeat"}
#: Why an agent is drawn as it is (the frame's ``status`` array): still acting, reached its goal, ended by a
#: collision, taken offline (missed heartbeats), or ended otherwise (a scout done, a battery empty...).
STATUS_NAMES = ("active", "arrived", "collided", "offline", "ended")
ACTIVE, ARRIVED, COLLIDED, OFFLINE, ENDED = range(len(STATUS_NAMES))
MAX_MESSAGE_LINES = 40  # message log lines per step (the rest are counted in one line)
MAX_DRAWN_MESSAGES = 4000  # message segments per frame


def pack_frame(seq: int, step: int, episode: int, arrays: dict[str, np.ndarray]) -> bytes:
    """Pack named arrays into one binary frame (see the module docstring).

    Args:
        seq: Frame sequence number (increasing; the page acknowledges it).
        step: Simulation step shown.
        episode: Episode number.
        arrays: Arrays of dtype float32, int32, int16 or uint8 (converted to little-endian, C order).

    Returns:
        The frame's bytes.
    """
    parts: list[np.ndarray] = []
    meta: dict[str, Any] = {}
    offset = 0
    for name, a in arrays.items():
        a = np.ascontiguousarray(a)
        code = _DTYPES.get(a.dtype.newbyteorder("<") if a.dtype.byteorder == ">" else a.dtype)
        if code is None:
            raise TypeError(f"array {name!r}: dtype {a.dtype} is not one of float32, int32, int16, uint8")
        a = a.astype(a.dtype.newbyteorder("<"), copy=False)
        meta[name] = {"dtype": code, "shape": list(a.shape), "offset": offset}
        parts.append(a)
        offset += (a.nbytes + 7) // 8 * 8
    # offsets count from the frame's start, so they depend on the header's length: settle it (lengths only
    # grow with the offsets' digits, so two or three passes suffice)
    head_len, header = 8, b""
    for _ in range(4):
        shifted = {k: {**m, "offset": m["offset"] + head_len} for k, m in meta.items()}
        header = json.dumps(
            {"seq": seq, "step": step, "episode": episode, "arrays": shifted}, separators=(",", ":")
        ).encode()
        need = 8 + (len(header) + 7) // 8 * 8
        if need == head_len:
            break
        head_len = need
    meta = shifted
    out = bytearray(head_len + offset)
    out[0:4] = MAGIC
    out[4:8] = struct.pack("<I", len(header))
    out[8 : 8 + len(header)] = header
    for a, m in zip(parts, meta.values()):
        out[m["offset"] : m["offset"] + a.nbytes] = a.tobytes()
    return bytes(out)


def unpack_frame(frame: bytes) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The header and arrays of a packed frame (the page's parser, in Python: tests and tools)."""
    if frame[:4] != MAGIC:
        raise ValueError(f"not a viewer frame (magic {frame[:4]!r})")
    (n,) = struct.unpack("<I", frame[4:8])
    header = json.loads(frame[8 : 8 + n])
    out = {}
    for name, m in header["arrays"].items():
        dt = np.dtype({"f4": "<f4", "i4": "<i4", "i2": "<i2", "u1": "u1"}[m["dtype"]])
        count = int(np.prod(m["shape"])) if m["shape"] else 1
        out[name] = np.frombuffer(frame, dtype=dt, count=count, offset=m["offset"]).reshape(m["shape"])
    return header, out


def _zones(markers: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The ``zones`` list of the scene message (its older form): the scenario's zone markers."""
    return [
        {
            "name": m.get("name", m.get("label", "")),
            "centre": list(m["pos"][:2]),
            "radius": m["radius"],
            "n_sensors": m.get("n_sensors", 0),
            "density": m.get("density", []),
        }
        for m in markers
        if m.get("kind") == "zone"
    ]


def new_status(n: int) -> np.ndarray:
    """A fresh ``status`` array for ``n`` agents (all ``ACTIVE``): the start of an episode."""
    return np.zeros(n, np.uint8)


def track_status(status: np.ndarray, world: World, w: int, events: StepEvents) -> None:
    """Record in ``status`` why agents of world ``w`` stopped this step (kept until the next episode).

    A collision (stage 5) is ``COLLIDED``, a heartbeat timeout ``OFFLINE``; a termination the scenario scored is
    ``ARRIVED`` when its ``arrived`` info says so, else ``ENDED``. The first reason an agent gets is kept.
    """
    n = status.shape[0]
    lo = w * n

    def mark(slots: np.ndarray, code: int) -> None:
        s = np.asarray(slots, dtype=np.int64) - lo
        s = s[(s >= 0) & (s < n)]
        s = s[status[s] == ACTIVE]
        status[s] = code

    mark(events.went_offline, COLLIDED)
    mark(events.timed_out, OFFLINE)
    sc = events.scores
    if sc is not None:
        term = sc.terminated[lo : lo + n] & sc.acting[lo : lo + n]
        arrived = sc.info.get("arrived")
        hit = term & (np.asarray(arrived[lo : lo + n]) > 0) if arrived is not None else np.zeros(n, bool)
        mark(np.flatnonzero(hit) + lo, ARRIVED)
        mark(np.flatnonzero(term & ~hit) + lo, ENDED)
    gone = ~world.state.online[lo : lo + n].astype(bool) & (status == ACTIVE)
    status[gone] = OFFLINE  # offline by any other road (a shard lost)


def scene_message(
    world: World,
    scenario: Any,
    w: int = 0,
    *,
    title: str = "",
    mode: str = "live",
    replay: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The ``scene`` message: bounds, static objects, agents' names and sizes, zones (docs/viewer.md)."""
    sc = world.scene
    mine = np.flatnonzero(sc.world == w)
    st = world.state
    slots = st.slots_of_world(w)
    names = scenario.agent_names()
    markers = scenario.view_markers(world, w)
    return {
        "type": "scene",
        "mode": mode,
        "title": title or scenario.name,
        "scenario": scenario.name,
        "dt": float(world.config.dt),
        "bounds": [float(b) for b in world.config.bounds],
        "z_range": [float(z) for z in world.config.z_range],
        "n_agents": int(len(slots)),
        "agent_names": list(names),
        "agent_radius": np.round(st.radius[slots].astype(float), 3).tolist(),
        "n_groups": int(scenario.n_groups),
        "objects": {
            "kind": sc.kind[mine].astype(int).tolist(),
            "centre": np.round(sc.centre[mine], 3).tolist(),
            "half": np.round(sc.half[mine], 3).tolist(),
        },
        "zones": _zones(markers),
        "markers": markers,
        "log_kinds": list(LOG_KINDS),
        "log_hidden": list(LOG_HIDDEN),
        "status_names": list(STATUS_NAMES),
        "replay": replay,
    }


def page_kinds(kinds: np.ndarray) -> np.ndarray:
    """The page's ``msg_kind`` codes of bus kind codes (``comms.messages``)."""
    return _PAGE_KIND[np.clip(np.asarray(kinds, dtype=np.int64), 0, len(_PAGE_KIND) - 1)]


def _messages(events: StepEvents, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
    """This step's deliveries inside world slots ``[lo, hi)``: (M, 2) sender/receiver (world-local) and kinds."""
    c = events.comms
    pairs, kinds = [], []
    if c is not None and c.bus is not None and len(c.bus.delivered):
        d = c.bus.delivered
        keep = (d.receiver >= lo) & (d.receiver < hi)
        send = np.where(d.sender[keep] >= 0, d.sender[keep] - lo, -1)
        pairs.append(np.column_stack([send, d.receiver[keep] - lo]))
        kinds.append(page_kinds(d.kind[keep]))
    if c is not None and c.overlay is not None and len(c.overlay.receiver):
        o = c.overlay
        keep = (o.receiver >= lo) & (o.receiver < hi)
        pairs.append(np.column_stack([o.origin[keep] - lo, o.receiver[keep] - lo]))
        kinds.append(np.full(int(keep.sum()), MSG_KIND[OVERLAY], np.uint8))
    if not pairs:
        return np.zeros((0, 2), np.int32), np.zeros(0, np.uint8)
    p, k = np.vstack(pairs).astype(np.int32), np.concatenate(kinds)
    return p[:MAX_DRAWN_MESSAGES], k[:MAX_DRAWN_MESSAGES]


def _rays(world: World, slot: int) -> tuple[np.ndarray, np.ndarray] | None:
    """End points and hit flags of the proximity rays of ``slot`` (None without a proximity sensor)."""
    sensor = next((s for s in world.sensors if s.name == "proximity"), None)
    scan = world.readings.get("proximity")
    if sensor is None or scan is None:
        return None
    st = world.state
    dirs = np.asarray(getattr(sensor, "directions"), dtype=np.float64)  # noqa: B009 - the proximity sensor's; body yaw frame
    c, s = np.cos(st.heading[slot]), np.sin(st.heading[slot])
    world_dirs = np.column_stack([c * dirs[:, 0] - s * dirs[:, 1], s * dirs[:, 0] + c * dirs[:, 1], dirs[:, 2]])
    dist = np.asarray(scan.distance[slot], dtype=np.float64) * float(st.sensor_range[slot])
    ends = st.pos[slot][None, :] + world_dirs * dist[:, None]
    return ends.astype(np.float32), (np.asarray(scan.hit_kind[slot]) != 0).astype(np.uint8)


def state_arrays(
    world: World, w: int, events: StepEvents | None, selected: int | None, status: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """The frame's arrays for world ``w`` (positions, headings, groups, online, status, messages, payloads, rays).

    ``status``: why each agent is (not) active (``STATUS_NAMES``, kept by ``track_status``); without it, an
    offline agent is ``OFFLINE``.
    """
    st = world.state
    n = st.n_agents
    lo, hi = w * n, (w + 1) * n
    out: dict[str, np.ndarray] = {
        "pos": st.pos[lo:hi].astype(np.float32),
        "heading": st.heading[lo:hi].astype(np.float32),
        "group": st.group[lo:hi].astype(np.int16),
        "online": st.online[lo:hi].astype(np.uint8),
        "status": (
            status.astype(np.uint8)
            if status is not None
            else np.where(st.online[lo:hi], ACTIVE, OFFLINE).astype(np.uint8)
        ),
    }
    if events is not None:
        out["msg"], out["msg_kind"] = _messages(events, lo, hi)
    ps = world.payloads.objects if world.payloads is not None else None
    if ps is not None:
        mine = np.asarray(ps.get("world")) == w
        falling, landed = mine & np.asarray(ps.get("falling")), mine & np.asarray(ps.get("landed"))
        land = np.asarray(ps.get("land_xy"))[landed]
        pos = np.vstack([np.asarray(ps.get("pos"))[falling], np.column_stack([land, np.zeros(len(land))])])
        out["payload_pos"] = pos.astype(np.float32)
        out["payload_state"] = np.concatenate(
            [np.full(int(falling.sum()), 1, np.uint8), np.full(len(land), 2, np.uint8)]
        )
    if selected is not None and 0 <= selected < n:
        rays = _rays(world, lo + selected)
        if rays is not None:
            out["rays"], out["ray_hit"] = rays
    return out


def message_log_kind(kind: int) -> str:
    """The log kind of a delivered message of bus kind ``kind``: ``broadcast`` (GROUP), ``heartbeat`` or
    ``message``."""
    return _MESSAGE_LOG_KIND.get(int(kind), "message")


def _line(step: int, episode: int, kind: str, text: str, slots: list[int]) -> dict[str, Any]:
    return {"step": step, "episode": episode, "kind": kind, "text": text, "slots": slots}


def log_lines(
    world: World, scenario: Any, events: StepEvents, w: int, episode: int, names: list[str] | None = None
) -> list[dict[str, Any]]:
    """The log stream's lines for one step of world ``w``: collisions, timeouts, group changes, releases,
    landings, terminations and (up to ``MAX_MESSAGE_LINES``) messages. ``names``: the agents' ids (default:
    the scenario's; pass them to save building the list every step)."""
    n = world.state.n_agents
    lo, hi = w * n, (w + 1) * n
    step = int(world.step_count[w])
    names = names if names is not None else scenario.agent_names()
    out: list[dict[str, Any]] = []

    def name(slot: int) -> str:
        return names[slot - lo] if lo <= slot < hi else "env"

    col = events.collisions
    for a, b, o in zip(col.agent.tolist(), col.other_agent.tolist(), col.obj.tolist()):
        if lo <= a < hi:
            what = f"agent {name(b)}" if b >= 0 else f"object #{o}"
            out.append(_line(step, episode, "collision", f"{name(a)} collided with {what}", [a - lo]))
    for s in events.timed_out.tolist():
        if lo <= s < hi:
            out.append(_line(step, episode, "timeout", f"{name(s)} missed its heartbeats: offline", [s - lo]))
    g = events.groups
    if g is not None:
        for s, old, new in zip(g.slot.tolist(), g.old.tolist(), g.new.tolist()):
            if lo <= s < hi:
                out.append(_line(step, episode, "group", f"{name(s)}: group {old} -> {new}", [s - lo]))
    p = events.payloads
    if p is not None and world.payloads is not None:
        ps = world.payloads.objects
        for kind, ids in (("release", p.released), ("landing", p.landed)):
            if len(ids):
                rows = ps.index_of(np.asarray(ids))
                mine = np.asarray(ps.get("world"))[rows] == w
                if mine.any():
                    k = int(mine.sum())
                    text = f"{k} sensor{'s' if k > 1 else ''} {'released' if kind == 'release' else 'landed'}"
                    out.append(_line(step, episode, kind, text, []))
    sc = events.scores
    if sc is not None:
        term = np.flatnonzero(sc.terminated[lo:hi] & sc.acting[lo:hi])
        if term.size:
            shown = ", ".join(names[i] for i in term[:8]) + (f" (+{term.size - 8})" if term.size > 8 else "")
            out.append(_line(step, episode, "terminated", f"terminated: {shown}", term[:64].tolist()))
    c = events.comms
    if c is not None and c.bus is not None and len(c.bus.delivered):
        d = c.bus.delivered
        keep = np.flatnonzero((d.receiver >= lo) & (d.receiver < hi))
        for j in keep[:MAX_MESSAGE_LINES].tolist():
            kind = KIND_NAMES.get(int(d.kind[j]), str(int(d.kind[j])))
            out.append(
                _line(
                    step,
                    episode,
                    message_log_kind(int(d.kind[j])),
                    f"{kind} {name(int(d.sender[j]))} -> {name(int(d.receiver[j]))}",
                    [int(d.receiver[j]) - lo],
                )
            )
        if keep.size > MAX_MESSAGE_LINES:
            out.append(
                _line(
                    step,
                    episode,
                    "message",
                    f"... and {keep.size - MAX_MESSAGE_LINES} more bus deliveries this step",
                    [],
                )
            )
    if c is not None and c.overlay is not None and len(c.overlay.receiver):
        o = c.overlay
        k = int(((o.receiver >= lo) & (o.receiver < hi)).sum())
        if k:
            out.append(_line(step, episode, "overlay", f"OVERLAY: {k} hop deliveries", []))
    return out


def agent_message(world: World, scenario: Any, w: int, slot: int) -> dict[str, Any]:
    """The ``agent`` message: one agent's state and its inbox (newest first)."""
    st = world.state
    n = st.n_agents
    s = w * n + slot
    state = {
        "pos": np.round(st.pos[s].astype(float), 3).tolist(),
        "vel": np.round(st.vel[s].astype(float), 3).tolist(),
        "heading_deg": round(float(np.degrees(st.heading[s])), 1),
        "group": int(st.group[s]),
        "role": int(st.role[s]),
        "energy": round(float(st.energy[s]), 3),
        "online": bool(st.online[s]),
    }
    inbox: list[dict[str, Any]] = []
    comms = world.comms
    if comms is not None:
        box = comms.bus.inbox
        rows = np.flatnonzero(box.valid[s])
        rows = rows[np.argsort(-box.created[s, rows], kind="stable")]
        tick = world.tick
        names = scenario.agent_names()
        for r in rows.tolist():
            snd = int(box.sender[s, r])
            inbox.append(
                {
                    "kind": KIND_NAMES.get(int(box.kind[s, r]), str(int(box.kind[s, r]))),
                    "sender": names[snd - w * n] if w * n <= snd < (w + 1) * n else "env",
                    "age": int(tick - box.created[s, r]),
                    "hops": int(box.hops[s, r]),
                    "payload": np.round(box.payload[s, r].astype(float), 3).tolist(),
                }
            )
    return {
        "type": "agent",
        "slot": int(slot),
        "name": scenario.agent_names()[slot],
        "state": state,
        "inbox": inbox,
    }


__all__ = [
    "LOG_HIDDEN",
    "LOG_KINDS",
    "MAGIC",
    "STATUS_NAMES",
    "message_log_kind",
    "new_status",
    "track_status",
    "page_kinds",
    "agent_message",
    "log_lines",
    "pack_frame",
    "scene_message",
    "state_arrays",
    "unpack_frame",
]

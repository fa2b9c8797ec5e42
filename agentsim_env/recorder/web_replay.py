"""Replay a recorded episode from the store in the 3D web viewer (``agentsim view --replay RUN.db``).

The episode's rows are read once into arrays over (step, agent); the page plays them with play / pause / step /
speed and a time slider (``seek``). Frames are the live viewer's packed frames (``render.web.frames``), built from
the store: positions, headings, groups, online flags, the step's delivered messages and the released sensors
(falling between their release and landing, then landed). The log stream replays the recorded events.

The static scene is not in the store: it is rebuilt from the run's config and the episode's seed (the scenario
places its objects from the seed), so obstacles and zones show as they were. An episode recorded without a seed
that follows one with a seed is rebuilt by resetting as many times as the recording did; with no seed at all the
objects cannot be known and the log says so.
"""

from __future__ import annotations

import os
import sys
import threading
from typing import Any

import numpy as np

from agentsim_env.comms.messages import AGENT, KIND_NAMES
from agentsim_env.core.budget import check_memory
from agentsim_env.recorder.checks import check_values, open_read
from agentsim_env.recorder.replay import ReplayInfo, replay_info
from agentsim_env.recorder.replay_scene import recorded_seeds
from agentsim_env.recorder.schema import info_columns
from agentsim_env.render.web.frames import (
    ARRIVED,
    COLLIDED,
    ENDED,
    MAX_MESSAGE_LINES,
    OFFLINE,
    message_log_kind,
    pack_frame,
    page_kinds,
    scene_message,
)
from agentsim_env.render.web.server import ClientError, WebServer
from agentsim_env.render.web.viewer import Controls, clamp_speed


class ReplayData:
    """One recorded episode as arrays (every recorded step, every agent of the world).

    Attributes:
        info: What the store says about the episode.
        steps: ``(T,)`` recorded step numbers, ascending.
        pos, heading, group, online: ``(T, N, 3)``, ``(T, N)``, ``(T, N)``, ``(T, N)`` (an agent missing from a
            step keeps its last row and shows offline).
        messages: Per step index, ``(M, 2)`` sender / receiver and ``(M,)`` page kind codes.
        sensors: ``(K, 7)`` release step, release x, y, z, land step (-1: never), land x, y.
        log: Per step index, the log lines.
        status: ``(T, N)`` why each agent is not active (``frames.STATUS_NAMES``): arrived (its recorded
            ``info_arrived``), collided or offline from the recorded step on; ended once offline otherwise.

    Raises:
        ValueError: When the arrays would not fit the memory limit (``core.budget``), checked before allocating.
        StoreError: A ``messages`` row of the episode of the wrong type (the other tables: ``replay_info``).
    """

    def __init__(self, info: ReplayInfo, names: list[str] | None = None) -> None:
        self.info = info
        self.steps = np.asarray(info.steps, dtype=np.int64)
        t, n = len(self.steps), info.n_agents
        # (T, N) arrays of 20 bytes a cell, and the episode's rows as read (a Python tuple and a float64 row each)
        check_memory(
            f"{info.path}: the replay of run {info.run} episode {info.episode} (runs.n_agents={n} x {t} "
            f"steps, {info.rows} rows)",
            20 * t * n + 360 * info.rows,
            "replay fewer agents or a shorter episode, or the store's runs.n_agents is damaged",
        )
        self.names = names or [f"#{i}" for i in range(n)]
        self.pos = np.zeros((t, n, 3), np.float32)
        self.heading = np.zeros((t, n), np.float32)
        self.group = np.full((t, n), -1, np.int16)
        self.online = np.zeros((t, n), np.uint8)
        self.messages: list[tuple[np.ndarray, np.ndarray]] = []
        self.log: list[list[dict[str, Any]]] = [[] for _ in range(t)]
        self.sensors = np.zeros((0, 7))
        self._load()

    def _load(self) -> None:
        info, n = self.info, self.info.n_agents
        key = (info.run, info.episode, info.world)
        index = {int(s): i for i, s in enumerate(self.steps)}
        why = [(-1, 0)] * n  # per agent: (step index, status code) of the first collision or timeout recorded
        con = open_read(info.path)
        try:
            check_values(con, info.path, "messages", "run = ? AND episode = ? AND world = ?", key)
            rows = np.array(
                con.execute(
                    "SELECT step, agent, x, y, coalesce(z, 0), coalesce(heading, 0), coalesce(online, 0), "
                    "coalesce(grp, -1) FROM steps WHERE run = ? AND episode = ? AND world = ? ORDER BY step, agent",
                    key,
                ).fetchall(),
                dtype=float,
            ).reshape(-1, 8)
            ti = np.array([index[int(s)] for s in rows[:, 0]], dtype=np.int64)
            ai = rows[:, 1].astype(np.int64)
            ok = (ai >= 0) & (ai < n)
            seen = np.zeros((len(self.steps), n), bool)
            seen[ti[ok], ai[ok]] = True
            self.pos[ti[ok], ai[ok]] = rows[ok, 2:5]
            self.heading[ti[ok], ai[ok]] = rows[ok, 5]
            self.online[ti[ok], ai[ok]] = rows[ok, 6]
            self.group[ti[ok], ai[ok]] = rows[ok, 7]
            for i in range(1, len(self.steps)):  # agents not recorded at a step (ended) keep their last place
                gone = ~seen[i]
                self.pos[i, gone] = self.pos[i - 1, gone]
                self.heading[i, gone] = self.heading[i - 1, gone]
                self.group[i, gone] = self.group[i - 1, gone]
            msgs = con.execute(
                "SELECT step, kind, coalesce(sender, -1), receiver FROM messages WHERE run = ? AND episode = ? "
                "AND world = ? AND event = 'delivered' AND receiver IS NOT NULL ORDER BY step",
                key,
            ).fetchall()
            by_step: dict[int, list[tuple[int, int, int]]] = {}
            for s, k, snd, rcv in msgs:
                by_step.setdefault(int(s), []).append((int(snd), int(rcv), int(k or AGENT)))
            for s in self.steps.tolist():
                m = by_step.get(s, [])
                self.messages.append(
                    (
                        np.array([(a, b) for a, b, _ in m], np.int32).reshape(-1, 2),
                        page_kinds(np.array([k for *_, k in m], np.int64)),
                    )
                )
                for a, b, k in m[:MAX_MESSAGE_LINES]:
                    self._add(
                        s,
                        message_log_kind(k),
                        f"{KIND_NAMES.get(k, k)} {self._name(a)} -> {self._name(b)}",
                        [b],
                    )
                if len(m) > MAX_MESSAGE_LINES:
                    self._add(s, "message", f"... and {len(m) - MAX_MESSAGE_LINES} more deliveries this step", [])
            for s, ev, a, b, obj, old, new in con.execute(
                "SELECT step, event, agent, other_agent, object, old, new FROM events WHERE run = ? AND "
                "episode = ? AND world = ? ORDER BY step",
                key,
            ):
                if ev in ("collision", "offline") and a is not None and 0 <= a < n and s in index:
                    why[a] = (index[s], COLLIDED if ev == "collision" else OFFLINE) if why[a][0] < 0 else why[a]
                if ev == "collision":
                    other = f"agent {self._name(b)}" if b is not None and b >= 0 else f"object #{obj}"
                    self._add(s, "collision", f"{self._name(a)} collided with {other}", [a])
                elif ev == "offline":
                    self._add(s, "timeout", f"{self._name(a)} missed its heartbeats: offline", [a])
                elif ev == "group":
                    self._add(s, "group", f"{self._name(a)}: group {old} -> {new}", [a])
            if "info_arrived" in info_columns(con):  # scenarios that score arrivals record them per step
                for s, a in con.execute(
                    "SELECT step, agent FROM steps WHERE run = ? AND episode = ? AND world = ? "
                    "AND info_arrived > 0 ORDER BY step",
                    key,
                ):
                    if a is not None and 0 <= a < n and s in index and why[a][0] < 0:
                        why[a] = (index[s], ARRIVED)
            self.sensors = np.array(
                con.execute(
                    "SELECT release_step, release_x, release_y, coalesce(release_z, 0), coalesce(land_step, -1), "
                    "coalesce(land_x, release_x), coalesce(land_y, release_y) FROM sensors WHERE run = ? AND "
                    "episode = ? AND world = ?",
                    key,
                ).fetchall(),
                dtype=float,
            ).reshape(-1, 7)
            for s in np.unique(self.sensors[:, 0]).astype(int).tolist():
                k = int((self.sensors[:, 0] == s).sum())
                self._add(s, "release", f"{k} sensor{'s' if k > 1 else ''} released", [])
            for s in np.unique(self.sensors[self.sensors[:, 4] >= 0, 4]).astype(int).tolist():
                k = int((self.sensors[:, 4] == s).sum())
                self._add(s, "landing", f"{k} sensor{'s' if k > 1 else ''} landed", [])
        finally:
            con.close()
        # the frame's status: collided or offline from the step the event was recorded, else ended once offline
        self.status = np.where(self.online == 0, ENDED, 0).astype(np.uint8)
        for a, (i, code) in enumerate(why):
            if i >= 0:
                self.status[i:, a] = np.where(self.online[i:, a] == 0, code, 0)
        for i in range(1, len(self.steps)):
            ended = np.flatnonzero(self.online[i - 1].astype(bool) & ~self.online[i].astype(bool))
            if ended.size:
                self.log[i].append(
                    {
                        "step": int(self.steps[i]),
                        "episode": self.info.episode,
                        "kind": "terminated",
                        "text": f"offline: {', '.join(self._name(int(a)) for a in ended[:8])}",
                        "slots": ended[:64].tolist(),
                    }
                )

    def _name(self, agent: int | None) -> str:
        if agent is None or agent < 0:
            return "env"
        return self.names[agent] if agent < len(self.names) else f"#{agent}"

    def _add(self, step: int, kind: str, text: str, slots: list[int]) -> None:
        i = int(np.searchsorted(self.steps, step))
        if i < len(self.steps) and self.steps[i] == step:
            self.log[i].append(
                {
                    "step": int(step),
                    "episode": self.info.episode,
                    "kind": kind,
                    "text": text,
                    "slots": [int(s) for s in slots if s is not None],
                }
            )

    def arrays(self, i: int, selected: int | None = None) -> dict[str, np.ndarray]:
        """The frame arrays of step index ``i``."""
        step = int(self.steps[i])
        out = {
            "pos": self.pos[i],
            "heading": self.heading[i],
            "group": self.group[i],
            "online": self.online[i],
            "status": self.status[i],
            "msg": self.messages[i][0],
            "msg_kind": self.messages[i][1],
        }
        if len(self.sensors):
            s = self.sensors
            out_pos, state = [], []
            falling = (s[:, 0] <= step) & ((s[:, 4] < 0) | (s[:, 4] > step))
            landed = (s[:, 4] >= 0) & (s[:, 4] <= step)
            if falling.any():  # linear descent between release and landing (the store keeps the two ends)
                f = s[falling]
                span = np.where(f[:, 4] > f[:, 0], f[:, 4] - f[:, 0], 1.0)
                a = np.clip((step - f[:, 0]) / span, 0.0, 1.0)[:, None]
                start, end = f[:, 1:4], np.column_stack([f[:, 5], f[:, 6], np.zeros(len(f))])
                out_pos.append(start + (end - start) * a)
                state.append(np.full(len(f), 1, np.uint8))
            if landed.any():
                lnd = s[landed]
                out_pos.append(np.column_stack([lnd[:, 5], lnd[:, 6], np.zeros(len(lnd))]))
                state.append(np.full(len(lnd), 2, np.uint8))
            out["payload_pos"] = (np.vstack(out_pos) if out_pos else np.zeros((0, 3))).astype(np.float32)
            out["payload_state"] = np.concatenate(state) if state else np.zeros(0, np.uint8)
        return out


def rebuild_scene(info: ReplayInfo) -> tuple[dict[str, Any], str | None]:
    """The ``scene`` message of the episode: its static scene rebuilt from the config and the seed.

    Returns:
        The message and, when the objects could not be rebuilt, why.
    """
    from agentsim_env.env.parallel_env import build_parallel_env

    n_worlds, known = recorded_seeds(info)  # a damaged seed is refused before anything is built
    config = info.config  # validated by replay_info
    replay = {
        "run": info.run,
        "episode": info.episode,
        "n_steps": len(info.steps),
        "first_step": int(info.steps[0]),
        "last_step": int(info.steps[-1]),
    }
    title = f"replay: {info.scenario}, run {info.run}, episode {info.episode}"
    try:
        env = build_parallel_env(info.scenario, **(config if isinstance(config, dict) else {}))
    except Exception as exc:  # noqa: BLE001 - a config of an older version: draw agents only
        return _bare_scene(info, title, replay), f"the run's config no longer builds ({exc}); no objects"
    why = None
    if n_worlds != 1:
        why = "a batched run: its static objects are not rebuilt"
        env.world.scene = type(env.world.scene)()
    elif not known:
        why = "the episode has no recorded seed: its static objects cannot be rebuilt"
        env.reset(seed=0)
        env.world.scene = type(env.world.scene)()
    else:
        first, seed = known[-1]
        env.reset(seed=int(seed))
        for _ in range(info.episode - first):  # episodes after a seeded one continue its sequence
            env.reset()
    msg = scene_message(env.world, env.scenario, 0, title=title, mode="replay", replay=replay)
    env.close()
    return msg, why


def _bare_scene(info: ReplayInfo, title: str, replay: dict[str, Any]) -> dict[str, Any]:
    (xmin, xmax, ymin, ymax) = info.canvas.bounds
    return {
        "type": "scene",
        "mode": "replay",
        "title": title,
        "scenario": info.scenario,
        "dt": info.dt or 0.1,
        "bounds": [xmin, xmax, ymin, ymax],
        "z_range": [0.0, 10.0],
        "n_agents": info.n_agents,
        "agent_names": [f"#{i}" for i in range(info.n_agents)],
        "agent_radius": [info.radius] * info.n_agents,
        "n_groups": 1,
        "objects": {"kind": [], "centre": [], "half": []},
        "zones": [],
        "log_kinds": [],
        "replay": replay,
    }


class ReplayViewer:
    """Serves one recorded episode to the viewer page; a thread plays it at the page's speed.

    Args:
        path: The store.
        run: The run (None: the last one).
        episode: The episode of the run.
        world: The world of a batched run.
        host, port: Where to serve (127.0.0.1 and a free port by default).
        speed: Steps per second of playback: 0 (as fast as possible) or ``MIN_SPEED..MAX_SPEED`` of
            ``render.web.viewer`` (None: real time, ``1 / dt``, brought into that range).
        quiet: Print nothing.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        run: int | None = None,
        episode: int = 0,
        world: int = 0,
        host: str = "127.0.0.1",
        port: int = 0,
        speed: float | None = None,
        quiet: bool = False,
    ) -> None:
        self.info = replay_info(path, run, episode, world)
        self.scene, why = rebuild_scene(self.info)
        self.data = ReplayData(self.info, self.scene["agent_names"])
        if why:
            self.data.log[0].insert(
                0,
                {
                    "step": int(self.data.steps[0]),
                    "episode": episode,
                    "kind": "episode",
                    "text": why,
                    "slots": [],
                },
            )
        rate = speed if speed is not None else clamp_speed(1.0 / self.info.dt if self.info.dt else 10.0)
        self.controls = Controls(rate)
        self.controls.reply = self._status  # replies to the controls carry the step and the steps/s shown
        self.controls.n_agents = self.info.n_agents
        self.server = WebServer(
            "viewer.html",
            host=host,
            port=port,
            title="agentsim replay",
            handlers=self.controls.handlers({"seek": self._seek, "play": self.controls._resume}),
            on_connect=self._hello,
        )
        self.quiet = quiet
        self.index = 0
        self.seq = 0
        self._seek_to: int | None = None
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        """The page's address."""
        return self.server.url

    def _hello(self) -> list[dict[str, Any]]:
        return [self.scene, self._status()]

    def _status(self) -> dict[str, Any]:
        return {
            **self.controls.status(),
            "step": int(self.data.steps[self.index]),
            "episode": self.info.episode,
            "index": self.index,
            "steps_per_s": self.controls.speed,
        }

    def _seek(self, msg: dict[str, Any]) -> dict[str, Any]:
        extra = sorted(set(msg) - {"cmd", "step"})
        if extra:
            raise ClientError(f"seek: unknown field(s) {extra}; allowed: ['step']")
        step = msg.get("step")
        first, last = int(self.data.steps[0]), int(self.data.steps[-1])
        if isinstance(step, bool) or not isinstance(step, int) or not first <= step <= last:
            raise ClientError(f"seek: 'step' must be an integer in {first}..{last}, got {step!r}")
        self._seek_to = min(int(np.searchsorted(self.data.steps, step)), len(self.data.steps) - 1)
        return {**self._status(), "index": self._seek_to, "step": int(self.data.steps[self._seek_to])}

    def _show(self, i: int) -> None:
        self.index = i
        self.seq += 1
        arrays = self.data.arrays(i)
        self.server.publish_frame(self.seq, pack_frame(self.seq, int(self.data.steps[i]), self.info.episode, arrays))
        self.server.publish_log(self.data.log[i])
        self.server.broadcast(self._status())

    def _run(self) -> None:
        """Playback: show the next step at the page's speed; hold when paused or at the end; obey seeks."""
        c = self.controls
        last_shown = -1
        while not c.closed:
            if self._seek_to is not None:
                i, self._seek_to = self._seek_to, None
                self._show(i)
                last_shown = i
                continue
            if not c.wait_turn(0.02):  # paused: look for seeks again shortly
                continue
            nxt = last_shown + 1
            if nxt >= len(self.data.steps):
                c.paused = True  # the end: hold the last frame
                self.server.broadcast(self._status())
                continue
            self._show(nxt)
            last_shown = nxt
            c.pace()

    def start(self) -> str:
        """Start the server and the playback thread; returns the URL."""
        url = self.server.start()
        if not self.quiet:
            print(
                f"agentsim viewer (replay of {self.info.path}, run {self.info.run}, episode {self.info.episode}, "
                f"{len(self.data.steps)} steps): {url}",
                file=sys.stderr,
                flush=True,
            )
        self._seek_to = 0
        self._thread = threading.Thread(target=self._run, name="agentsim-replay", daemon=True)
        self._thread.start()
        return url

    def close(self) -> None:
        """Stop the playback and the server."""
        self.controls.close()
        if self._thread is not None:
            self._thread.join(5.0)
        self.server.stop()


__all__ = ["ReplayData", "ReplayViewer", "rebuild_scene"]

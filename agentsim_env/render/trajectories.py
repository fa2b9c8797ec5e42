"""Trajectory figures of one episode: the map, obstacles, scenario markers and every agent's path.

:class:`TrajectoryRecorder` is an observer for ``agentsim_env.policies.rollout.run_episode(on_step=...)`` (and,
through its ``on_rollout``, for ``env.rollout(..., on_step=...)``): it
keeps the positions of world 0's agents after the reset and after every step, and what happened to each agent
(arrived, collided, went offline, still flying). :func:`plot_trajectories` draws the result with matplotlib
(headless, no pyplot state): map bounds, obstacles (boxes and cylinders, shaded by height), the scenario's
markers (goals, zones, landed sensors: ``scenario.markers(world, 0)``), each path as a line from a start
marker to an end marker whose shape says the agent's outcome, a legend and a title. Each agent has its own colour
(``render.palette``) while there are at most a dozen; beyond that the colour says the agent's group.

The recorder reads ``env.world``, ``env.scenario`` and ``env.possible_agents`` only; it imports nothing above
the render layer.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agentsim_env.core.scene import BOX
from agentsim_env.render.palette import MAX_DISTINCT, PALETTE, agent_colors

__all__ = ["MAX_PATHS", "OUTCOMES", "TrajectoryRecorder", "Trajectories", "plot_trajectories"]

MAX_PATHS = 5_000
"""Most agent paths drawn (evenly spaced agents beyond that; the legend says how many); counts cover all."""

#: Agent outcomes, in drawing priority, with their end marker (filled with the agent's colour).
OUTCOMES: dict[str, str] = {
    "collided": "X",
    "arrived": "*",
    "offline": "v",
    "active": "s",
}
#: Info keys that mean an agent reached its objective (``met``: rendezvous).
ARRIVAL_KEYS: tuple[str, ...] = ("arrived", "met")


@dataclass
class Trajectories:
    """One episode's paths and the map they were flown on.

    Attributes:
        agents: Agent ids of world 0, in slot order.
        xy: Positions ``(records, agents, 2)``: after the reset, then after every step.
        last: Per agent, the last record index at which it was still in the episode.
        outcome: Per agent, a key of :data:`OUTCOMES`.
        bounds: ``(xmin, xmax, ymin, ymax)`` of the map in metres.
        obstacles: ``(k, 5)`` rows ``(is_box, cx, cy, half_x, half_y)`` (cylinders: ``half_x`` is the radius).
        obstacle_top: ``(k,)`` obstacle top heights in metres (for shading).
        markers: ``(xy (m, 2), rgb (m, 3) uint8, radius (m,))`` of the scenario at the end, or None.
        steps: Steps of the episode.
        group: Per agent, its group at the start (``-1``: none; empty: unknown, all drawn as one group).
    """

    agents: list[str]
    xy: np.ndarray
    last: np.ndarray
    outcome: list[str]
    bounds: tuple[float, float, float, float]
    obstacles: np.ndarray = field(default_factory=lambda: np.zeros((0, 5)))
    obstacle_top: np.ndarray = field(default_factory=lambda: np.zeros(0))
    markers: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    steps: int = 0
    group: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


class TrajectoryRecorder:
    """Records world 0's agent positions and outcomes; pass it as ``run_episode(..., on_step=recorder)``."""

    def __init__(self) -> None:
        """An empty recorder (one episode; it restarts when called with empty infos after a reset)."""
        self._xy: list[np.ndarray] = []
        self._live: list[np.ndarray] = []
        self._arrived: np.ndarray = np.zeros(0, dtype=bool)
        self._collided: np.ndarray = np.zeros(0, dtype=bool)
        self._agents: list[str] = []
        self._group: np.ndarray = np.zeros(0, dtype=np.int64)

    def __call__(self, env: Any, infos: dict[str, dict[str, Any]]) -> None:
        """Record the positions now and the outcome flags in ``infos`` (empty right after the reset)."""
        st = env.world.state
        slots = st.slots_of_world(0)
        if not infos or not self._agents:  # right after a reset: a new episode
            self._agents = list(env.possible_agents)
            n = len(self._agents)
            self._xy, self._live = [], []
            self._arrived, self._collided = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
            self._group = np.array(st.group[slots], dtype=np.int64)
        self._xy.append(np.array(st.pos[slots, :2], dtype=float))
        live = set(env.agents)
        self._live.append(np.array([a in live for a in self._agents], dtype=bool))
        for i, a in enumerate(self._agents):
            info = infos.get(a)
            if not info:
                continue
            if any(info.get(k) for k in ARRIVAL_KEYS):
                self._arrived[i] = True
            if info.get("collided"):
                self._collided[i] = True

    def on_rollout(self, env: Any, step: int, view: Any) -> None:
        """The same record from ``env.rollout(..., on_step=recorder.on_rollout)``, on arrays (no infos dicts).

        Args:
            env: The env.
            step: Steps so far (0: right after the reset, a new episode).
            view: The step's ``StepView`` (``acted`` and ``live`` masks, ``info`` arrays over slots); None at 0.
        """
        st = env.world.state
        slots = st.slots_of_world(0)
        if view is None:
            self._agents = list(env.possible_agents)
            n = len(self._agents)
            self._xy, self._live = [], []
            self._arrived, self._collided = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
            self._group = np.array(st.group[slots], dtype=np.int64)
            live = np.ones(n, dtype=bool)
        else:
            live = np.asarray(view.live[slots], dtype=bool)
            acted = np.asarray(view.acted[slots], dtype=bool)
            for k in ARRIVAL_KEYS:
                if k in view.info:
                    self._arrived |= acted & (np.asarray(view.info[k])[slots] != 0)
            if "collided" in view.info:
                self._collided |= acted & (np.asarray(view.info["collided"])[slots] != 0)
        self._xy.append(np.array(st.pos[slots, :2], dtype=float))
        self._live.append(live)

    def result(self, env: Any) -> Trajectories:
        """The recorded episode, with the map, obstacles and markers of ``env`` as they are now (its end)."""
        if not self._xy:
            raise ValueError("no positions recorded: pass the recorder to run_episode(on_step=...) first")
        world = env.world
        st = world.state
        slots = st.slots_of_world(0)
        xy = np.stack(self._xy)
        live = np.stack(self._live)
        # an agent's last record is the step that ended it (it is no longer live after that step)
        gone = ~live
        first_gone = np.where(gone.any(axis=0), gone.argmax(axis=0), len(live) - 1)
        online = np.asarray(st.online[slots], dtype=bool)
        outcome = []
        for i in range(len(self._agents)):
            if self._collided[i]:
                outcome.append("collided")
            elif self._arrived[i]:
                outcome.append("arrived")
            elif not online[i]:
                outcome.append("offline")
            else:
                outcome.append("active")
        sc = world.scene
        mine = np.flatnonzero(np.asarray(sc.world) == 0)
        obstacles = (
            np.column_stack(
                [
                    np.asarray(sc.kind)[mine] == BOX,
                    np.asarray(sc.centre)[mine, 0],
                    np.asarray(sc.centre)[mine, 1],
                    np.asarray(sc.half)[mine, 0],
                    np.asarray(sc.half)[mine, 1],
                ]
            ).astype(float)
            if len(mine)
            else np.zeros((0, 5))
        )
        tops = (np.asarray(sc.centre)[mine, 2] + np.asarray(sc.half)[mine, 2]).astype(float)
        found = env.scenario.markers(world, 0)  # may be views of the world's arrays: copy them
        markers = None if found is None else (np.array(found[0]), np.array(found[1]), np.array(found[2]))
        xmin, xmax, ymin, ymax = (float(b) for b in world.config.bounds)
        return Trajectories(
            agents=list(self._agents),
            xy=xy,
            last=first_gone.astype(int),
            outcome=outcome,
            bounds=(xmin, xmax, ymin, ymax),
            obstacles=obstacles,
            obstacle_top=tops,
            markers=markers,
            steps=len(xy) - 1,
            group=self._group.copy(),
        )


def plot_trajectories(traj: Trajectories, path: str | os.PathLike[str], title: str) -> Path:
    """Draw an episode's paths over its map and write the figure as PNG.

    Args:
        traj: The recorded episode (:meth:`TrajectoryRecorder.result`).
        path: The PNG file to write (its folder must exist).
        title: The figure title (e.g. scenario, policy, seed, steps).

    Returns:
        The written path.
    """
    from matplotlib.collections import LineCollection, PatchCollection
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Patch, Rectangle

    # one artist per kind (collections), not one per agent or object: 100,000 agents draw in seconds
    xmin, xmax, ymin, ymax = traj.bounds
    w, h = xmax - xmin, ymax - ymin
    side = 7.0
    fig = Figure(figsize=(side * min(1.6, max(0.6, w / max(h, 1e-9))) + 2.5, side))
    ax = fig.add_subplot()
    ax.add_patch(Rectangle((xmin, ymin), w, h, fill=False, edgecolor="black", linewidth=1.2))
    handles: list[Any] = [Patch(facecolor="none", edgecolor="black", label="map bounds")]
    ztop = max(float(traj.obstacle_top.max()) if len(traj.obstacle_top) else 1.0, 1.0)
    shapes, greys = [], []
    for (is_box, cx, cy, hx, hy), top in zip(traj.obstacles, traj.obstacle_top):
        greys.append(float(np.clip(0.75 - 0.45 * top / ztop, 0.2, 0.75)))
        shapes.append(Rectangle((cx - hx, cy - hy), 2 * hx, 2 * hy) if is_box else Circle((cx, cy), hx))
    if shapes:
        g = np.repeat(np.asarray(greys)[:, None], 3, axis=1)
        ax.add_collection(PatchCollection(shapes, facecolors=g, edgecolors="none"))
        handles.append(Patch(facecolor="0.5", label=f"obstacles ({len(traj.obstacles)})"))
    if traj.markers is not None and len(traj.markers[0]):
        mxy, rgb, rad = traj.markers
        # past MAX_PATHS markers (a goal per agent of a big world) an even sample of them, and past 200 their
        # smallest size shrinks as the paths' do: 100,000 goals at full size would cover the whole map
        m = len(mxy)
        keep = np.unique(np.linspace(0, m - 1, min(m, MAX_PATHS)).astype(np.int64))
        crowd_m = min(1.0, 200.0 / keep.size)
        floor = 0.006 * max(w, h) * max(crowd_m**0.5, 0.2)  # a goal of a metre still shows on a map of kilometres
        discs = [Circle((float(mxy[i, 0]), float(mxy[i, 1])), max(float(rad[i]), floor)) for i in keep.tolist()]
        ax.add_collection(
            PatchCollection(discs, facecolors=np.asarray(rgb, dtype=float)[keep] / 255.0, edgecolors="none", alpha=0.6)
        )
        label = "scenario markers (goals, zones, sensors)" + (f", {keep.size:,} of {m:,}" if keep.size < m else "")
        handles.append(Patch(facecolor=tuple(np.asarray(rgb[0], dtype=float) / 255.0), alpha=0.6, label=label))
    counts = dict.fromkeys(OUTCOMES, 0)
    n = len(traj.outcome)
    shown = np.unique(np.linspace(0, n - 1, min(n, MAX_PATHS)).astype(np.int64)) if n else np.zeros(0, np.int64)
    outcome = np.asarray(traj.outcome, dtype=object)
    for name, k in zip(*np.unique(outcome, return_counts=True)):
        counts[str(name)] = int(k)
    group = traj.group if len(traj.group) == n else np.zeros(n, dtype=np.int64)
    colours = agent_colors(n, group).astype(float) / 255.0
    crowd = min(1.0, 200.0 / max(shown.size, 1))  # markers and lines shrink past 200 paths, to stay readable
    if shown.size:
        paths = [traj.xy[: traj.last[i] + 1, i] for i in shown.tolist()]
        ax.add_collection(
            LineCollection(paths, colors=colours[shown], linewidths=max(0.4, 1.4 * crowd**0.5), alpha=0.9, zorder=3)
        )
        first = np.array([p[0] for p in paths])
        ax.scatter(
            first[:, 0],
            first[:, 1],
            s=max(1.0, 25 * crowd),
            marker="o",
            facecolors="white",
            edgecolors=colours[shown].tolist(),
            linewidths=max(0.3, 1.2 * crowd),
            zorder=4,
        )
    for name, end in OUTCOMES.items():
        mine = shown[outcome[shown] == name]
        if not mine.size:
            continue
        last = np.array([traj.xy[traj.last[i], i] for i in mine.tolist()])
        ax.scatter(
            last[:, 0],
            last[:, 1],
            s=max(2.0, 90 * crowd),
            marker=end,
            c=colours[mine],
            edgecolors="black",
            linewidths=0.5 * crowd**0.5,
            zorder=5,
        )
    if n <= MAX_DISTINCT:
        for i in range(n):
            handles.append(Line2D([], [], color=colours[i], linewidth=1.6, label=traj.agents[i]))
    else:
        groups, sizes = np.unique(group, return_counts=True)
        for g, k in list(zip(groups.tolist(), sizes.tolist()))[:MAX_DISTINCT]:
            handles.append(
                Line2D(
                    [],
                    [],
                    color=PALETTE[max(g, 0) % MAX_DISTINCT] / 255.0,
                    linewidth=1.6,
                    label=f"group {g} ({k:,} agents)",
                )
            )
        if len(groups) > MAX_DISTINCT:
            handles.append(
                Patch(
                    facecolor="none",
                    edgecolor="none",
                    label=f"... {len(groups) - MAX_DISTINCT} more groups (colours repeat)",
                )
            )
    handles.append(
        Line2D(
            [],
            [],
            linestyle="none",
            marker="o",
            markerfacecolor="white",
            markeredgecolor="black",
            label="start",
        )
    )
    for name, k in counts.items():
        if k:
            handles.append(
                Line2D(
                    [],
                    [],
                    linestyle="none",
                    marker=OUTCOMES[name],
                    markerfacecolor="0.85",
                    markeredgecolor="black",
                    markersize=8,
                    markeredgewidth=0.6,
                    label=f"{name} ({k})",
                )
            )
    if shown.size < n:
        handles.append(Patch(facecolor="none", edgecolor="none", label=f"paths of {shown.size:,} of {n:,} agents"))
    pad = 0.03 * max(w, h)
    ax.set_xlim(xmin - pad, xmax + pad)
    ax.set_ylim(ymin - pad, ymax + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    out = Path(path)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    return out

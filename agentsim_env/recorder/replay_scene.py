"""The static scene of a recorded episode for the frame replay: obstacles and the scenario's markers at the reset.

Neither is stored. Like the web replay, the scene is rebuilt from the run's config and the episode's seed: the
scenario places its obstacles and goals from the seed, so an env built from the config and reset with that seed
has them where the recording had them. An episode recorded without a seed after one with a seed is rebuilt by
resetting as many times as the recording did. A batched run, an episode without any seed, or a config that no
longer builds gives no scene (the replay draws agents, trails and sensors only) and says why.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agentsim_env.core.scene import BOX
from agentsim_env.recorder.checks import open_read
from agentsim_env.recorder.replay_load import ReplayInfo
from agentsim_env.recorder.schema import StoreError

__all__ = ["StaticScene", "static_scene"]


@dataclass(frozen=True)
class StaticScene:
    """What a replay frame draws under the agents.

    Attributes:
        box: ``(k,)`` bool, True for boxes (else cylinders).
        centre: ``(k, 2)`` obstacle centres in metres.
        half: ``(k, 2)`` half-extents (cylinders: the radius in both).
        top: ``(k,)`` obstacle top heights in metres.
        z_top: The world's ceiling in metres (for shading obstacles by height).
        markers: ``(xy (m, 2), rgb (m, 3) uint8, radius (m,))`` of the scenario right after the reset, or None.
    """

    box: np.ndarray
    centre: np.ndarray
    half: np.ndarray
    top: np.ndarray
    z_top: float
    markers: tuple[np.ndarray, np.ndarray, np.ndarray] | None


def recorded_seeds(info: ReplayInfo) -> tuple[int, list[tuple[int, int]]]:
    """The run's world count and the recorded ``(episode, seed)`` of the world's episodes up to this one.

    Raises:
        StoreError: A seed that is neither an integer >= 0 nor None (a damaged store).
    """
    con = open_read(info.path)
    try:
        (n_worlds,) = con.execute("SELECT n_worlds FROM runs WHERE run = ?", (info.run,)).fetchone()
        rows = con.execute(
            "SELECT episode, seed FROM episodes WHERE run = ? AND world = ? AND episode <= ? ORDER BY episode",
            (info.run, info.world, info.episode),
        ).fetchall()
    finally:
        con.close()
    known = []
    for e, s in rows:
        if s in (None, "None"):
            continue
        if not (isinstance(s, (int, str)) and str(s).isascii() and str(s).isdigit() and len(str(s)) <= 100):
            raise StoreError(
                f"{info.path}: episodes.seed holds {str(s)[:40]!r} in the row of run {info.run}, "
                f"episode {e}, world {info.world}, but it must be an integer >= 0 or None: "
                "the store is damaged"
            )
        known.append((int(e), int(s)))
    return int(n_worlds), known


def static_scene(info: ReplayInfo) -> tuple[StaticScene | None, str | None]:
    """The obstacles and markers of the episode, rebuilt from the run's config and the episode's seed.

    Args:
        info: The episode (``replay_info``).

    Returns:
        The scene, and None; or None and why it could not be rebuilt.

    Raises:
        StoreError: An ``episodes.seed`` of the world that is not an integer.
    """
    from agentsim_env.env.parallel_env import build_parallel_env

    n_worlds, known = recorded_seeds(info)
    if n_worlds != 1:
        return None, "a batched run: obstacles and goals are not rebuilt"
    if not known:
        return None, "no recorded seed: obstacles and goals cannot be rebuilt"
    try:
        env = build_parallel_env(info.scenario, **info.config)
    except Exception as exc:  # noqa: BLE001 - a config of another version, a scenario not registered here
        return None, f"the run's config no longer builds ({str(exc)[:80]})"
    try:
        first, seed = known[-1]
        env.reset(seed=seed)
        for _ in range(info.episode - first):  # episodes after a seeded one continue its sequence
            env.reset()
        world = env.world
        sc = world.scene
        mine = np.flatnonzero(np.asarray(sc.world) == 0)
        found = env.scenario.markers(world, 0)  # may be views of the world's arrays: copied
        markers = None if found is None else tuple(np.array(a) for a in found)
        scene = StaticScene(
            box=np.asarray(sc.kind)[mine] == BOX,
            centre=np.array(np.asarray(sc.centre)[mine, :2], dtype=float),
            half=np.array(np.asarray(sc.half)[mine, :2], dtype=float),
            top=np.asarray(sc.centre)[mine, 2] + np.asarray(sc.half)[mine, 2],
            z_top=float(world.config.z_range[1]),
            markers=markers,  # type: ignore[arg-type]
        )
    finally:
        env.close()
    return scene, None

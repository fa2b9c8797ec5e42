"""Every message an agent receives is in the store's ``messages`` table: bus deliveries, overlay hops and the
environment's collision notices (kind 3 ENV), so every inbox row an agent observed has its stored row."""

from __future__ import annotations

import sqlite3
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

import agentsim_env
from agentsim_env.comms.messages import ENV, FEATURES_PER_MESSAGE, OVERLAY
from agentsim_env.recorder import record

AGE_HORIZON = 100  # the inbox's age feature: age / 100 (episodes here are shorter, so never clipped)
CONFIG: dict[str, Any] = {
    "n_agents": 6,
    "max_steps": 40,
    "map_size": 60.0,
    "obstacle_density": 0.005,
    "obstacle_height": (20.0, 30.0),
    "comms": {"latency": 1, "heartbeat_period": 4, "heartbeat_timeout": 12, "inbox_size": 6},
}


def _toward_nearest_object(env: Any, rng: np.random.Generator) -> dict[str, dict[str, np.ndarray]]:
    """Each live agent flies at the nearest obstacle (collisions) and sends a random ``comm`` action."""
    st, scene = env.world.state, env.world.scene
    acts = {}
    for a in env.agents:
        s = env.possible_agents.index(a)
        d = scene.centre[:, :2] - st.pos[s, :2]
        v = d[np.argmin(np.hypot(d[:, 0], d[:, 1]))]
        motion = np.array([*(v / max(float(np.hypot(*v)), 1e-9)), 0.0], dtype=np.float32)
        comm = rng.uniform(-1, 1, env.action_space(a)["comm"].shape).astype(np.float32)
        acts[a] = {"motion": motion, "comm": comm}
    return acts


def _observed(inbox: np.ndarray, step: int) -> Counter[tuple[int, int]]:
    """(kind, created step) of each valid row of one agent's inbox observation ``(M, F)`` at ``step``."""
    rows = inbox[inbox[:, 0] == 1.0]
    kinds = np.argmax(rows[:, 1:6], axis=1) + 1
    ages = np.rint(rows[:, 10] * AGE_HORIZON).astype(int)
    return Counter(zip(kinds.tolist(), (step - ages).tolist()))


def test_every_observed_inbox_row_has_its_stored_message(tmp_path: Path) -> None:
    db = tmp_path / "run.db"
    env = record(agentsim_env.make("navigation", **CONFIG), db)
    rng = np.random.default_rng(4)
    seen: list[tuple[int, int, str, Counter[tuple[int, int]]]] = []  # episode, step, agent, inbox rows
    for episode in range(3):
        obs, _ = env.reset(seed=10 + episode)
        step = 0
        while env.agents:
            obs, *_ = env.step(_toward_nearest_object(env, rng))
            step += 1
            seen += [(episode, step, a, _observed(o["inbox"], step)) for a, o in obs.items()]
    env.close()
    assert FEATURES_PER_MESSAGE == 11  # the layout _observed decodes
    with sqlite3.connect(db) as con:
        rows = con.execute(
            "SELECT episode, step, receiver, coalesce(kind, ?), created FROM messages "
            "WHERE event IN ('delivered', 'overlay') AND receiver >= 0",
            (OVERLAY,),
        ).fetchall()
        notices = con.execute("SELECT count(*) FROM messages WHERE kind = ? AND event = 'delivered'", (ENV,))
        hits = con.execute("SELECT count(*) FROM events WHERE event = 'collision'").fetchone()[0]
        assert notices.fetchone()[0] == hits > 0, "one stored ENV notice per collision"
    agents = env.possible_agents
    checked = Counter[int]()
    for episode, step, agent, inbox in seen:
        i = agents.index(agent)
        stored = Counter((k, c) for e, s, r, k, c in rows if e == episode and s <= step and r == i)
        missing = inbox - stored
        assert not missing, f"episode {episode}, step {step}, {agent}: inbox rows without a stored row {missing}"
        for kind, _ in inbox.elements():
            checked[kind] += 1
    assert checked[ENV] > 0 and checked[OVERLAY] + checked[1] + checked[2] > 0, checked


def test_a_batched_world_stores_the_events_of_its_single_env(tmp_path: Path) -> None:
    """World 1 of a recorded batch stores the collision rows (object numbered within the world) of a recorded
    single env with its seed."""
    from agentsim_env.env.vector import BatchedEnv
    from tests.test_seeding import CRASH_CONFIG, crash_actions

    w, seeds = 1, [21, 7, 1234]
    batch = record(BatchedEnv("navigation", len(seeds), **CRASH_CONFIG), tmp_path / "batch.db")
    single = record(agentsim_env.make("navigation", action_format="flat", **CRASH_CONFIG), tmp_path / "one.db")
    batch.reset(seed=seeds)
    single.reset(seed=seeds[w])
    rng = np.random.default_rng(5)
    for _ in range(100):
        acts = crash_actions(batch, rng)
        out = batch.step(acts)
        single.step({a: acts[w, i] for i, a in enumerate(single.possible_agents) if a in single.agents})
        if out.reset_worlds[w]:
            single.reset()
    batch.close()
    single.close()
    sql = "SELECT episode, step, event, agent, other_agent, object FROM events WHERE world = ? ORDER BY rowid"
    with sqlite3.connect(tmp_path / "batch.db") as a, sqlite3.connect(tmp_path / "one.db") as b:
        got, want = a.execute(sql, (w,)).fetchall(), b.execute(sql, (0,)).fetchall()
    assert any(r[2] == "collision" and r[5] >= 0 for r in want), "the test should hit objects"
    assert got == want

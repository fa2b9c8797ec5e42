"""Reading a store back (``agentsim_env.recorder.read``), exporting it, the ``agentsim runs`` / ``export``
commands, and the SQL queries of docs/store.md.

Every registered scenario is recorded for a short episode while the test keeps what the env returned at every
step; the frames read back must hold the same values, every field of every step.
"""

from __future__ import annotations

import re
import shutil
import sqlite3
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env import cli_store
from agentsim_env.cli import main
from agentsim_env.env.vector import BatchedEnv
from agentsim_env.policies.registry import make_policy
from agentsim_env.recorder import SCHEMA_VERSION, StoreError, record
from agentsim_env.recorder import read as store_read
from agentsim_env.recorder.read import INDEX, TABLES, export, open_store

pd = pytest.importorskip("pandas")

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "store.md"
#: Small configs per scenario (others: defaults with a short episode).
CONFIGS: dict[str, dict[str, Any]] = {
    "navigation": {"n_agents": 4, "max_steps": 25, "comms": {"heartbeat_period": 3}},
    "relay": {"max_steps": 25},
    "rendezvous": {"n_agents": 3, "max_steps": 25},
    "uav_release": {"zones": "tiny", "n_agents": 1, "payload": 20},  # the tiny zone needs 20 sensors
}
SCRIPTED = {"uav_release"}  # scenarios flown by their scripted policy (random actions elsewhere)
STATE = ("x", "y", "z", "vx", "vy", "vz", "heading", "online", "grp")


# ------------------------------------------------------------------------------------------ recording
def _state(env: Any, idx: int) -> dict[str, float]:
    st = env.world.state
    return {
        "x": st.pos[idx, 0],
        "y": st.pos[idx, 1],
        "z": st.pos[idx, 2],
        "vx": st.vel[idx, 0],
        "vy": st.vel[idx, 1],
        "vz": st.vel[idx, 2],
        "heading": st.heading[idx],
        "online": bool(st.online[idx]),
        "grp": int(st.group[idx]),
    }


def _record_episode(name: str, path: Path) -> list[dict[str, dict[str, Any]]]:
    """Record one episode of ``name``; return per step, per agent name, what the env returned and its state."""
    env = record(agentsim_env.make(name, **CONFIGS.get(name, {"max_steps": 20})), path, observations=[0])
    index = {a: i for i, a in enumerate(env.possible_agents)}
    obs, _ = env.reset(seed=0)
    policy = make_policy(name, env, None) if name in SCRIPTED else None
    if policy is not None:
        policy.reset(seed=0)
    for a, i in index.items():
        env.action_space(a).seed(i)
    kept = [{a: {**_state(env, index[a]), "obs": _flat(obs[a])} for a in env.agents}]
    while env.agents:
        live = list(env.agents)
        if policy is not None:
            actions = policy.act({a: obs[a] for a in live})
        else:
            actions = {a: env.action_space(a).sample() for a in live}
        obs, rew, term, trunc, infos = env.step(actions)
        kept.append(
            {
                a: {
                    **_state(env, index[a]),
                    "reward": rew[a],
                    "terminated": term[a],
                    "truncated": trunc[a],
                    "info": infos[a],
                    "obs": _flat(obs[a]) if a in obs else None,
                }
                for a in rew
            }
        )
    env.close()
    return kept


def _flat(o: Any) -> np.ndarray:
    return np.concatenate([np.ravel(v) for v in o.values()]) if isinstance(o, dict) else np.ravel(o)


@pytest.fixture(scope="module")
def doc_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Run 1: navigation with lossy, range-limited comms, heartbeats and agents steered into each other
    (collisions, drops of every reason, offline events); run 2: uav_release (sensors released and landed)."""
    path = tmp_path_factory.mktemp("store") / "run.db"
    comms = {"heartbeat_period": 3, "loss": 0.2, "bandwidth": 1, "max_range": 15.0, "latency": 1}
    env = record(
        agentsim_env.make(
            "navigation", n_agents=8, map_size=30, max_steps=40, comms=comms, body={"altitude": (5.0, 5.2)}
        ),
        path,
        label="doc example",
    )
    for ep in range(2):
        env.reset(seed=ep)
        for i, a in enumerate(env.possible_agents):
            env.action_space(a).seed(10 * ep + i)
        while env.agents:
            actions = {}
            for a in env.agents:
                act = env.action_space(a).sample()
                d = np.array([15.0, 15.0]) - env.world.state.pos[env.possible_agents.index(a), :2]
                act["motion"][:2] = d / max(float(np.linalg.norm(d)), 1e-6)  # towards the centre: collisions
                actions[a] = act
            env.step(actions)
    env.close()
    _record_episode("uav_release", path)
    return path


# ------------------------------------------------------------------------------------------ round trip
@pytest.mark.parametrize("name", agentsim_env.list_scenarios())
def test_round_trip_every_scenario(name: str, tmp_path: Path) -> None:
    path = tmp_path / "run.db"
    kept = _record_episode(name, path)
    with open_store(path) as store:
        runs = store.runs()
        steps = store.steps(run=1)
        observations = store.observations(run=1, episode=0)
        assert runs.loc[1, "scenario"] == name and runs.loc[1, "status"] == "complete"
        assert runs.loc[1, "step_rows"] == len(steps) == sum(len(k) for k in kept)
        assert runs.loc[1, "episodes"] == 1 and len(store.episodes(run=1)) == 1
        names = store.info_keys()
    cols = [f"info_{k}" for k in names]
    assert steps.index.names == list(INDEX["steps"]) and steps.index.is_unique
    assert set(steps.index.get_level_values("episode")) == {0}
    assert set(steps.index.get_level_values("world")) == {0}
    agents = agentsim_env.make(name, **CONFIGS.get(name, {"max_steps": 20})).possible_agents
    got = {(r["step"], r["agent"]): r for r in steps.reset_index().to_dict("records")}
    want = {(t, agents.index(a)): w for t, per_agent in enumerate(kept) for a, w in per_agent.items()}
    assert sorted(got) == sorted(want), "the (step, agent) rows differ from the agents the env stepped"
    keys = sorted(want)
    for c in STATE:  # positions, velocities, heading, online, group: every row
        a, b = (np.array([float(d[k][c]) for k in keys]) for d in (got, want))
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=0, err_msg=f"{name}: column {c}")
    first = [k for k in keys if k[0] == 0]  # the state after a reset: no reward, no flags, no infos
    assert all(pd.isna(got[k][c]) for k in first for c in ("reward", "terminated", "truncated", *cols))
    later = [k for k in keys if k[0] > 0]
    for c in ("reward", "terminated", "truncated"):
        a, b = (np.array([float(d[k][c]) for k in later]) for d in (got, want))
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=0, err_msg=f"{name}: column {c}")
    for k in later:
        numeric = {i: v for i, v in want[k]["info"].items() if isinstance(v, (int, float, np.number))}
        assert set(numeric) <= set(names), f"{name} {k}: info keys {sorted(numeric)} not all columns {names}"
        for i, v in numeric.items():
            assert got[k][f"info_{i}"] == pytest.approx(float(v), rel=1e-12, abs=1e-12), f"{name} {k} info {i}"
    # agent 0's flat observation, at every step it was returned
    obs0 = observations.xs(0, level="agent")["obs"]
    want_obs = {t: w["obs"] for (t, i), w in want.items() if i == 0 and w["obs"] is not None}
    assert sorted(obs0.index.get_level_values("step")) == sorted(want_obs)
    for (_, _, t, _), o in obs0.items():
        np.testing.assert_allclose(o, want_obs[t], rtol=1e-6, atol=1e-7)


def test_batched_round_trip_across_automatic_resets(tmp_path: Path) -> None:
    path = tmp_path / "batched.db"
    env = record(BatchedEnv("navigation", 3, n_agents=2, max_steps=4), path)
    snap: list[np.ndarray] = []
    env.world.add_hook(lambda world, events: snap.append(world.state.pos.copy()))  # after the recorder's hook
    rng = np.random.default_rng(0)
    env.reset(seed=5)
    st, n = env.world.state, 2
    episode = np.zeros(3, dtype=int)
    step = np.zeros(3, dtype=int)
    # (world, episode, step, agent) -> (position, (reward, terminated, truncated) or None after a reset)
    expected: dict[tuple[int, int, int, int], tuple[np.ndarray, Any]] = {
        (w, 0, 0, i): (st.pos[w * n + i].copy(), None) for w in range(3) for i in range(n)
    }
    for _ in range(11):
        alive = env.alive.copy()
        out = env.step(rng.uniform(-1, 1, (3, n, env.act_dim)))
        step += 1
        for w, i in zip(*np.nonzero(alive)):
            flags = (out.rewards[w, i], out.terminated[w, i], out.truncated[w, i])
            expected[(w, episode[w], step[w], i)] = (snap[-1][w * n + i], flags)
        for w in np.flatnonzero(out.reset_worlds):
            episode[w] += 1
            step[w] = 0
            for i in range(n):
                expected[(w, episode[w], 0, i)] = (st.pos[w * n + i].copy(), None)
    env.close()
    with open_store(path) as store:
        steps = store.steps()
        episodes = store.episodes()
        run = store.runs().loc[1]
    assert run["n_worlds"] == 3 and run["n_agents"] == 2 and run["episodes"] == len(episodes) == episode.sum() + 3
    for w in range(3):  # episode numbers increase per world, each starting at step 0
        assert list(episodes.xs(w, level="world").index.get_level_values("episode")) == list(range(episode[w] + 1))
    assert steps.index.is_unique and len(steps) == len(expected)
    for (w, ep, s, i), (pos, flags) in expected.items():
        row = steps.loc[(1, ep, s, w, i)]
        if pos is not None:
            np.testing.assert_allclose([row.x, row.y, row.z], pos, rtol=1e-12, atol=0)
        if flags is None:
            assert pd.isna(row.reward)
        else:
            assert row.reward == pytest.approx(float(flags[0]), rel=1e-6, abs=1e-6)
            assert bool(row.terminated) == bool(flags[1]) and bool(row.truncated) == bool(flags[2])
    # every finished episode ends with every agent terminated or truncated
    last = steps.groupby(level=("episode", "world", "agent")).tail(1)
    finished = [k for k in last.index if k[1] < episode[k[3]]]
    assert finished and all(bool(last.loc[k, "terminated"]) or bool(last.loc[k, "truncated"]) for k in finished)


# ------------------------------------------------------------------------------------------ the API
def test_frames_are_typed_indexed_and_filtered(doc_store: Path) -> None:
    with open_store(doc_store) as store:
        steps = store.steps()
        assert str(steps["terminated"].dtype) == "boolean" and str(steps["grp"].dtype) == "Int64"
        assert steps["x"].dtype == np.float64
        for table in ("episodes", "steps", "messages", "events", "sensors", "observations"):
            frame = getattr(store, table)()
            assert frame.index.names == list(INDEX[table]), table
            assert len(frame) == len(store.table(table)), table
            assert frame.index.is_monotonic_increasing, table
        assert set(store.steps(run=2).index.get_level_values("run")) == {2}
        assert set(store.steps(run=[1], episode=1).index.get_level_values("episode")) == {1}
        assert store.steps(run=[]).empty and store.steps(run=99).empty
        assert len(store.sensors(run=2)) == 20 and store.sensors(run=2)["land_step"].notna().all()
        runs = store.runs()
        assert list(runs.index) == [1, 2] and runs.loc[1, "label"] == "doc example"
        for name, table in (
            ("episodes", "episodes"),
            ("step_rows", "steps"),
            ("messages", "messages"),
            ("events", "events"),
            ("sensors", "sensors"),
        ):
            counts = store.table(table).groupby("run").size()
            assert runs[name].tolist() == [int(counts.get(r, 0)) for r in runs.index], name
        assert (runs["seconds"] >= 0).all()
        raw = store.table("steps")
        assert list(raw.columns[:5]) == ["run", "episode", "step", "world", "agent"]
        for bad in (True, "1", 1.5, [-1], [1, None]):
            with pytest.raises(ValueError, match="run must be an integer >= 0"):
                store.steps(run=bad)  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="table must be one of meta, runs, .*got .nope."):
            store.table("nope")
    with pytest.raises(StoreError, match="closed"):
        store.steps()


def test_the_reader_writes_nothing(doc_store: Path, tmp_path: Path) -> None:
    copy = tmp_path / "copy.db"
    shutil.copy(doc_store, copy)
    before = copy.read_bytes()
    with open_store(copy) as store:
        store.steps()
        with pytest.raises(sqlite3.OperationalError, match="readonly|read-only|query_only"):
            store.con.execute("DELETE FROM steps")
    assert copy.read_bytes() == before


# ------------------------------------------------------------------------------------------ export
def _read_back(path: Path, store: Any, table: str) -> Any:
    if path.suffix == ".csv":
        text = {c: str for c, t in store.columns(table).items() if t == "TEXT"}
        return pd.read_csv(path, dtype=text)
    return pd.read_parquet(path)


def _values(frame: Any) -> dict[str, list[Any]]:
    """Column -> values, missing ones (None, NaN, NA) as None, numbers as float."""

    def norm(v: Any) -> Any:
        if v is None or (not isinstance(v, str) and pd.isna(v)):
            return None
        return float(v) if isinstance(v, (int, float, np.number)) and not isinstance(v, bool) else v

    return {c: [norm(v) for v in frame[c].tolist()] for c in frame.columns}


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_export_equals_the_tables(doc_store: Path, tmp_path: Path, fmt: str) -> None:
    paths = export(doc_store, tmp_path / "out", fmt)
    assert [p.name for p in paths] == [f"{t}.{fmt}" for t in TABLES]
    with open_store(doc_store) as store:
        for path, table in zip(paths, TABLES):
            got, want = _read_back(path, store, table), store.table(table)
            assert list(got.columns) == list(want.columns), table
            assert len(got) == len(want) > 0 or table == "observations", table
            assert _values(got) == _values(want), table
    assert not list((tmp_path / "out").glob(".*")), "temporary files left behind"


def test_export_some_tables_and_typed_parquet(doc_store: Path, tmp_path: Path) -> None:
    pq = pytest.importorskip("pyarrow.parquet")
    paths = export(doc_store, tmp_path, "parquet", ["steps", "messages", "steps"])
    assert [p.name for p in paths] == ["steps.parquet", "messages.parquet"]
    schema = pq.read_schema(paths[0])
    assert str(schema.field("step").type) == "int64" and str(schema.field("x").type) == "double"
    assert str(pq.read_schema(paths[1]).field("reason").type) == "string"
    with pytest.raises(ValueError, match="format must be one of csv, parquet, got 'xlsx'"):
        export(doc_store, tmp_path, "xlsx")
    with pytest.raises(ValueError, match="tables must be among .*got 'stepz'"):
        export(doc_store, tmp_path, "csv", ["stepz"])


# ------------------------------------------------------------------------------------------ CLI
def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("agentsim: error: "), err
    return err


def test_cli_runs_and_export(doc_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["runs", str(doc_store)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0] == "| " + " | ".join(cli_store.RUNS_COLUMNS) + " |"
    assert len(lines) == 4
    with open_store(doc_store) as store:
        r = store.run_rows()[0]
    cells = [c.strip() for c in lines[2].strip("|").split("|")]
    assert cells[:3] == ["1", "navigation", "complete"] and cells[5] == "1 x 8"
    assert cells[6:11] == [str(r[k]) for k in ("episodes", "step_rows", "messages", "events", "sensors")]
    assert cells[11] == "doc example" and lines[3].split("|")[2].strip() == "uav_release"
    out = tmp_path / "new" / "folder"
    argv = [
        "export",
        str(doc_store),
        "--format",
        "parquet",
        "--out",
        str(out),
        "--tables",
        "steps",
        "sensors",
    ]
    assert main(argv) == 0
    printed = capsys.readouterr().out.split()
    assert printed == [str(out / "steps.parquet"), str(out / "sensors.parquet")]
    assert main(["export", str(doc_store), "--out", str(out)]) == 0
    assert len(capsys.readouterr().out.split()) == len(TABLES) and (out / "meta.csv").is_file()


def test_cli_constants_match_the_reader() -> None:
    assert cli_store.FORMATS == store_read.FORMATS and cli_store.TABLES == store_read.TABLES


def test_cli_runs_of_an_empty_store(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from agentsim_env.recorder import connect

    connect(tmp_path / "empty.db").close()
    assert main(["runs", str(tmp_path / "empty.db")]) == 0
    assert "no runs recorded" in capsys.readouterr().out


# ------------------------------------------------------------------------------------------ errors
def _other_version(src: Path, dst: Path) -> Path:
    shutil.copy(src, dst)
    con = sqlite3.connect(dst)
    con.execute("UPDATE meta SET value = '99' WHERE key = 'schema_version'")
    con.commit()
    con.close()
    return dst


def test_bad_stores(doc_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "missing.db"
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"not an sqlite file, just text " * 40)
    other = _other_version(doc_store, tmp_path / "v99.db")
    cases = [
        (missing, "no such store"),
        (junk, "not a database"),
        (other, f"schema version 99, but this agentsim-env reads and writes version {SCHEMA_VERSION}"),
    ]
    for path, needle in cases:
        with pytest.raises(StoreError, match=re.escape(needle)):
            open_store(path)
        for argv in (["runs", str(path)], ["export", str(path), "--out", str(tmp_path / "out")]):
            assert main(argv) == 2
            err = _one_error_line(capsys)
            assert str(path) in err and needle in err, err
    assert not missing.exists() and not (tmp_path / "out").exists()
    assert junk.read_bytes() == b"not an sqlite file, just text " * 40


def test_bad_export_options(doc_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    for out, needle in ((a_file, "is a file"), (a_file / "sub", "cannot be created or written")):
        assert main(["export", str(doc_store), "--out", str(out)]) == 2
        err = _one_error_line(capsys)
        assert str(out) in err and needle in err
    assert main(["export", str(doc_store), "--out", str(tmp_path), "--format", "xlsx"]) == 2
    assert "csv, parquet" in _one_error_line(capsys)
    assert main(["export", str(doc_store), "--out", str(tmp_path), "--tables", "steps", "nope"]) == 2
    assert "'nope'" in _one_error_line(capsys)


def test_missing_pandas_gives_the_install_hint(
    doc_store: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "pandas", None)
    with open_store(doc_store) as store:
        for method in ("steps", "runs", "table"):
            args = ("steps",) if method == "table" else ()
            with pytest.raises(ImportError, match=re.escape('pip install "agentsim-env[store]"')):
                getattr(store, method)(*args)
        assert store.run_rows()[0]["scenario"] == "navigation"  # no pandas needed
    # CSV export and the commands work without pandas
    assert export(doc_store, tmp_path / "csv", tables=["runs"]) == [tmp_path / "csv" / "runs.csv"]
    assert main(["runs", str(doc_store)]) == 0


def test_missing_pyarrow_gives_the_install_hint(
    doc_store: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    with pytest.raises(ImportError, match=r"pyarrow.*agentsim-env\[store\]"):
        export(doc_store, tmp_path / "pq", "parquet")
    assert main(["export", str(doc_store), "--format", "parquet", "--out", str(tmp_path / "pq")]) == 2
    assert 'pip install "agentsim-env[store]"' in _one_error_line(capsys)
    assert not (tmp_path / "pq").exists()


# ------------------------------------------------------------------------------------------ docs
def _doc_queries() -> list[str]:
    return re.findall(r"```sql\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)


def test_the_doc_has_the_queries() -> None:
    text = DOC.read_text(encoding="utf-8")
    assert len(_doc_queries()) >= 6
    for table in TABLES:
        assert f"`{table}`" in text, table


@pytest.mark.parametrize("index", range(len(_doc_queries())))
def test_doc_query_runs(doc_store: Path, index: int) -> None:
    """Each ```sql block of docs/store.md runs against a recorded store and returns rows."""
    sql = _doc_queries()[index]
    con = sqlite3.connect(f"file:{doc_store}?mode=ro", uri=True)
    try:
        rows = con.execute(sql).fetchall()
    finally:
        con.close()
    assert rows, f"no rows from:\n{sql}"


def test_doc_python_examples_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The recording and reading examples of docs/store.md (not the DuckDB one: duckdb is not a dependency)."""
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)
    runnable = [b for b in blocks if "duckdb" not in b]
    assert len(runnable) == 2
    monkeypatch.chdir(tmp_path)
    for block in runnable:
        exec(compile(block, str(DOC), "exec"), {})
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["messages.parquet", "steps.parquet"]


def test_read_while_recording(tmp_path: Path) -> None:
    """A reader sees every committed step of a run still being written (WAL: neither blocks the other)."""
    path = tmp_path / "live.db"
    env = record(agentsim_env.make("rendezvous", n_agents=2, max_steps=50), path)
    env.reset(seed=1)
    for _ in range(3):
        env.step({a: env.action_space(a).sample() for a in env.agents})
    with open_store(path) as store:
        assert store.runs().loc[1, "status"] == "running" and pd.isna(store.runs().loc[1, "seconds"])
        assert store.steps().index.get_level_values("step").max() == 3
        n_rows = len(store.table("steps"))
    (steps_csv,) = export(path, tmp_path / "live", tables=["steps"])
    assert len(pd.read_csv(steps_csv)) == n_rows
    env.step({a: env.action_space(a).sample() for a in env.agents})  # the writer goes on
    env.close()
    with open_store(path) as store:
        assert store.runs().loc[1, "status"] == "complete"
        assert store.steps().index.get_level_values("step").max() == 4


def test_events_of_one_step_come_in_index_order_keeping_each_agents_recording_order(tmp_path: Path) -> None:
    """A step's events are recorded by stage (collisions, then timeouts, then group changes), not by agent; the
    frame follows its index and keeps each agent's events in the order they were recorded."""
    from tests.store_helpers import small_store

    path = small_store(tmp_path / "run.db")
    con = sqlite3.connect(path)
    con.execute("DELETE FROM events")
    rows = [
        ("collision", 2, 1, None, None),
        ("collision", 1, 2, None, None),
        ("offline", 0, None, None, None),
        ("group", 2, None, 0, 1),
    ]
    con.executemany(
        "INSERT INTO events (run, episode, world, step, event, agent, other_agent, object, old, new) "
        "VALUES (1, 0, 0, 3, ?, ?, ?, -1, ?, ?)",
        rows,
    )
    con.commit()
    con.close()
    with open_store(path) as store:
        ev = store.events()
    assert ev.index.is_monotonic_increasing
    assert list(zip(ev.index.get_level_values("agent"), ev["event"])) == [
        (0, "offline"),
        (1, "collision"),
        (2, "collision"),
        (2, "group"),
    ]

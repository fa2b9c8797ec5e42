"""The store's guarantees under failure: a killed writer, concurrent writers, another schema version, a
missing folder, a read-only and a full store.

- **Kill**: a child process records ``navigation`` and prints each step number once ``step()`` has returned; it
  is killed with SIGKILL mid-episode. The file then opens cleanly, passes ``PRAGMA integrity_check``, holds
  every step the child saw return (commit_every=1; with commit_every=k every step up to the last multiple of
  k) and nothing half-written, and the run is ``incomplete`` after the next open.
- **Concurrency**: several processes (and threads, each with its own connection) record to one file at the
  same time, the file created by whichever comes first; every run completes with all its rows.
- **Errors**: a refused file is refused before anything is written to it; a write that fails mid-run (the
  store turned read-only, the disk full) warns once, detaches the recorder and lets the episode run to its end,
  and the steps committed before the failure stay readable.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import threading
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.recorder import SCHEMA_VERSION, StoreError, connect, record
from agentsim_env.recorder.read import open_store

N = 4
#: Agents standing still never end, so an episode lasts exactly ``max_steps`` and every agent acts every step.
CONFIG: dict[str, Any] = {"n_agents": N, "comms": {"heartbeat_period": 3}}
CHILD_TIMEOUT_S = 120


def _zero(env: Any) -> dict[str, np.ndarray]:
    """An all-zero action (every part: motion, comm)."""
    space = env.action_space(env.possible_agents[0])
    return {k: np.zeros(b.shape, dtype=np.float32) for k, b in space.spaces.items()}


KILL_CHILD = """
import sys
import numpy as np
import agentsim_env
from agentsim_env.recorder import record

path, commit_every, stop_at = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
env = agentsim_env.make("navigation", n_agents=4, max_steps=100_000, comms={"heartbeat_period": 3})
env = record(env, path, commit_every=commit_every, observations=[0])
env.reset(seed=0)
zero = {k: np.zeros(b.shape, np.float32) for k, b in env.action_space(env.possible_agents[0]).spaces.items()}
step = 0
while True:
    env.step({a: zero for a in env.agents})
    step += 1
    print(step, flush=True)  # step() has returned: with commit_every=1 this step is durable
    if step == stop_at:
        sys.stdin.read()  # mid-episode, until killed
"""

CONCURRENT_CHILD = """
import json, sys
import numpy as np
import agentsim_env
from agentsim_env.recorder import record

path, label, episodes, steps = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
env = agentsim_env.make("navigation", n_agents=4, max_steps=steps, comms={"heartbeat_period": 3})
print("ready", flush=True)
sys.stdin.readline()  # every writer starts together; the first creates the file
env = record(env, path, label=label)
run = env.recorder.run
zero = {k: np.zeros(b.shape, np.float32) for k, b in env.action_space(env.possible_agents[0]).spaces.items()}
for ep in range(episodes):
    env.reset(seed=ep)
    while env.agents:
        env.step({a: zero for a in env.agents})
env.close()
print(json.dumps({"run": run, "label": label}), flush=True)
"""


def _python(script: Path, *args: object) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, str(script), *map(str, args)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _stop(proc: subprocess.Popen[str]) -> None:
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def _run_status(path: Path, run: int = 1) -> tuple[str, int, int]:
    """(status, pid, last_step) of ``run``, read without the recovery that ``connect`` does."""
    con = sqlite3.connect(path)
    try:
        return con.execute("SELECT status, pid, last_step FROM runs WHERE run = ?", (run,)).fetchone()
    finally:
        con.close()


def _integrity_ok(con: sqlite3.Connection) -> None:
    assert con.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
    assert con.execute("PRAGMA foreign_key_check").fetchall() == []


def _steps_complete(con: sqlite3.Connection, run: int, last: int, episodes: int = 1) -> None:
    """Every step 0..last of each episode of ``run`` has its N rows, and no later step has any."""
    rows = con.execute(
        "SELECT episode, step, COUNT(*) FROM steps WHERE run = ? GROUP BY episode, step ORDER BY episode, step",
        (run,),
    ).fetchall()
    assert rows == [(ep, s, N) for ep in range(episodes) for s in range(last + 1)]


# ------------------------------------------------------------------------------------------ kill -9
def _kill_child(tmp_path: Path, commit_every: int, stop_at: int, kill_at: int = 30) -> tuple[Path, int, int]:
    """Run the recording child and SIGKILL it once it printed step ``kill_at`` (it waits there when
    ``stop_at == kill_at``, else it goes on stepping until the signal lands). Returns the store, the child's
    pid and the last step it printed."""
    db = tmp_path / "killed.db"
    script = tmp_path / "kill_child.py"
    script.write_text(KILL_CHILD, encoding="utf-8")
    proc = _python(script, db, commit_every, stop_at)
    watchdog = threading.Timer(CHILD_TIMEOUT_S, proc.kill)
    watchdog.start()
    printed: list[int] = []
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            printed.append(int(line))
            if printed[-1] >= kill_at:
                break
        os.kill(proc.pid, signal.SIGKILL)
        # read() drains what the line iterator buffered ahead too (communicate() would skip it)
        rest, err = proc.stdout.read(), proc.stderr.read() if proc.stderr is not None else ""
        proc.wait(CHILD_TIMEOUT_S)
    finally:
        watchdog.cancel()
        _stop(proc)
    printed += [int(x) for x in rest.split()]
    assert proc.returncode == -signal.SIGKILL, err
    assert printed == list(range(1, len(printed) + 1)) and printed[-1] >= kill_at, err
    return db, proc.pid, printed[-1]


def _check_killed_store(db: Path, pid: int, committed: int) -> None:
    """The killed child's store: clean, every committed step present and complete, the run incomplete."""
    status, writer, last_step = _run_status(db)
    assert (status, writer) == ("running", pid)  # as the child left it
    assert last_step == committed
    con = connect(db)  # opens cleanly; the dead writer's run is recovered
    try:
        _integrity_ok(con)
        assert con.execute("SELECT status, last_step FROM runs").fetchall() == [("incomplete", committed)]
        assert con.execute("SELECT MAX(step) FROM steps WHERE run = 1").fetchone() == (committed,)
        _steps_complete(con, 1, committed)
        # the observations of agent 0 are committed with their step
        obs = con.execute("SELECT step FROM observations WHERE run = 1 ORDER BY step").fetchall()
        assert obs == [(s,) for s in range(committed + 1)]
        # messages go out every step: those of every committed step, none of a lost one
        msg = con.execute("SELECT DISTINCT step FROM messages WHERE run = 1 AND event = 'sent'").fetchall()
        assert {s for (s,) in msg} == set(range(1, committed + 1))
    finally:
        con.close()
    with open_store(db) as store:  # the reader agrees
        (row,) = store.run_rows()
        assert row["status"] == "incomplete" and row["step_rows"] == N * (committed + 1)


def test_kill_9_mid_episode_keeps_every_returned_step(tmp_path: Path) -> None:
    db, pid, last = _kill_child(tmp_path, commit_every=1, stop_at=30)
    assert last == 30
    _check_killed_store(db, pid, last)


def test_kill_9_with_commit_every_keeps_the_committed_steps(tmp_path: Path) -> None:
    db, pid, last = _kill_child(tmp_path, commit_every=5, stop_at=32, kill_at=32)
    assert last == 32
    _check_killed_store(db, pid, 30)  # steps 31 and 32 were not committed yet


def test_kill_9_while_stepping(tmp_path: Path) -> None:
    """The signal lands anywhere in a step: the store holds the last printed step, or the next one when it was
    committed before the print, never a part of a step."""
    db, pid, last = _kill_child(tmp_path, commit_every=1, stop_at=0)
    _, _, committed = _run_status(db)
    assert committed in (last, last + 1)
    con = connect(db)
    try:
        _integrity_ok(con)
        assert con.execute("SELECT status, last_step FROM runs").fetchall() == [("incomplete", committed)]
        _steps_complete(con, 1, committed)
        (obs_last,) = con.execute("SELECT MAX(step) FROM observations").fetchone()
        assert last <= obs_last <= committed  # a step's observations follow its commit
    finally:
        con.close()


# ------------------------------------------------------------------------------------------ concurrency
def test_processes_record_to_one_file_at_once(tmp_path: Path) -> None:
    db = tmp_path / "shared.db"
    script = tmp_path / "writer.py"
    script.write_text(CONCURRENT_CHILD, encoding="utf-8")
    writers, episodes, steps = 3, 3, 40
    procs = [_python(script, db, f"writer{i}", episodes, steps) for i in range(writers)]
    watchdog = threading.Timer(CHILD_TIMEOUT_S, lambda: [p.kill() for p in procs])
    watchdog.start()
    try:
        for p in procs:
            assert p.stdout is not None and p.stdout.readline().strip() == "ready", p.communicate()[1]
        for p in procs:  # start together
            assert p.stdin is not None
            p.stdin.write("go\n")
            p.stdin.flush()
        outs = [p.communicate(timeout=CHILD_TIMEOUT_S) for p in procs]
    finally:
        watchdog.cancel()
        for p in procs:
            _stop(p)
    for p, (_out, err) in zip(procs, outs):
        assert p.returncode == 0, err
        assert "RuntimeWarning" not in err, err  # no writer detached
    done = {json.loads(out.splitlines()[-1])["label"]: json.loads(out.splitlines()[-1])["run"] for out, _ in outs}
    assert sorted(done) == [f"writer{i}" for i in range(writers)] and sorted(done.values()) == [1, 2, 3]
    con = connect(db)
    try:
        _integrity_ok(con)
        runs = con.execute("SELECT run, label, status, last_step, pid FROM runs ORDER BY run").fetchall()
        assert [(r, s, last) for r, _, s, last, _ in runs] == [(r, "complete", steps) for r in (1, 2, 3)]
        assert len({pid for *_, pid in runs}) == writers
        for run, label, *_ in runs:
            assert done[label] == run
            _steps_complete(con, run, steps, episodes)
            assert con.execute("SELECT COUNT(*) FROM episodes WHERE run = ?", (run,)).fetchone() == (episodes,)
    finally:
        con.close()


def test_threads_record_to_one_file_at_once(tmp_path: Path) -> None:
    """Two recorders of one process (separate connections, same pid): neither takes the other's live run for a
    dead one, both complete."""
    db = tmp_path / "threads.db"
    steps, errors, runs = 60, [], {}
    barrier = threading.Barrier(2)

    def writer(label: str) -> None:
        try:
            env = agentsim_env.make("navigation", max_steps=steps, **CONFIG)
            barrier.wait()
            env = record(env, db, label=label)
            runs[label] = env.recorder.run
            env.reset(seed=0)
            while env.agents:
                env.step({a: _zero(env) for a in env.agents})
            env.close()
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # a detached recorder fails its thread
        threads = [threading.Thread(target=writer, args=(f"t{i}",)) for i in range(2)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(CHILD_TIMEOUT_S)
    assert not errors, errors
    con = connect(db)
    try:
        _integrity_ok(con)
        assert con.execute("SELECT label, status FROM runs ORDER BY label").fetchall() == [
            ("t0", "complete"),
            ("t1", "complete"),
        ]
        for run in runs.values():
            _steps_complete(con, run, steps)
    finally:
        con.close()


# ------------------------------------------------------------------------------------------ schema
def _short_store(path: Path, steps: int = 3) -> None:
    env = record(agentsim_env.make("navigation", max_steps=50, **CONFIG), path)
    env.reset(seed=0)
    for _ in range(steps):
        env.step({a: _zero(env) for a in env.agents})
    env.close()


def _sqlite_objects(path: Path) -> list[tuple[str, str]]:
    con = sqlite3.connect(path)
    try:
        return con.execute("SELECT type, name FROM sqlite_master ORDER BY type, name").fetchall()
    finally:
        con.close()


def test_another_schema_version_is_refused_naming_both(tmp_path: Path) -> None:
    db = tmp_path / "v99.db"
    _short_store(db)
    con = sqlite3.connect(db)
    con.execute("UPDATE meta SET value = '99' WHERE key = 'schema_version'")
    con.execute("DROP TABLE observations")  # a version without this table: it must not be added back
    con.execute("DROP INDEX steps_key")
    con.commit()
    con.close()
    before = _sqlite_objects(db)
    openers = {
        "record": lambda: record(agentsim_env.make("navigation", **CONFIG), db),
        "connect": lambda: connect(db),
        "connect(create=False)": lambda: connect(db, create=False),
        "open_store": lambda: open_store(db),
    }
    for name, opener in openers.items():
        with pytest.raises(StoreError) as info:
            opener()
        msg = str(info.value)
        assert str(db) in msg and "schema version 99" in msg and f"version {SCHEMA_VERSION}" in msg, (
            name,
            msg,
        )
    assert _sqlite_objects(db) == before  # refused as it is
    con = sqlite3.connect(db)
    assert con.execute("SELECT value FROM meta").fetchall() == [("99",)]
    con.execute("DELETE FROM meta")
    con.commit()
    con.close()
    with pytest.raises(StoreError, match=rf"schema version none, but .* version {SCHEMA_VERSION}"):
        connect(db)


def test_an_sqlite_file_that_is_no_store_is_left_alone(tmp_path: Path) -> None:
    db = tmp_path / "mine.db"
    con = sqlite3.connect(db)
    con.execute("CREATE TABLE results (x REAL)")
    con.commit()
    con.close()
    before = db.read_bytes()
    env = agentsim_env.make("navigation", **CONFIG)
    with pytest.raises(StoreError, match=r"not an agentsim store.*results"):
        record(env, db)
    assert db.read_bytes() == before and not env.world.hooks


# ------------------------------------------------------------------------------------------ errors
def test_missing_folder_is_refused_at_record(tmp_path: Path) -> None:
    path = tmp_path / "no" / "such" / "run.db"
    env = agentsim_env.make("navigation", **CONFIG)
    with pytest.raises(StoreError) as info:
        record(env, path)
    assert str(path) in str(info.value) and "does not exist" in str(info.value)
    assert not (tmp_path / "no").exists() and not env.world.hooks
    env.reset(seed=0)  # the env itself is untouched
    env.step({a: _zero(env) for a in env.agents})


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root writes a 0444 file anyway")
def test_read_only_file_is_refused_at_record(tmp_path: Path) -> None:
    db = tmp_path / "ro.db"
    _short_store(db)
    db.chmod(0o444)
    before = db.read_bytes()
    env = agentsim_env.make("navigation", **CONFIG)
    try:
        with pytest.raises(StoreError, match="readonly|read-only") as info:
            record(env, db)
        assert str(db) in str(info.value) and not env.world.hooks
        with open_store(db) as store:  # still readable
            assert store.run_rows()[0]["status"] == "complete"
    finally:
        db.chmod(0o644)
    assert db.read_bytes() == before


def _read_only(con: sqlite3.Connection) -> None:
    con.execute("PRAGMA query_only = ON")  # every later write fails with SQLITE_READONLY


def _full(con: sqlite3.Connection) -> None:
    (pages,) = con.execute("PRAGMA page_count").fetchone()
    con.execute(f"PRAGMA max_page_count = {pages}")  # the next page allocated: SQLITE_FULL


class _Witness:
    """A step hook added after the recorder: it must see every step, the one the recorder fails in too."""

    def __init__(self) -> None:
        self.steps: list[int] = []

    def __call__(self, world: Any, events: Any) -> None:
        self.steps.append(int(world.step_count[0]))


@pytest.mark.parametrize(
    ("breaker", "needle", "status"),
    [(_read_only, "readonly", "running"), (_full, "database or disk is full", "incomplete")],
    ids=["read-only", "disk-full"],
)
def test_failed_write_warns_once_detaches_and_the_episode_goes_on(
    tmp_path: Path, breaker: Any, needle: str, status: str
) -> None:
    db = tmp_path / "broken.db"
    max_steps, break_after = 60, 20
    env = record(agentsim_env.make("navigation", max_steps=max_steps, **CONFIG), db, observations=[0])
    rec = env.recorder
    witness = _Witness()
    env.world.add_hook(witness)
    env.reset(seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        failed_at = None
        steps = 0
        while env.agents:
            if steps == break_after:
                breaker(rec.con)
            # random actions: rows differ step to step (and fill pages), agents may end: the episode still runs out
            env.step({a: env.action_space(a).sample() for a in env.agents})
            steps += 1
            if failed_at is None and not rec.active:
                failed_at = steps
        env.reset(seed=1)  # a new episode is not recorded, and does not warn again
        env.step({a: _zero(env) for a in env.agents})
        env.close()
    mine = [w for w in caught if issubclass(w.category, RuntimeWarning) and "recorder" in str(w.message)]
    assert len(mine) == 1, [str(w.message) for w in caught]
    text = str(mine[0].message)
    assert str(db) in text and needle in text and "recording stopped" in text
    assert failed_at is not None and break_after < failed_at <= max_steps
    assert steps == max_steps  # the episode ran to its end
    assert not rec.active and rec.hook not in env.world.hooks and witness in env.world.hooks
    assert witness.steps == [*range(1, max_steps + 1), 1]  # never skipped, not even in the failing step
    assert rec.error is not None and needle in rec.error
    committed = failed_at - 1  # the failing step was rolled back whole
    con = sqlite3.connect(db)
    try:
        _integrity_ok(con)
        assert con.execute("SELECT status, last_step FROM runs").fetchall() == [(status, committed)]
        (n_rows,) = con.execute("SELECT COUNT(*) FROM steps").fetchone()
        assert con.execute("SELECT MIN(step), MAX(step) FROM steps").fetchone() == (0, committed)
        assert n_rows >= committed + N  # step 0 has every agent, each later step at least one
        assert con.execute("SELECT MAX(step) FROM observations").fetchone() == (committed,)
        assert con.execute("SELECT COUNT(*) FROM episodes").fetchone() == (1,)
    finally:
        con.close()
    with open_store(db) as store:  # the committed rows read back
        (row,) = store.run_rows()
        assert row["step_rows"] == n_rows and row["status"] == status


def test_failed_write_in_a_batched_env(tmp_path: Path) -> None:
    from agentsim_env.env.vector import BatchedEnv

    db = tmp_path / "batched.db"
    benv = record(BatchedEnv("navigation", 3, max_steps=10, **CONFIG), db)
    benv.reset(seed=0)
    act = np.zeros((3, N, benv.act_dim))
    for _ in range(4):
        benv.step(act)
    _full(benv.recorder.con)
    with pytest.warns(RuntimeWarning, match="database or disk is full") as caught:
        for _ in range(30):  # through two automatic resets of every world
            out = benv.step(act)
    assert len([w for w in caught if "recorder" in str(w.message)]) == 1
    assert out.obs.shape == (3, N, benv.obs_dim)
    assert not benv.recorder.active and benv.recorder.hook not in benv.world.hooks
    benv.close()
    con = connect(db)
    try:
        _integrity_ok(con)
        (last,) = con.execute("SELECT last_step FROM runs").fetchone()
        assert 4 <= last < 10
        rows = con.execute("SELECT world, MAX(step), COUNT(*) FROM steps GROUP BY world").fetchall()
        assert rows == [(w, last, N * (last + 1)) for w in range(3)]
    finally:
        con.close()


DISK_CHILD = """
import json, resource, signal, sys, warnings
import numpy as np
import agentsim_env
from agentsim_env.recorder import record

path, limit = sys.argv[1], int(sys.argv[2])
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG instead
env = record(agentsim_env.make("navigation", n_agents=50, max_steps=300), path)
zero = {k: np.zeros(b.shape, np.float32) for k, b in env.action_space(env.possible_agents[0]).spaces.items()}
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    env.reset(seed=0)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))  # files cannot grow past `limit` bytes
    steps, failed_at = 0, None
    while env.agents:
        env.step({a: zero for a in env.agents})
        steps += 1
        if failed_at is None and not env.recorder.active:
            failed_at = steps
    env.close()
print(json.dumps({"steps": steps, "failed_at": failed_at, "warnings": [str(w.message) for w in caught],
                  "hooked": env.recorder.hook in env.world.hooks}))
"""


@pytest.mark.skipif(not hasattr(signal, "SIGXFSZ"), reason="needs RLIMIT_FSIZE (POSIX)")
def test_a_real_write_error_from_the_os_detaches(tmp_path: Path) -> None:
    """Not a simulated error: the child's files may not grow past 256 KiB (RLIMIT_FSIZE, which binds root too),
    so SQLite's own write() of the WAL fails part-way through the episode."""
    db = tmp_path / "small.db"
    script = tmp_path / "disk_child.py"
    script.write_text(DISK_CHILD, encoding="utf-8")
    proc = _python(script, db, 256 * 1024)
    try:
        out, err = proc.communicate(timeout=CHILD_TIMEOUT_S)
    finally:
        _stop(proc)
    assert proc.returncode == 0, err
    res = json.loads(out.splitlines()[-1])
    assert res["steps"] == 300 and res["failed_at"] is not None and not res["hooked"], res
    (msg,) = [w for w in res["warnings"] if "recorder" in w]
    assert str(db) in msg and "recording stopped" in msg
    con = connect(db)  # the child has exited: the run is recovered as incomplete if it was left running
    try:
        _integrity_ok(con)
        ((status, last),) = con.execute("SELECT status, last_step FROM runs").fetchall()
        assert status == "incomplete" and 0 <= last < res["failed_at"]
        assert con.execute("SELECT MAX(step) FROM steps").fetchone() == (last,)
        (n0,) = con.execute("SELECT COUNT(*) FROM steps WHERE step = 0").fetchone()
        assert n0 == 50
    finally:
        con.close()

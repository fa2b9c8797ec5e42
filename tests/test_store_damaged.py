"""A damaged store is refused with one clear error, never a traceback or a wrong picture.

Each case copies a small recorded store, damages it with SQL the way a hand edit, another tool or a broken copy
would (a dropped table or column, text / inf / 1e308 in ``steps.x``, a config value the config classes refuse, an
agent count no replay can hold), then runs ``agentsim runs``, ``export``, ``replay`` and ``view --replay``.
Each command either works or ends with exit status 2 and one ``agentsim: error:`` line that names the store,
the table and the column; ``export`` writes no file when it refuses.
"""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path
from typing import Any

import pytest

import agentsim_env
from agentsim_env.cli import main
from agentsim_env.core.budget import MEMORY_ENV
from agentsim_env.recorder import StoreError, record
from agentsim_env.recorder.read import export, open_store
from agentsim_env.recorder.replay import replay_info

N = 3
STEPS = 5


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A store with one navigation run of one episode (N agents, STEPS steps)."""
    path = tmp_path_factory.mktemp("damaged") / "base.db"
    env = record(agentsim_env.make("navigation", n_agents=N, max_steps=STEPS), path)
    env.reset(seed=0)
    while env.agents:
        env.step({a: env.action_space(a).sample() for a in env.agents})
    env.close()
    return path


def _damaged(base: Path, tmp_path: Path, sql: str, name: str = "damaged.db") -> Path:
    path = tmp_path / name
    shutil.copy(base, path)
    con = sqlite3.connect(path)
    con.executescript(sql)
    con.commit()
    con.close()
    return path


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("agentsim: error: "), err
    return err


class _Started(Exception):
    """Raised instead of serving: the viewer got past every check."""


@pytest.fixture
def no_serving(monkeypatch: pytest.MonkeyPatch) -> None:
    """``view --replay`` must not serve in these tests: a store that passes its checks raises _Started."""
    from agentsim_env.recorder.web_replay import ReplayViewer

    def start(self: Any) -> str:
        raise _Started

    monkeypatch.setattr(ReplayViewer, "start", start)


def _commands(db: Path, out: Path) -> dict[str, list[str]]:
    return {
        "runs": ["runs", str(db)],
        "export": ["export", str(db), "--out", str(out / "export")],
        "replay": ["replay", str(db), "--episode", "0", "--out", str(out / "frames")],
        "view": ["view", "--replay", str(db), "--episode", "0"],
    }


def _run(argv: list[str]) -> int:
    try:
        return main(argv)
    except _Started:
        return 0


#: (damage, the commands that refuse it, what their error names)
CASES = {
    "dropped table": ("DROP TABLE events;", {"runs", "export", "replay", "view"}, "table events is missing"),
    "dropped column": (
        "ALTER TABLE steps DROP COLUMN heading;",
        {"runs", "export", "replay", "view"},
        "steps.heading is missing",
    ),
    "text in steps.x": (
        "UPDATE steps SET x = 'abc' WHERE step = 2 AND agent = 1;",
        {"export", "replay", "view"},
        "steps.x",
    ),
    "inf in steps.x": (
        "UPDATE steps SET x = 9e999 WHERE step = 2 AND agent = 1;",
        {"replay", "view"},
        "steps.x",
    ),
    "1e308 in steps.x": (
        "UPDATE steps SET x = 1e308 WHERE step = 2 AND agent = 1;",
        {"replay", "view"},
        "steps.x",
    ),
    "agent out of range": (
        "UPDATE steps SET agent = 7 WHERE step = 2 AND agent = 1;",
        {"replay", "view"},
        "steps.agent",
    ),
    "body.radius=1e308": (
        "UPDATE runs SET config = json_set(config, '$.body.radius', 1e308);",
        {"replay", "view"},
        "runs.config of run 1: body.radius",
    ),
    "config not JSON": (
        "UPDATE runs SET config = '{\"body\": ';",
        {"replay", "view"},
        "runs.config of run 1",
    ),
    "n_agents 10**7": ("UPDATE runs SET n_agents = 10000000;", {"replay", "view"}, "runs.n_agents"),
    "started as text": (
        "UPDATE runs SET started = 'yesterday';",
        {"runs", "export", "replay", "view"},
        "runs.started",
    ),
    "started 1e308": ("UPDATE runs SET started = 1e308;", {"runs", "replay", "view"}, "runs.started"),
    "seed as text": ("UPDATE episodes SET seed = 'abc';", {"replay", "view"}, "episodes.seed"),
    "sender as text": (
        "INSERT INTO messages (run, episode, world, step, event, kind, sender, receiver) "
        "VALUES (1, 0, 0, 1, 'delivered', 1, 'x', 0);",
        {"export", "view"},
        "messages.sender",
    ),
}


@pytest.mark.usefixtures("no_serving")
@pytest.mark.parametrize("case", list(CASES))
def test_damaged_store_gives_one_clear_line(
    base: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str
) -> None:
    sql, refused, needle = CASES[case]
    db = _damaged(base, tmp_path, sql)
    for name, argv in _commands(db, tmp_path).items():
        code = _run(argv)
        if name in refused:
            assert code == 2, (name, capsys.readouterr())
            err = _one_error_line(capsys)
            assert str(db) in err and needle in err, (name, err)
        else:
            assert code == 0, (name, capsys.readouterr())
            capsys.readouterr()
    if "export" in refused:
        assert not (tmp_path / "export").exists() or not any((tmp_path / "export").iterdir())
    if "replay" in refused:
        assert not (tmp_path / "frames").exists() or not any((tmp_path / "frames").iterdir())


def test_the_python_api_raises_store_errors(base: Path, tmp_path: Path) -> None:
    db = _damaged(base, tmp_path, "DROP TABLE sensors;")
    with pytest.raises(StoreError, match="table sensors is missing"):
        open_store(db)
    with pytest.raises(StoreError, match="table sensors is missing"):
        export(db, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    with pytest.raises(StoreError, match="table sensors is missing"):
        replay_info(db)
    db2 = _damaged(base, tmp_path, "UPDATE steps SET y = -9e999 WHERE step = 3;", "inf.db")
    with pytest.raises(StoreError, match=r"steps\.y holds -inf .*run 1, episode 0, step 3"):
        replay_info(db2)


def test_export_refuses_before_writing_any_file(base: Path, tmp_path: Path) -> None:
    """The bad value sits in the last table exported: no earlier table's file is written either."""
    db = _damaged(
        base,
        tmp_path,
        "INSERT INTO observations (run, episode, world, step, agent, obs) VALUES (1, 0, 0, 1, 'one', '[]');",
    )
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(StoreError, match=r"observations\.agent holds text 'one'"):
        export(db, out)
    assert list(out.iterdir()) == []


def test_the_replay_memory_is_checked_before_allocating(
    base: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    no_serving: None,
) -> None:
    """An agent count the config allows (10^6) but that the memory limit cannot hold in the viewer's arrays."""
    db = _damaged(base, tmp_path, "UPDATE runs SET n_agents = 1000000;")
    monkeypatch.setenv(MEMORY_ENV, "0.05")
    assert _run(["view", "--replay", str(db), "--episode", "0"]) == 2
    err = _one_error_line(capsys)
    assert str(db) in err and "runs.n_agents=1000000" in err and MEMORY_ENV in err, err


def test_a_sound_store_still_replays(base: Path, tmp_path: Path, no_serving: None) -> None:
    for argv in _commands(base, tmp_path).values():
        assert _run(argv) == 0, argv

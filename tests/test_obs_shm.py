"""The shared-memory segments through which shards beside the driver take their actions and send their rows."""

from __future__ import annotations

import os
import stat
import subprocess
import sys

import numpy as np
import pytest

from agentsim_env.distributed.obs_shm import ObsSegment, ObsWriter, RowReader, RowSegment, reply_layouts

if not sys.platform.startswith("linux"):  # pragma: no cover - POSIX segments live in /dev/shm
    pytest.skip("reads /dev/shm", allow_module_level=True)


def _path(seg: ObsSegment) -> str:
    return os.path.join("/dev/shm", seg.name)


_CHILD = """
import sys
import numpy as np
from agentsim_env.distributed.obs_shm import ObsWriter
name, region, n_shards, n_slots, obs_dim, n = sys.argv[1], *map(int, sys.argv[2:])
w = ObsWriter(name, region, n_shards, n_slots, obs_dim)
w.array[:n] = np.arange(n * obs_dim, dtype=np.float32).reshape(n, obs_dim) + region
w.close()
"""


def test_rows_written_by_a_shard_are_read_by_the_driver() -> None:
    seg = ObsSegment(3, 10, 4)
    try:
        w = ObsWriter(seg.name, 1, 3, 10, 4)
        rows = np.random.default_rng(0).random((7, 4)).astype(np.float32)
        w.array[:7] = rows
        assert np.array_equal(seg.rows(1, 7), rows)
        assert not seg.rows(0, 7).any() and not seg.rows(2, 7).any()  # the other regions are untouched
        w.close()
    finally:
        seg.close()


def test_the_segment_is_its_owners_only_and_gone_after_close() -> None:
    seg = ObsSegment(2, 100, 8)
    path = _path(seg)
    st = os.stat(path)
    assert stat.S_IMODE(st.st_mode) == 0o600 and st.st_uid == os.getuid()
    assert len(seg.name) > 24  # a random name, not a guessable one
    seg.close()
    assert not os.path.exists(path)
    seg.close()  # idempotent
    with pytest.raises(RuntimeError, match="closed"):
        seg.rows(0, 1)


def test_a_shard_process_that_exits_leaves_the_segment_to_the_driver() -> None:
    seg = ObsSegment(2, 50, 3)
    try:
        # a process of its own, as a Ray worker is (not a multiprocessing child sharing this one's tracker)
        done = subprocess.run(
            [sys.executable, "-c", _CHILD, seg.name, "1", "2", "50", "3", "20"],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert done.returncode == 0, done.stderr
        assert "leaked" not in done.stderr
        assert os.path.exists(_path(seg))  # the child's resource tracker did not unlink it
        want = np.arange(60, dtype=np.float32).reshape(20, 3) + 1
        assert np.array_equal(seg.rows(1, 20), want)
    finally:
        seg.close()


@pytest.mark.parametrize(
    ("region", "n_shards", "n_slots", "obs_dim"),
    [(2, 2, 10, 4), (-1, 2, 10, 4), (0, 3, 10, 4), (0, 2, 11, 4), (0, 2, 10, 5)],
)
def test_a_writer_refuses_a_region_the_segment_does_not_hold(
    region: int, n_shards: int, n_slots: int, obs_dim: int
) -> None:
    seg = ObsSegment(2, 10, 4)
    try:
        with pytest.raises(ValueError, match="observation segment"):
            ObsWriter(seg.name, region, n_shards, n_slots, obs_dim)
    finally:
        seg.close()


def test_a_missing_segment_is_a_clear_error() -> None:
    with pytest.raises(FileNotFoundError):
        ObsWriter("agentsim-obs-does-not-exist", 0, 1, 1, 1)


@pytest.mark.parametrize(("k", "n"), [(-1, 1), (2, 1), (0, -1), (0, 11)])
def test_the_driver_reads_only_rows_a_region_holds(k: int, n: int) -> None:
    seg = ObsSegment(2, 10, 4)
    try:
        with pytest.raises(ValueError, match="shard must be in"):
            seg.rows(k, n)
    finally:
        seg.close()


_FULL_CHILD = """
import sys
import numpy as np
from agentsim_env.distributed.obs_shm import ObsWriter
name = sys.argv[1]
w = ObsWriter(name, 0, 2, 10, 4)
slots = np.array([7, 2, 5])
w.full[1][slots] = np.arange(12, dtype=np.float32).reshape(3, 4)
w.close()
"""


def test_a_shard_writes_rows_at_their_slots_of_a_full_array_the_driver_hands_out() -> None:
    seg = ObsSegment(2, 10, 4)
    try:
        assert len(seg.full) == 2 and all(a.shape == (10, 4) and a.dtype == np.float32 for a in seg.full)
        done = subprocess.run(
            [sys.executable, "-c", _FULL_CHILD, seg.name], capture_output=True, text=True, timeout=120
        )
        assert done.returncode == 0, done.stderr
        assert np.array_equal(seg.full[1][[7, 2, 5]], np.arange(12, dtype=np.float32).reshape(3, 4))
        assert not seg.full[1][[0, 1, 3, 4, 6, 8, 9]].any() and not seg.full[0].any()
        assert not seg.rows(0, 10).any() and not seg.rows(1, 10).any()  # after the shards' regions
    finally:
        seg.close()


def test_a_full_array_is_handed_out_only_when_nobody_holds_it() -> None:
    seg = ObsSegment(2, 10, 4)
    try:
        a = seg.free_full()
        assert a is seg.full[0] and seg.full_index(a) == 0
        b = seg.free_full(avoid=a)  # the previous step's is never handed out next
        assert b is seg.full[1]
        assert seg.free_full() is None  # both held
        view = b[2:4].reshape(-1)  # a view of a view still holds it
        del a, b
        assert seg.free_full(avoid=seg.full[1]) is seg.full[0]
        assert seg.free_full(avoid=seg.full[0]) is None
        del view
        assert seg.free_full(avoid=seg.full[0]) is seg.full[1]
        seg.retired.add(1)
        assert seg.free_full(avoid=seg.full[0]) is None
        assert seg.free_full() is seg.full[0]  # (one assert each: pytest keeps an assert's values until its end)
        assert seg.full_index(np.zeros((10, 4), np.float32)) == -1
    finally:
        seg.close()


def test_a_full_array_held_past_close_stays_readable() -> None:
    # the caller may keep the last observations after env.close(): the mapping goes with the last array, not
    # with the segment (a view of an unmapped segment would crash the interpreter when read)
    seg = ObsSegment(2, 10, 4)
    kept = seg.free_full()
    assert kept is not None
    kept[:] = 3.0
    obs = kept.reshape(1, 10, 4)
    path = _path(seg)
    del kept
    seg.close()
    assert not os.path.exists(path) and seg.full == ()
    assert float(obs.sum()) == 120.0
    obs[0, 0, 0] = 1.0  # still writable memory of this process


LAYOUT = (("motion", 3, "<f8"), ("comm", 7, "<f8"))


def test_actions_written_by_the_driver_are_read_by_their_shard() -> None:
    seg = RowSegment(2, 50, LAYOUT)
    try:
        rng = np.random.default_rng(1)
        parts = {"motion": rng.uniform(-1, 1, (50, 3)), "comm": rng.uniform(-1, 1, (50, 7))}
        mine, theirs = np.array([3, 7, 8, 40]), np.array([0, 1, 49])
        assert seg.write(1, mine, parts) == 4 and seg.write(0, theirs, parts) == 3
        reader = RowReader(seg.name, 1, 2, 50, LAYOUT)
        slots, rows = reader.read(4)
        assert np.array_equal(slots, mine) and list(rows) == ["motion", "comm"]
        for name, v in parts.items():
            assert np.array_equal(rows[name], v[mine]) and rows[name].dtype == np.float64
        seg.write(1, np.array([5]), parts)  # the next step overwrites the region: the slots read were a copy
        assert np.array_equal(slots, mine)
        with pytest.raises(ValueError, match="action rows must number"):
            reader.read(51)
        reader.close()
    finally:
        seg.close()


def test_the_action_segment_is_its_owners_only_and_gone_after_close() -> None:
    seg = RowSegment(2, 10, LAYOUT)
    path = os.path.join("/dev/shm", seg.name)
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    seg.close()
    assert not os.path.exists(path)
    with pytest.raises(RuntimeError, match="closed"):
        seg.write(0, np.zeros(0, dtype=np.int64), {})


@pytest.mark.parametrize(("region", "n_shards", "n_slots"), [(2, 2, 10), (-1, 2, 10), (0, 3, 10), (0, 2, 11)])
def test_a_reader_refuses_a_region_the_action_segment_does_not_hold(region: int, n_shards: int, n_slots: int) -> None:
    seg = RowSegment(2, 10, LAYOUT)
    try:
        with pytest.raises(ValueError, match="action segment"):
            RowReader(seg.name, region, n_shards, n_slots, LAYOUT)
    finally:
        seg.close()


def test_reply_rows_written_by_a_shard_are_read_by_the_driver_exactly() -> None:
    # the acting agents' rewards, terminations and infos (bool, int and float infos carried as float64) and the
    # own agents' slots, with or without their kinematics
    acted_layout, own_layout = reply_layouts(3)
    acted, own = RowSegment(2, 60, acted_layout, "acted"), RowSegment(2, 60, own_layout, "own")
    try:
        rng = np.random.default_rng(2)
        cols = {
            "rewards": rng.normal(size=60),
            "terminated": rng.uniform(size=60) < 0.3,
            "info0": (rng.uniform(size=60) < 0.5).astype(np.float64),
            "info1": rng.integers(-(2**40), 2**40, 60).astype(np.float64),
            "info2": rng.normal(size=60).astype(np.float32).astype(np.float64),
        }
        kin = {"pos": rng.normal(size=(60, 3)), "vel": rng.normal(size=(60, 3)), "heading": rng.normal(size=60)}
        kin["online"] = rng.uniform(size=60) < 0.9
        w_acted = RowReader(acted.name, 1, 2, 60, acted_layout, "reply")
        w_own = RowReader(own.name, 1, 2, 60, own_layout, "reply")
        slots, mine = np.array([4, 9, 33, 59]), np.array([4, 9, 12, 33, 59])
        assert w_acted.write(slots, cols) == 4 and w_own.write(mine, kin) == 5
        got_slots, got = acted.rows(1, 4)
        assert np.array_equal(got_slots, slots)
        for name, v in cols.items():
            assert np.array_equal(got[name][:, 0], v[slots]), name
        assert got["terminated"].dtype == bool
        assert np.array_equal(got["info1"][:, 0].astype(np.int64), cols["info1"][slots].astype(np.int64))
        got_mine, got_kin = own.rows(1, 5)
        assert np.array_equal(got_mine, mine)
        for name, v in kin.items():
            assert np.array_equal(got_kin[name].reshape(v[mine].shape), v[mine]), name
        assert w_own.write(np.array([1, 2]), None) == 2  # the slots only
        assert np.array_equal(own.rows(1, 2)[0], [1, 2])
        with pytest.raises(ValueError, match="holds 60 rows"):
            w_acted.write(np.arange(61), cols)
        with pytest.raises(ValueError, match="rows in"):
            acted.rows(1, 61)
        w_acted.close()
        w_own.close()
    finally:
        acted.close()
        own.close()

"""The distributed benchmark's bytes tables at a tiny size (2 local shards, every byte count positive) and its stage
table over Ray."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import distributed_bytes as bd  # noqa: E402


@pytest.mark.slow
def test_border_bytes_rows_have_positive_byte_counts() -> None:
    rows = bd.border_bytes([500], steps=2, shards=2)
    assert len(rows) == 1
    row = rows[0]
    assert row["n"] == 500
    assert row["halo"] > 0 and row["total"] > row["halo"]
    assert row["handover"] >= 0
    assert row["ghosts"] == row["halo"] / bd.GHOST_BYTES > 0
    assert row["expected"] > 0
    table = bd.border_table(rows)
    assert table.count("\n") == 2 and "500" in table


@pytest.mark.slow
def test_bytes_through_the_exchange_grow_with_the_shards() -> None:
    by_k = bd.bytes_by_shards(2000, [2, 3], steps=1)
    assert set(by_k) == {2, 3}
    for b in by_k.values():
        assert b["total"] > 0 and b["bus"] > 0 and b["groups"] > 0
        assert b["total"] >= sum(b[f] for f in ("halo", "handover", "offline", "bus", "positions", "groups")) - 1
    assert by_k[3]["groups"] > by_k[2]["groups"]  # every shard posts and gets every group's sums
    table = bd.hub_table(by_k, 2000)
    assert table.count("\n") == 3


@pytest.mark.slow
def test_stage_table_times_every_stage_in_both_shards() -> None:
    """``--stages``: the timed policy runs inside both Ray shards and every stage gets a time from each."""
    pytest.importorskip("ray")
    import subprocess

    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_distributed.py"), "--stages", "3000", "--steps", "4"],
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
    ).stdout
    rows = [line for line in out.splitlines() if line.startswith("| ") and "---" not in line][1:]
    import shard_stages as ss

    assert len(rows) == len(ss.STAGES) + 3
    for line, (_, t_one, _) in zip(rows[: len(ss.STAGES)], ss.STAGES, strict=True):
        cells = [c.strip() for c in line.strip("|").split("|")]
        shards = cells[3].split(" / ")  # "-" where a shard never ran the stage's methods
        assert len(shards) == 2 and all(float(x) >= 0 for x in shards), line
        assert (cells[1] == "-") == (not t_one), line  # one process ran each stage it has
        if t_one:
            assert float(cells[1]) >= 0, line
    assert float(rows[-2].split("|")[4].split("/")[0].strip(" *")) > 0  # the shards' whole step


@pytest.mark.slow
def test_coordinator_cost_table_has_a_row_per_shard_count_and_its_line() -> None:
    """Table d of ``bench_distributed``: the coordinator's part of a rollout step over 1 and 2 Ray shards."""
    pytest.importorskip("ray")
    import subprocess

    code = (
        "import bench_distributed as b, distributed_setup as ds\n"
        "ray = ds.start_ray()\n"
        "table, (a, slope) = b.coordinator_cost(600, [1, 2], 3)\n"
        "print(table)\n"
        "print('LINE', a, slope)\n"
        "ray.shutdown()\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
        cwd=ROOT / "benchmarks",
    ).stdout
    rows = [line for line in out.splitlines() if line.startswith("| ") and "---" not in line][1:]
    assert [r.split("|")[1].strip() for r in rows] == ["1", "2"]
    for r in rows:
        cells = [float(c.replace(",", "")) for c in r.strip("|").split("|")[1:]]
        assert all(c > 0 for c in cells), r  # a step's calls cost the driver some time and CPU
    a, slope = (float(x) for x in out.split("LINE")[1].split())
    assert abs(a + slope - float(rows[0].split("|")[2])) < 1e-6 + 0.05 * abs(a + slope) + 0.01

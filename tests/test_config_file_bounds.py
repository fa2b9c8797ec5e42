"""Config inputs under hostile sizes: bounded error messages, bounded YAML configs, bounded ``--set`` JSON.

A small file or argument must never cost more than a small, fixed amount of memory and time: error messages
never build a whole ``repr``; YAML configs refuse duplicate keys, deep nesting, aliases that expand past a
bound, big files and files that are not regular files; ``--set`` JSON refuses duplicate keys and deep nesting.
Each is answered with one ``agentsim: error:`` line and exit status 2.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import pytest

from agentsim_env.cli import main
from agentsim_env.core.validation import check_float, check_int, short_repr

yaml = pytest.importorskip("yaml")

from agentsim_env.train.config import load_config  # noqa: E402

#: The documented bounds of a YAML config (``agentsim_env.train.yaml_load``).
MAX_CONFIG_BYTES, MAX_DEPTH, MAX_NODES = 1 << 20, 32, 10_000


def load_yaml_text(text: str, name: str) -> Any:
    """``yaml_load.load_yaml_text`` (imported here so that every other test runs without the module)."""
    from agentsim_env.train import yaml_load

    assert (yaml_load.MAX_CONFIG_BYTES, yaml_load.MAX_DEPTH, yaml_load.MAX_NODES) == (
        MAX_CONFIG_BYTES,
        MAX_DEPTH,
        MAX_NODES,
    )
    return yaml_load.load_yaml_text(text, name)


def load_yaml_file(path: str | Path) -> Any:
    """``yaml_load.load_yaml_file``."""
    from agentsim_env.train import yaml_load

    return yaml_load.load_yaml_file(path)


def laughs(levels: int = 10, width: int = 10) -> str:
    """A "billion laughs" config: ``width ** levels`` strings under ``seed:`` from a few hundred bytes."""
    lines = ["scenario: navigation", "seed:", "  - &a0 [" + ",".join(['"lol"'] * width) + "]"]
    lines += [f"  - &a{i} [" + ",".join([f"*a{i - 1}"] * width) + "]" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


class Counted:
    """An object that counts how often its ``repr`` is taken."""

    calls = 0

    def __repr__(self) -> str:
        Counted.calls += 1
        return "Counted()"


def one_error_line(err: str) -> str:
    """The single ``agentsim: error:`` line of ``err`` (asserting it is the only output and no traceback)."""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("agentsim: error: "), err[-2000:]
    return lines[0]


# ------------------------------------------------------------------------------------------ short_repr
def test_short_repr_work_is_bounded_by_its_limit() -> None:
    shared: Any = [Counted()] * 10
    for _ in range(5):  # 10**6 references to one object, from six small lists
        shared = [shared] * 10
    Counted.calls = 0
    text = short_repr(shared, limit=120)
    assert len(text) <= 160 and text.startswith("[[[")
    assert Counted.calls <= 20, Counted.calls  # the whole repr would take 10**6 calls
    assert "list of 10 items" in text


def test_short_repr_of_values_repr_cannot_show() -> None:
    huge = 10**5000  # repr() itself refuses ints past 4,300 digits
    assert "5,001 digits" in short_repr(huge)
    with pytest.raises(ValueError, match="must be <= 5, got .*digits"):
        check_int("n", huge, 0, 5)
    with pytest.raises(ValueError, match="must be a finite number, got <int of 401 digits>"):
        check_float("x", 10**400, 0.0, 1.0)  # float(10**400) overflows
    loop: list[Any] = [1]
    loop.append(loop)
    assert short_repr(loop) == repr(loop)
    text = short_repr("x" * 10_000_000, limit=60)
    assert len(text) < 110 and "10,000,000 characters" in text
    assert short_repr({"a": 1, "b": (2, 3.5)}) == repr({"a": 1, "b": (2, 3.5)})
    assert short_repr("it's") == repr("it's") and short_repr(b"\x00") == repr(b"\x00")


def test_short_repr_keeps_small_values_exact() -> None:
    import numpy as np

    values: list[Any] = [
        None,
        True,
        3,
        -2.5,
        "abc",
        [1, 2],
        (1,),
        (),
        {},
        {1, 2} - {2},
        frozenset(),
        np.float32(1.5),
        np.arange(3),
        [[1, [2, [3]]]],
        b"ab",
        bytearray(b"x"),
    ]
    for value in values:
        assert short_repr(value) == repr(value), value


# ------------------------------------------------------------------------------------------ YAML loader
def test_billion_laughs_config_fails_fast_with_one_line(tmp_path: Path) -> None:
    path = tmp_path / "laughs.yaml"
    path.write_text(laughs())
    assert len(path.read_bytes()) < 600
    script = textwrap.dedent(f"""
        import resource, sys
        resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))  # the unbounded path needs GBs
        from agentsim_env.cli import main
        sys.exit(main(["train", "navigation", "--config", {str(path)!r}, "--out", {str(tmp_path / "out")!r}]))
    """)
    t0 = time.perf_counter()
    res = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "NUMBA_NUM_THREADS": "1"},
    )
    elapsed = time.perf_counter() - t0
    line = one_error_line(res.stderr)
    assert res.returncode == 2, res.stderr[-2000:]
    assert str(path) in line and "aliases" in line and f"{MAX_NODES:,}" in line, line
    assert elapsed < 30, elapsed
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("text", "needles"),
    [
        ("seed: 1\nworlds: 2\nseed: 3\n", ["duplicate key 'seed'", "line 3", "line 1"]),
        ("ppo:\n  n_steps: 8\n  n_steps: 16\n", ["duplicate key 'n_steps'", "line 3"]),
        ("env: {n_agents: 2, n_agents: 3}\n", ["duplicate key 'n_agents'", "line 1"]),
        ("x: " + "[" * 2000 + "]" * 2000 + "\n", [f"nested deeper than {MAX_DEPTH}", "line 1"]),
        ("x:\n" + "".join("  " * i + f"k{i}:\n" for i in range(1, 100)), [f"nested deeper than {MAX_DEPTH}"]),
        ("x: &a [*a]\n", ["recursive structure"]),
        (laughs(5, 10), ["aliases", f"{MAX_NODES:,}"]),
        ("x: &a [" + ",".join(["1"] * 9) + "]\n" + "y: [" + ",".join(["*a"] * 1200) + "]\n", ["aliases"]),
        (
            "d: &a [[[[[[[[[[[[[[[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]]]]]]]]]]]]]]\ne: [[[[[*a]]]]]\n",
            [f"nested deeper than {MAX_DEPTH}"],
        ),
    ],
    ids=[
        "top-key",
        "nested-key",
        "flow-key",
        "deep-flow",
        "deep-block",
        "self-alias",
        "laughs",
        "wide-alias",
        "deep-alias",
    ],
)
def test_yaml_configs_refuse_what_they_cannot_mean(text: str, needles: list[str]) -> None:
    with pytest.raises(ValueError) as err:
        load_yaml_text(text, "my.yaml")
    msg = str(err.value)
    assert msg.startswith("my.yaml: ") and len(msg) < 400, msg
    for needle in needles:
        assert needle in msg, msg


def test_yaml_configs_keep_what_they_mean() -> None:
    text = "base: &b {x: 1, y: 2}\nmerged:\n  <<: *b\n  x: 3\nuse: [*b, *b]\n1: one\n'1': string one\n"
    assert load_yaml_text(text, "ok.yaml") == {
        "base": {"x": 1, "y": 2},
        "merged": {"x": 3, "y": 2},
        "use": [{"x": 1, "y": 2}] * 2,
        1: "one",
        "1": "string one",
    }
    deep = "x: " + "[" * (MAX_DEPTH - 1) + "]" * (MAX_DEPTH - 1) + "\n"
    load_yaml_text(deep, "deep.yaml")  # exactly the documented depth
    assert load_yaml_text("", "empty.yaml") is None


def test_yaml_config_files_are_bounded_regular_files(tmp_path: Path) -> None:
    big = tmp_path / "big.yaml"
    big.write_text("# " + "x" * MAX_CONFIG_BYTES + "\nseed: 1\n")
    with pytest.raises(ValueError, match=f"is at most {MAX_CONFIG_BYTES:,} bytes"):
        load_yaml_file(big)
    with pytest.raises(ValueError, match="not a regular file"):
        load_yaml_file("/dev/zero")
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match="not a regular file"):
        load_yaml_file(fifo)  # never opened: opening a FIFO for reading blocks until a writer comes
    bad = tmp_path / "latin1.yaml"
    bad.write_bytes(b"name: caf\xe9\n")
    with pytest.raises(ValueError, match="not UTF-8"):
        load_yaml_file(bad)


def test_load_config_names_the_file_and_the_key(tmp_path: Path) -> None:
    path = tmp_path / "dup.yaml"
    path.write_text("scenario: navigation\nppo:\n  gamma: 0.9\n  gamma: 0.99\n")
    with pytest.raises(ValueError, match=r"dup\.yaml': duplicate key 'gamma' at line 4"):
        load_config(path)
    path.write_text("scenario: navigation\nseed: " + "9" * 5000 + "\n")
    with pytest.raises(ValueError, match=r"dup\.yaml.*integer at line 2 has 5,000 digits"):
        load_config(path)
    path.write_text("scenario: navigation\n1: 2\nzz: 3\n")  # unknown keys of mixed types
    with pytest.raises(ValueError, match="unknown key"):
        load_config(path)


@pytest.mark.parametrize(
    ("content", "needle"),
    [
        ("scenario: navigation\nseed: 1\nseed: 2\n", "duplicate key 'seed' at line 3"),
        ("scenario: navigation\nenv: " + "[" * 500 + "]" * 500 + "\n", "nested deeper than"),
        ("scenario: navigation\nseed: [" + ", ".join(["x" * 20] * 9000) + "]\n", "must be an integer"),
        ("scenario: navigation\nseed: [" + ", ".join(["1"] * 100_000) + "]\n", "more than 10,000 values"),
    ],
    ids=["duplicate", "deep", "long-value", "many-values"],
)
def test_agentsim_train_config_errors_are_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str, needle: str
) -> None:
    path = tmp_path / "c.yaml"
    path.write_text(content)
    # --eval-only with no model: a config that loads is refused right after, and nothing trains
    assert main(["train", "navigation", "--config", str(path), "--out", str(tmp_path), "--eval-only"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert needle in line and len(line) < 500, line


# ------------------------------------------------------------------------------------------ --set JSON
@pytest.mark.parametrize(
    ("pair", "needle"),
    [
        ('comms={"loss": 0.1, "loss": 0.5}', "duplicate key 'loss'"),
        ("comms=" + "[" * 5000 + "]" * 5000, "nested deeper than"),
        ("obstacle_size=" + "[" * 5000 + "]" * 5000, "obstacle_size: JSON nested deeper than 32 levels"),
        ("obstacle_size=[[[1]]]", "expected a list of 2 numbers"),
        ("goal_radius=" + "x" * 100_000, "expected a finite number"),
        ("n_agents=" + "9" * 5000, "expected an integer, got '999"),
    ],
    ids=["duplicate", "deep-subconfig", "deep-tuple", "shallow-tuple", "long-text", "long-integer"],
)
def test_set_json_is_bounded(capsys: pytest.CaptureFixture[str], pair: str, needle: str) -> None:
    assert main(["run", "navigation", "--episodes", "1", "--set", pair]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert needle in line and len(line) < 500, line


# ------------------------------------------------------------------------------------------ a model's config.json
@pytest.mark.parametrize(
    ("content", "needle"),
    [
        ('{"scenario": "navigation", "env": {"n_agents": 2, "n_agents": 3}}', "duplicate key 'n_agents'"),
        ('{"scenario": "navigation", "env": ' + "[" * 5000 + "]" * 5000 + "}", "nested too deeply"),
        ('{"scenario": "navigation", "env": ' + "[" * 100 + "]" * 100 + "}", "more than 32 levels"),
    ],
    ids=["duplicate", "deeper-than-recursion", "deep"],
)
def test_trained_model_config_json_is_bounded(tmp_path: Path, content: str, needle: str) -> None:
    from agentsim_env.policies.learned import model_env_config

    (tmp_path / "model.zip").write_bytes(b"")
    (tmp_path / "config.json").write_text(content)
    with pytest.raises(ValueError, match=needle) as err:
        model_env_config(tmp_path)
    assert "config.json" in str(err.value)

"""The ``agentsim`` command: input checks before any rollout, help texts, typed ``--set`` parsing, the
trajectory PNG and the kernel warm-up."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import matplotlib.image as mpimg
import numpy as np
import pytest

import agentsim_env
from agentsim_env import cli_kernels
from agentsim_env.cli import COMPILE_NOTICE, WARM_MARKER, config_tag, main, prepare_out
from agentsim_env.cli_set import parse_set
from agentsim_env.policies.registry import BASELINES, make_policy
from agentsim_env.policies.rollout import run_episode
from agentsim_env.render.trajectories import OUTCOMES, TrajectoryRecorder, plot_trajectories
from agentsim_env.scenarios.registry import scenario_class
from agentsim_env.uav.evaluation import runner

NAV = scenario_class("navigation").config_cls
RELAY = scenario_class("relay").config_cls
UAV = scenario_class("uav_release").config_cls
TINY_NAV = ["--set", "n_agents=2", "max_steps=20"]


@pytest.fixture
def no_rollout(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if any env is built or any evaluation run starts."""

    def boom(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("a rollout started")

    monkeypatch.setattr(agentsim_env, "make", boom)
    monkeypatch.setattr(runner, "run_grid", boom)


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("agentsim: error: "), err
    return err


# ---------------------------------------------------------------------------------------- counts (1)
@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["run", "navigation", "--episodes", "0"], ["--episodes", ">= 1", "got 0"]),
        (["run", "navigation", "--episodes", "-3"], ["--episodes", ">= 1", "got -3"]),
        (["run", "navigation", "--fps", "0"], ["--fps", "> 0"]),
        (["run", "navigation", "--seed", "-1"], ["--seed", ">= 0"]),
        (["evaluate", "--seeds", "0"], ["--seeds", ">= 1"]),
        (["evaluate", "--seeds", "0,-2"], ["--seeds", ">= 0"]),
    ],
)
def test_bad_counts_exit_2_before_any_rollout(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], no_rollout: None, argv: list[str], needles: list[str]
) -> None:
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out), "--quiet"]) == 2
    err = _one_error_line(capsys)
    assert all(n in err for n in needles), err
    assert not out.exists()


# ------------------------------------------------------------------------------------ output folder (2)
@pytest.mark.parametrize("command", [["run", "navigation", *TINY_NAV], ["evaluate", "--zones", "tiny"]])
def test_out_under_a_file_is_rejected_before_any_rollout(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], no_rollout: None, command: list[str]
) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    out = blocker / "sub"
    assert main([*command, "--out", str(out), "--quiet"]) == 2
    err = _one_error_line(capsys)
    assert "--out" in err and str(out) in err and "Not a directory" in err


def test_out_that_is_a_file_is_rejected(tmp_path: Path, capsys: pytest.CaptureFixture[str], no_rollout: None) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert main(["run", "navigation", "--out", str(blocker), "--quiet"]) == 2
    err = _one_error_line(capsys)
    assert "--out" in err and str(blocker) in err and "file" in err


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root writes anywhere")
def test_read_only_out_is_rejected(tmp_path: Path, capsys: pytest.CaptureFixture[str], no_rollout: None) -> None:
    ro = tmp_path / "ro"
    ro.mkdir(mode=0o500)
    try:
        assert main(["run", "navigation", "--out", str(ro / "out"), "--quiet"]) == 2
        err = _one_error_line(capsys)
        assert "--out" in err and "Permission denied" in err
    finally:
        ro.chmod(0o700)


def test_prepare_out_creates_probes_and_reports_what_it_made(tmp_path: Path) -> None:
    out = tmp_path / "a" / "b"
    created = prepare_out(out)
    assert out.is_dir() and not any(out.iterdir())  # the probe file is gone
    assert created == [out, tmp_path / "a"]
    assert prepare_out(out) == []


def test_a_bad_config_leaves_no_output_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "x" / "out"
    assert main(["run", "navigation", "--set", "n_agents=0", "--out", str(out), "--quiet"]) == 2
    assert "n_agents" in _one_error_line(capsys)
    assert not (tmp_path / "x").exists()


# ------------------------------------------------------------------------------------------ help (3)
def _help(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--help"])
    assert exc.value.code == 0
    return " ".join(capsys.readouterr().out.split())  # argparse wraps to the terminal width


def test_run_help_names_scenarios_baselines_and_defaults(capsys: pytest.CaptureFixture[str]) -> None:
    text = _help(["run"], capsys)
    for name in agentsim_env.list_scenarios():
        assert name in text
    for scenario, policies in BASELINES.items():
        first, *rest = policies
        assert f"{first} (default)" in text
        assert all(p in text for p in rest), scenario
    assert "(default: 5; 1 with --render)" in text and "(default: outputs)" in text and "(default: 0)" in text
    assert "examples:" in text and "agentsim run navigation" in text
    assert "body.radius=1.0" in text  # the --set syntax


def test_evaluate_and_main_help(capsys: pytest.CaptureFixture[str]) -> None:
    text = _help(["evaluate"], capsys)
    assert "B0_uniform" in text and "B8_teleport" in text and "(default: outputs/evaluation)" in text
    assert "(default: default)" in text and "(default: 3)" in text and "examples:" in text
    text = _help([], capsys)
    assert "warmup" in text and all(n in text for n in agentsim_env.list_scenarios())


def test_main_help_is_light() -> None:
    """``agentsim --help`` imports neither torch nor the policies (their registry pulls numba kernels)."""
    code = (
        "import sys\nfrom agentsim_env.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        "bad = [m for m in ('torch', 'agentsim_env.policies.registry') if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert "navigation" in res.stdout


# ------------------------------------------------------------------------------------- --set types (4)
@pytest.mark.parametrize(
    ("cls", "pairs", "expected"),
    [
        (NAV, ["collisions=False"], {"collisions": False}),
        (NAV, ["collisions=TRUE"], {"collisions": True}),
        (NAV, ["collisions=no"], {"collisions": False}),
        (NAV, ["collisions=1"], {"collisions": True}),
        (NAV, ["n_agents=8", "dt=0.2", "goal_radius=2"], {"n_agents": 8, "dt": 0.2, "goal_radius": 2.0}),
        (NAV, ["action_mode=primitive"], {"action_mode": "primitive"}),
        (NAV, ["obstacle_size=1,3"], {"obstacle_size": (1.0, 3.0)}),
        (NAV, ["obstacle_size=[1, 3]"], {"obstacle_size": (1.0, 3.0)}),
        (RELAY, ["gap=12,20"], {"gap": (12.0, 20.0)}),
        (NAV, ["map_size=none", "n_groups=NULL"], {"map_size": None, "n_groups": None}),
        (NAV, ["map_size=80"], {"map_size": 80.0}),
        (NAV, ["sensing.elevations_deg=0,"], {"sensing": {"elevations_deg": (0.0,)}}),
        (
            NAV,
            ["body.radius=1.0", "comms.loss=0.1", "body.max_speed=8"],
            {"body": {"radius": 1.0, "max_speed": 8.0}, "comms": {"loss": 0.1}},
        ),
        (
            NAV,
            ['body={"radius": 1, "altitude": [1, 5]}', "body.max_speed=3"],
            {"body": {"radius": 1.0, "altitude": (1.0, 5.0), "max_speed": 3.0}},
        ),
        (NAV, ["comms=none"], {"comms": None}),
        (NAV, ["comms.max_range=none"], {"comms": {"max_range": None}}),
        (UAV, ["n_uavs=2"], {"n_agents": 2}),
        (UAV, ["max_cycles=50"], {"max_steps": 50}),
        (UAV, ["zones=tiny"], {"zones": "tiny"}),  # Any: JSON when it parses, else the text
        (UAV, ['zones={"a": [1, 2]}'], {"zones": {"a": (1, 2)}}),
        (UAV, ["wind.direction=none", "wind.mean_speed=3"], {"wind": {"direction": None, "mean_speed": 3.0}}),
        (UAV, ["wsn.sink=centroid"], {"wsn": {"sink": "centroid"}}),
        (UAV, ["wsn.sink=10,20"], {"wsn": {"sink": (10, 20)}}),
        (NAV, ["dt=0.2", "dt=0.3"], {"dt": 0.3}),  # the last one wins
    ],
)
def test_parse_set_by_field_type(cls: type, pairs: list[str], expected: dict[str, Any]) -> None:
    assert parse_set(cls, pairs) == expected


@pytest.mark.parametrize(
    ("cls", "pairs", "needles"),
    [
        (NAV, ["collisions=maybe"], ["collisions", "'maybe'", "true/false/1/0/yes/no"]),
        (NAV, ["collisions=2"], ["collisions", "'2'", "true/false"]),
        (NAV, ["n_agents=1.5"], ["n_agents", "integer", "'1.5'"]),
        (NAV, ["dt=fast"], ["dt", "number", "'fast'"]),
        (NAV, ["dt=nan"], ["dt", "finite"]),
        (NAV, ["obstacle_size=1,2,3"], ["obstacle_size", "2 numbers"]),
        (NAV, ["map_size=big"], ["map_size", "none"]),
        (NAV, ["nope=1"], ["unknown --set key 'nope'", "allowed keys", "n_agents", "max_cycles"]),
        (NAV, ["body.nope=1"], ["'body.nope'", "BodyConfig", "radius"]),
        (NAV, ["dt.x=1"], ["dt", "not a sub-config", "body"]),
        (NAV, ["body=3"], ["body", "JSON object", "body.FIELD=VALUE"]),
        (NAV, ['comms={"loss": "x"}'], ["comms.loss", "number"]),
        (UAV, ["n_uavs=2", "n_agents=3"], ["n_agents", "n_uavs", "one name"]),
        (NAV, ["n_agents"], ["KEY=VALUE"]),
        (NAV, ["=3"], ["KEY=VALUE"]),
    ],
)
def test_parse_set_errors_name_the_key_and_allowed_values(cls: type, pairs: list[str], needles: list[str]) -> None:
    with pytest.raises(ValueError) as exc:
        parse_set(cls, pairs)
    msg = str(exc.value)
    assert "\n" not in msg and all(n in msg for n in needles), msg


def test_typed_set_values_build_the_scenario() -> None:
    values = parse_set(NAV, ["collisions=false", "n_agents=3", "body.radius=0.8", "max_cycles=7"])
    env = agentsim_env.make("navigation", **values)
    cfg = env.scenario.config
    assert cfg.collisions is False and cfg.n_agents == 3 and cfg.body.radius == 0.8 and cfg.max_steps == 7


def test_bad_set_value_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str], no_rollout: None) -> None:
    assert main(["run", "navigation", "--set", "collisions=maybe", "--out", str(tmp_path / "o")]) == 2
    assert "collisions" in _one_error_line(capsys)
    assert main(["evaluate", "--set", "n_uavs=1.5", "--out", str(tmp_path / "o")]) == 2
    assert "n_agents" in _one_error_line(capsys)


# ---------------------------------------------------------------------------------- trajectory PNG (5)
def test_run_writes_one_png_per_config(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "png"
    base = ["run", "navigation", "--episodes", "1", "--seed", "3", "--out", str(out), "--quiet"]
    assert main([*base, "--set", "n_agents=2", "max_steps=20"]) == 0
    assert main([*base, "--set", "n_agents=3", "max_steps=20"]) == 0
    assert main([*base, "--set", "max_cycles=20", "n_agents=3"]) == 0  # same config, other spelling
    files = sorted(p.name for p in out.iterdir())
    assert len(files) == 2, files
    tag = config_tag({"n_agents": 2, "max_steps": 20})
    assert f"navigation_go_to_goal_seed3{tag}.png" in files and len(tag) == 7
    printed = capsys.readouterr().out
    assert str(out / f"navigation_go_to_goal_seed3{tag}.png") in printed
    img = mpimg.imread(out / files[0])
    assert img.ndim == 3 and img.shape[0] > 200 and img.shape[1] > 200
    assert config_tag({}) == ""


def test_run_without_set_has_no_hash_and_names_the_policy(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    real = agentsim_env.make  # a tiny default config, so that the run without --set stays fast
    monkeypatch.setattr(agentsim_env, "make", lambda name, **kw: real(name, n_agents=2, max_steps=10, **kw))
    out = tmp_path / "png"
    assert main(["run", "rendezvous", "--policy", "random", "--episodes", "2", "--out", str(out), "--quiet"]) == 0
    assert [p.name for p in out.iterdir()] == ["rendezvous_random_seed0.png"]


def test_recorder_outcomes_and_plot(tmp_path: Path) -> None:
    env = agentsim_env.make("navigation", n_agents=4, max_steps=150)
    rec = TrajectoryRecorder()
    ep = run_episode(env, make_policy("navigation", env), 0, on_step=rec)
    traj = rec.result(env)
    assert traj.xy.shape == (ep.steps + 1, 4, 2) and traj.steps == ep.steps
    assert set(traj.outcome) <= set(OUTCOMES)
    assert traj.outcome.count("arrived") == ep.info_sums.get("arrived", 0)
    xmin, xmax, ymin, ymax = traj.bounds
    assert np.all((traj.xy[..., 0] >= xmin) & (traj.xy[..., 0] <= xmax))
    assert np.all((traj.last >= 0) & (traj.last <= ep.steps))
    assert traj.markers is not None and len(traj.markers[0]) == 4  # the goals, copied
    np.testing.assert_array_equal(traj.markers[0], env.world.task.goal[:4, :2])
    env.reset(seed=1)  # a new episode must not change what was recorded
    assert not np.array_equal(traj.markers[0], env.world.task.goal[:4, :2])
    path = plot_trajectories(traj, tmp_path / "t.png", "navigation | test")
    assert path.stat().st_size > 10_000


def test_run_episode_without_observer_is_unchanged() -> None:
    env = agentsim_env.make("navigation", n_agents=2, max_steps=15)
    pol = make_policy("navigation", env)
    a = run_episode(env, pol, 4)
    calls: list[int] = []
    b = run_episode(env, pol, 4, on_step=lambda e, infos: calls.append(len(infos)))
    assert (a.steps, a.returns, a.info_sums) == (b.steps, b.returns, b.info_sums)
    assert len(calls) == a.steps + 1 and calls[0] == 0


# ----------------------------------------------------------------------------------- warm-up (6)
def test_warmup_announces_a_cold_cache_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(cli_kernels, "_kernel_cache_dir", lambda: tmp_path / "cache")
    assert cli_kernels.kernels_cold()
    assert main(["warmup", "--quiet"]) == 0
    captured = capsys.readouterr()
    assert captured.err.strip() == COMPILE_NOTICE and captured.out == ""
    assert (tmp_path / "cache" / WARM_MARKER).is_file() and not cli_kernels.kernels_cold()
    assert main(["warmup"]) == 0
    captured = capsys.readouterr()
    assert COMPILE_NOTICE not in captured.err
    assert all(name in captured.out for name in agentsim_env.list_scenarios())
    (tmp_path / "cache" / WARM_MARKER).write_text("an older version\n")
    assert cli_kernels.kernels_cold()


def test_run_prints_the_notice_only_when_cold(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(cli_kernels, "_kernel_cache_dir", lambda: tmp_path / "cache")
    argv = ["run", "navigation", "--episodes", "1", *TINY_NAV, "--out", "", "--quiet"]
    assert main(argv) == 0
    assert capsys.readouterr().err.count(COMPILE_NOTICE) == 1
    assert main(argv) == 0
    assert COMPILE_NOTICE not in capsys.readouterr().err


def test_makefile_warms_up_after_install() -> None:
    text = (Path(__file__).resolve().parents[1] / "Makefile").read_text()
    install, _, _ = text.partition("install: $(STAMP)")
    assert "agentsim warmup" in install.split('-e ".[$(EXTRAS)]"', 1)[1]

"""The plug-in of ``docs/extending.md`` (``examples/plugin/``): the doc shows its files, registering it from code
works, and installed with pip its entry points reach the command line and the Python API."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from agentsim_env.core.plugins import POLICIES, SCENARIOS, STRATEGIES

ROOT = Path(__file__).resolve().parents[1]
PLUGIN = ROOT / "examples" / "plugin"
DOC = ROOT / "docs" / "extending.md"
DIST = "agentsim-beacon"
LANG = {".py": "python", ".toml": "toml"}


def _files() -> list[Path]:
    """The plug-in's source files (no build or cache leftovers)."""
    return sorted(
        p
        for p in PLUGIN.rglob("*")
        if p.is_file() and "__pycache__" not in p.parts and not any(s.endswith(".egg-info") for s in p.parts)
    )


def _run(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    env = {
        **os.environ,
        "PIP_NO_INDEX": "1",
        "PIP_DISABLE_PIP_VERSION_CHECK": "1",
        "AGENTSIM_QUIET_COMPILE": "1",
    }
    return subprocess.run(args, capture_output=True, text=True, cwd=cwd, env=env, timeout=300)


def _check(res: subprocess.CompletedProcess[str]) -> str:
    assert res.returncode == 0, f"{res.args} failed ({res.returncode}):\n{res.stdout}\n{res.stderr}"
    return res.stdout


def _installed() -> bool:
    return _run(sys.executable, "-m", "pip", "show", "--quiet", DIST).returncode == 0


def test_the_doc_shows_every_file_of_the_plugin() -> None:
    doc = DOC.read_text(encoding="utf-8")
    files = _files()
    assert {p.relative_to(PLUGIN).as_posix() for p in files} >= {
        "pyproject.toml",
        "register.py",
        "agentsim_beacon/__init__.py",
        "agentsim_beacon/scenario.py",
        "agentsim_beacon/policy.py",
        "agentsim_beacon/strategy.py",
    }
    for path in files:
        rel = path.relative_to(ROOT).as_posix()
        block = f"`{rel}`:\n\n```{LANG[path.suffix]}\n{path.read_text(encoding='utf-8')}```\n"
        assert block in doc, f"docs/extending.md does not show {rel} as it is"
    assert "\n## A release strategy\n" in doc and "release_strategies.md" in doc
    assert "docs/extending.md" in (ROOT / "README.md").read_text(encoding="utf-8")


@pytest.mark.slow
def test_registering_from_code_without_installing() -> None:
    if _installed():
        pytest.skip(f"{DIST} is installed: its entry points hold the names register.py takes")
    out = _check(_run(sys.executable, str(PLUGIN / "register.py")))
    assert "beacon: 3 of 3 agents arrived" in out


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """The plug-in installed into this venv with pip (offline, no dependencies), uninstalled afterwards."""
    assert not _installed(), f"{DIST} is already installed in {sys.prefix}; uninstall it first"
    copy = tmp_path_factory.mktemp("plugin") / "agentsim-beacon"
    shutil.copytree(PLUGIN, copy, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "build"))
    try:
        pip = (
            "-m",
            "pip",
            "install",
            "--no-deps",
            "--no-build-isolation",
            "--no-index",
            "--quiet",
            str(copy),
        )
        _check(_run(sys.executable, *pip, cwd=copy.parent))
        for registry in (SCENARIOS, POLICIES, STRATEGIES):
            registry.refresh()
        yield
    finally:
        _run(sys.executable, "-m", "pip", "uninstall", "--yes", "--quiet", DIST)
        for registry in (SCENARIOS, POLICIES, STRATEGIES):
            registry.refresh()
        for name in [m for m in sys.modules if m == "agentsim_beacon" or m.startswith("agentsim_beacon.")]:
            del sys.modules[name]


@pytest.mark.slow
def test_installed_plugin_runs_from_the_command_line(installed: None, tmp_path: Path) -> None:
    agentsim = str(Path(sys.executable).with_name("agentsim"))
    listed = _check(_run(agentsim, "scenarios"))
    assert any(line.startswith("beacon ") and "fly to a beacon" in line for line in listed.splitlines())
    helped = _check(_run(agentsim, "run", "--help"))
    assert "beacon       to_beacon (default)" in helped
    out = tmp_path / "out"
    args = ("run", "beacon", "--policy", "to_beacon", "--episodes", "1", "--quiet", "--out", str(out))
    ran = _check(_run(agentsim, *args, "--set", "n_agents=3", "max_steps=5"))
    assert "beacon: 1 episodes x 3 agents, policy=to_beacon" in ran and "| steps | 5.0 |" in ran
    assert len(list(out.glob("beacon_to_beacon_seed0_*.png"))) == 1  # the trajectories of the first episode
    bad = _run(agentsim, "run", "beacon", "--policy", "meet", "--episodes", "1", "--out", "")
    assert bad.returncode != 0 and "--policy must be one of ['to_beacon'] for 'beacon'" in bad.stderr
    evaluated = tmp_path / "evaluation"
    ev = ("evaluate", "--zones", "tiny", "--strategies", "beacon_ring", "B2_rings", "--seeds", "1")
    _check(_run(agentsim, *ev, "--out", str(evaluated), "--no-plots", "--quiet"))
    summary = (evaluated / "summary.md").read_text(encoding="utf-8")
    assert "| `beacon_ring` |" in summary and "| `B2_rings` |" in summary  # ranked beside a shipped one
    assert "beacon_ring" in _check(_run(agentsim, "evaluate", "--help"))


@pytest.mark.slow
def test_installed_plugin_through_the_python_api(installed: None) -> None:
    import agentsim_env
    from agentsim_env.policies.registry import baseline_names, make_policy

    assert "beacon" in agentsim_env.list_scenarios()
    assert SCENARIOS.origin("beacon") == "entry point 'agentsim_beacon.scenario:Beacon' of agentsim-beacon"
    assert baseline_names("beacon") == ["to_beacon"] and "to_beacon" not in baseline_names("rendezvous")
    env = agentsim_env.make("beacon", n_agents=3, max_steps=60)
    policy = make_policy("beacon", env, "to_beacon")
    assert type(policy).__name__ == "ToBeaconPolicy" and type(policy).scenarios == ("beacon",)
    obs, infos = env.reset(seed=0)
    arrived = 0
    while env.agents:
        obs, rewards, terminations, truncations, infos = env.step(policy.act(obs))
        arrived += sum(int(info["arrived"]) for info in infos.values())
    assert arrived == 3
    assert env.rollout("to_beacon", 60, seed=0).info_sums["arrived"] == 3  # by name, as a shard builds it
    assert "beacon_ring" in STRATEGIES.names()
    from agentsim_env.policies.release import strategy_class, strategy_names

    assert strategy_names()[-1] == "beacon_ring" and "beacon_ring" in baseline_names("uav_release")
    ring_cls = strategy_class("beacon_ring")
    assert ring_cls is STRATEGIES.get("beacon_ring") and ring_cls().radius_share == 0.6
    with pytest.raises(ValueError, match="radius_share"):
        ring_cls(radius_share=1.5)
    uav = agentsim_env.make("uav_release", zones="tiny", n_uavs=2, payload=12, wind={"mean_speed": 0.0})
    flown = make_policy("uav_release", uav, "beacon_ring")
    obs, _ = uav.reset(seed=0)
    flown.reset(0)
    for _ in range(3000):
        obs, *_ = uav.step(flown.act({a: obs[a] for a in uav.agents}))
        if flown.mission_complete and uav.world.payloads.objects.n_falling == 0:  # type: ignore[attr-defined]
            break
    objects = uav.world.payloads.objects
    assert int(objects.get("landed")[: objects.count].sum()) == 20  # every sensor of the tiny zone landed
    uav.close()
    with pytest.raises(ValueError, match=r"'beacon' is already taken \(entry point "):
        agentsim_env.register_scenario("beacon", "agentsim_beacon.scenario:Beacon")

"""The adapters for other RL stacks (RLlib, TorchRL, BenchMARL) without those stacks installed: each raises
ImportError with its install hint when its stack is missing, the RLlib env ends episodes correctly (checked over
stand-in ray modules), and the ecosystem examples (those three, CleanRL, skrl and AgileRL) exist, take
``--frames`` and are run by ``make test-ecosystem``, each stack by its own ``make test-ecosystem-<stack>``. The
examples themselves run in their own environments (``make test-ecosystem``)."""

from __future__ import annotations

import ast
import importlib
import re
import sys
import types
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
# adapter module -> (the stack's top-level modules, the extra named in the hint)
ADAPTERS = {
    "agentsim_env.env.rllib": (("ray",), "rllib"),
    "agentsim_env.env.torchrl": (("torchrl",), "torchrl"),
    "agentsim_env.env.benchmarl": (("benchmarl", "torchrl"), "benchmarl"),
}
# example -> the stack (venv, extra) it runs in
EXAMPLES = {
    "rllib_ppo_shared.py": "rllib",
    "torchrl_mappo.py": "torchrl",
    "benchmarl_mappo.py": "benchmarl",
    "cleanrl_ppo.py": "cleanrl",
    "skrl_mappo.py": "skrl",
    "agilerl_matd3.py": "agilerl",
}
# stack -> the top-level modules its example imports (and no other stack's)
STACK_IMPORTS = {
    "rllib": {"ray"},
    "torchrl": {"torchrl", "tensordict"},
    "benchmarl": {"benchmarl"},
    "cleanrl": {"tyro"},  # CleanRL is a single file, not a package: tyro is its own import
    "skrl": {"skrl"},
    "agilerl": {"agilerl"},
}
# stack -> the package its constraints must pin
STACK_PIN = {
    "rllib": "ray",
    "torchrl": "torchrl",
    "benchmarl": "benchmarl",
    "cleanrl": "tyro",
    "skrl": "skrl",
    "agilerl": "agilerl",
}
STACK_MODULES = ("ray", "torchrl", "tensordict", "benchmarl", "tyro", "skrl", "agilerl")


@pytest.mark.parametrize("module", sorted(ADAPTERS))
def test_adapter_without_its_stack_raises_the_install_hint(module: str, monkeypatch: pytest.MonkeyPatch) -> None:
    blocked, extra = ADAPTERS[module]
    for name in blocked:  # None in sys.modules makes `import name` raise ImportError
        monkeypatch.setitem(sys.modules, name, None)
    monkeypatch.delitem(sys.modules, module, raising=False)
    with pytest.raises(ImportError, match=re.escape(f'pip install "agentsim-env[{extra}]"')):
        importlib.import_module(module)


def test_no_other_module_imports_the_stacks() -> None:
    """Each stack is imported by its adapter only (and the examples), never by the rest of the package; the learning
    benchmark's BenchMARL worker (``train/benchmarl_worker.py``) is a script run by BenchMARL's own Python as a
    subprocess, which the package never imports (checked below)."""
    worker = "benchmarl_worker.py"
    allowed = {
        "ray": {"env/rllib.py", "distributed"},
        "torchrl": {"env/torchrl.py", worker},
        "tensordict": set(),
        "benchmarl": {"env/benchmarl.py", worker},
    }
    bad = []
    for folder in (ROOT / "agentsim_env", ROOT / "policies", ROOT / "train"):
        for path in folder.rglob("*.py"):
            rel = path.relative_to(folder).as_posix()
            for top in _imported_tops(path):
                if top in allowed and not any(rel == a or rel.startswith(a + "/") for a in allowed[top]):
                    bad.append(f"{folder.name}/{rel} imports {top}")
            if "benchmarl_worker" in _imported_tops(path) or "import benchmarl_worker" in path.read_text("utf-8"):
                bad.append(f"{folder.name}/{rel} imports the BenchMARL worker")
    assert not bad, bad


def test_core_install_and_default_extras_leave_the_stacks_out() -> None:
    tomllib = pytest.importorskip("tomllib")
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    assert set(STACK_IMPORTS) <= set(extras)
    default = re.search(r"^EXTRAS\s*:?=\s*(\S+)", (ROOT / "Makefile").read_text(), re.M)
    assert default is not None
    deps = list(project["dependencies"])
    for extra in default.group(1).split(","):
        deps += extras[extra]
    names = {re.split(r"[\[<>=!~; ]", d, maxsplit=1)[0].lower() for d in deps}
    assert not names & {"torchrl", "tensordict", "benchmarl", "tyro", "skrl", "agilerl", "peft"}, names
    # plain Ray (the distributed shards' extra, whose tests run in make test) is in; RLlib stays out
    assert not [d for d in deps if "rllib" in d.lower()], deps
    assert "ray" not in {re.split(r"[\[<>=!~; ]", d, maxsplit=1)[0].lower() for d in project["dependencies"]}


@pytest.mark.parametrize("stack", sorted(set(EXAMPLES.values())))
def test_constraints_pin_the_cpu_torch_and_the_stack(stack: str) -> None:
    pins = dict(
        line.split("==", 1)
        for line in (ROOT / "examples" / f"constraints-{stack}.txt").read_text().splitlines()
        if "==" in line and not line.startswith("#")
    )
    pins = {k.lower(): v for k, v in pins.items()}
    assert pins["torch"] == "2.13.0+cpu"
    assert STACK_PIN[stack] in pins
    assert not [k for k in pins if k.startswith("nvidia")], "a CUDA package in the pins"


@pytest.mark.parametrize("example", sorted(EXAMPLES))
def test_example_exists_takes_frames_and_imports_only_its_stack(example: str) -> None:
    path = ROOT / "examples" / example
    source = path.read_text()
    assert '"--frames"' in source
    tops = _imported_tops(path)
    own = STACK_IMPORTS[EXAMPLES[example]]
    assert own & tops and not (tops & set(STACK_MODULES)) - own, tops
    assert example in (ROOT / "examples" / "README.md").read_text()


def test_make_target_runs_every_example_in_its_venv() -> None:
    text = (ROOT / "Makefile").read_text()
    whole = re.search(r"^test-ecosystem:(.*)$", text, re.M)
    assert whole is not None, "no test-ecosystem target"
    for example, stack in EXAMPLES.items():
        # one target per stack, built on that stack's venv, and test-ecosystem runs them all
        recipe = re.search(rf"^test-ecosystem-{stack}:(.*)\n((?:\t.*\n?)+)", text, re.M)
        assert recipe is not None, f"no test-ecosystem-{stack} target"
        assert f"$(ECO)/{stack}/.installed" in recipe.group(1), stack
        assert re.search(rf"{stack},examples/{re.escape(example)} --frames", recipe.group(2)), example
        assert f"test-ecosystem-{stack}" in whole.group(1).split(), stack
    assert ".venv-eco/" in (ROOT / ".gitignore").read_text().splitlines()
    ci = (ROOT / ".ci" / "run").read_text()
    assert ci.index("make test\n") < ci.index("make test-ecosystem")


def _imported_tops(path: Path) -> set[str]:
    """Top-level names of every module a file imports (lazy imports included)."""
    tops = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            tops |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            tops.add(node.module.split(".")[0])
    return tops


# ---------------------------------------------------------------- the RLlib env over stand-in ray modules
class _StandInParallelPettingZooEnv:
    """What ``AgentSimRLlibEnv`` uses of RLlib's ``ParallelPettingZooEnv``: it keeps the env and resets it."""

    def __init__(self, env: Any) -> None:
        self.par_env = env
        self.par_env.reset()


@pytest.fixture
def rllib_adapter(monkeypatch: pytest.MonkeyPatch) -> Iterator[types.ModuleType]:
    names = {
        "ray.rllib.algorithms.ppo": {"PPOConfig": object},
        "ray.rllib.connectors.env_to_module": {"FlattenObservations": object},
        "ray.rllib.core.rl_module.multi_rl_module": {"MultiRLModuleSpec": object},
        "ray.rllib.core.rl_module.rl_module": {"RLModuleSpec": object},
        "ray.rllib.env.wrappers.pettingzoo_env": {"ParallelPettingZooEnv": _StandInParallelPettingZooEnv},
    }
    for full, attrs in names.items():
        parts = full.split(".")
        for i in range(1, len(parts) + 1):
            name = ".".join(parts[:i])
            if not isinstance(sys.modules.get(name), types.ModuleType) or name in names:
                monkeypatch.setitem(sys.modules, name, types.ModuleType(name))
        for k, v in attrs.items():
            setattr(sys.modules[full], k, v)
    monkeypatch.delitem(sys.modules, "agentsim_env.env.rllib", raising=False)
    module = importlib.import_module("agentsim_env.env.rllib")
    yield module
    sys.modules.pop("agentsim_env.env.rllib", None)


class _ScriptedEnv:
    """A ParallelEnv stand-in whose step returns scripted end flags and drops the agents that ended."""

    def __init__(self, terms: dict[str, bool], truncs: dict[str, bool], agents: list[str]) -> None:
        self.terms, self.truncs, self.agents = terms, truncs, agents

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        self.agents = [a for a in self.agents if not (self.terms[a] or self.truncs[a])]
        keys = list(self.terms)
        return {a: 0 for a in keys}, {a: 0.0 for a in keys}, dict(self.terms), dict(self.truncs), {}


@pytest.mark.parametrize(
    ("terms", "truncs", "expected"),
    [
        ({"a": True, "b": False}, {"a": False, "b": False}, (False, False)),  # b goes on
        ({"a": True, "b": True}, {"a": False, "b": False}, (True, False)),  # all terminated
        ({"a": False, "b": False}, {"a": True, "b": True}, (False, True)),  # time limit
        ({"a": True, "b": False}, {"a": False, "b": True}, (False, True)),  # a mix: over all the same
    ],
)
def test_rllib_env_ends_the_episode_when_no_agent_is_left(
    rllib_adapter: types.ModuleType, terms: dict, truncs: dict, expected: tuple[bool, bool]
) -> None:
    env = rllib_adapter.AgentSimRLlibEnv({"scenario": "navigation", "n_agents": 2})
    assert env.par_env.obs_format == "dict" and env.par_env.action_format == "flat"
    env.par_env = _ScriptedEnv(terms, truncs, ["a", "b"])
    _, _, t, u, _ = env.step({"a": 0, "b": 0})
    assert (t["__all__"], u["__all__"]) == expected


def test_rllib_env_steps_the_real_env_to_the_end(rllib_adapter: types.ModuleType) -> None:
    env = rllib_adapter.AgentSimRLlibEnv({"scenario": "navigation", "n_agents": 3, "max_steps": 4})
    obs, _ = env.par_env.reset(seed=0)
    assert set(obs["agent_0"]) >= {"self", "lidar", "task"}
    for step in range(4):
        _, _, t, u, _ = env.step({a: [0.0, 0.0, 0.0] for a in env.par_env.agents})
        assert u["__all__"] == (step == 3) and not t["__all__"]
    with pytest.raises(ValueError, match="unknown"):
        rllib_adapter.AgentSimRLlibEnv({"scenario": "navigation", "no_such_key": 1})

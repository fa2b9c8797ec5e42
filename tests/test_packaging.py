"""Packaging.

``policies/`` and ``train/`` install as ``agentsim_env.policies`` and ``agentsim_env.train``, so a user's own
``policies/`` or ``train/`` folder cannot shadow them; the evaluation package finds the policies through its
``strategies`` registry.
"""

from __future__ import annotations

import importlib.metadata
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Repository folders installed under another package name.
MOVED = {"policies": "agentsim_env.policies", "train": "agentsim_env.train"}


def _python(code: str, cwd: Path, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
    """Run ``code`` in a fresh interpreter of this environment, in ``cwd``, without PYTHONPATH."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout
    )


def _user_folders(root: Path) -> None:
    """A user's project with its own ``policies`` and ``train`` packages."""
    for name in MOVED:
        (root / name).mkdir()
        (root / name / "__init__.py").write_text(f"OWNER = 'user {name}'\n")
    (root / "train" / "ppo.py").write_text("raise RuntimeError('the user module was imported')\n")


def test_user_folders_do_not_shadow_the_policies(tmp_path: Path) -> None:
    _user_folders(tmp_path)
    code = """
import os
import policies, train
assert policies.OWNER == "user policies" and train.OWNER == "user train"
from agentsim_env.policies.navigation import GoToGoalPolicy
from agentsim_env.policies.registry import make_policy
import agentsim_env.policies, agentsim_env.train
for mod in (agentsim_env.policies, agentsim_env.train):
    assert not mod.__file__.startswith(os.getcwd()), mod.__file__
    assert not hasattr(mod, "OWNER")
print("ok", GoToGoalPolicy.__module__, make_policy.__module__)
"""
    res = _python(code, tmp_path)
    assert res.returncode == 0, res.stderr
    assert "ok agentsim_env.policies.navigation agentsim_env.policies.registry" in res.stdout


def test_no_top_level_policies_or_train(tmp_path: Path) -> None:
    code = """
import importlib.util
print([n for n in ("policies", "train") if importlib.util.find_spec(n) is not None])
import agentsim_env.policies.release, agentsim_env.train
"""
    res = _python(code, tmp_path)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]"
    top = importlib.metadata.distribution("agentsim-env").read_text("top_level.txt")
    assert top is not None and top.split() == ["agentsim_env"]


def _package_folders() -> set[str]:
    """Dotted names of the folders that hold files (``__pycache__`` aside), as they install."""
    names: set[str] = set()
    for top, dotted in {"agentsim_env": "agentsim_env", **MOVED}.items():
        for folder in [ROOT / top, *(p for p in (ROOT / top).rglob("*") if p.is_dir())]:
            rel = folder.relative_to(ROOT / top).parts
            if any(part == "__pycache__" or part.startswith(".") for part in rel):
                continue
            files = (f for f in folder.rglob("*") if f.is_file() and "__pycache__" not in f.parts)
            if any(True for _ in files):
                names.add(".".join((dotted, *rel)))
    return names


def test_pyproject_lists_every_package() -> None:
    tomllib = pytest.importorskip("tomllib")
    setuptools_cfg = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    assert setuptools_cfg["package-dir"] == {v: k for k, v in MOVED.items()}
    listed = set(setuptools_cfg["packages"])
    assert listed == _package_folders(), "add the new package folders to [tool.setuptools] packages"


def test_wheel_installs_policies_and_train_inside_the_package(tmp_path: Path) -> None:
    src = tmp_path / "src"
    skip = shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc")
    for name in ("agentsim_env", *MOVED):
        shutil.copytree(ROOT / name, src / name, ignore=skip)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    out = tmp_path / "wheel"
    cmd = [
        sys.executable,
        "-m",
        "pip",
        "wheel",
        "-q",
        "--no-deps",
        "--no-build-isolation",
        "--no-index",
        "-w",
        str(out),
        str(src),
    ]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    (wheel,) = out.glob("*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"agentsim_env"}
    assert "agentsim_env/train/configs/navigation.yaml" in names  # the shipped training configs
    for top, dotted in MOVED.items():
        for f in (ROOT / top).rglob("*.py"):
            rel = f.relative_to(ROOT / top).as_posix()
            assert f"{dotted.replace('.', '/')}/{rel}" in names
    assert "agentsim_env/uav/data/zones_default.json" in names
    # the web pages and three.js ship in the package (the viewer works with no network)
    static = ROOT / "agentsim_env" / "render" / "web" / "static"
    designer = ROOT / "agentsim_env" / "uav" / "designer" / "static"
    for f in [*static.glob("*.*"), *(static / "vendor").glob("*.*"), *designer.glob("*.*")]:
        assert f"agentsim_env/{f.relative_to(ROOT / 'agentsim_env').as_posix()}" in names, f


# ------------------------------------------------------------------------------------------ registry
# (the layering itself, no cycles and nothing below the CLI importing the policies, is tests/test_layers.py)
def test_evaluation_finds_the_policies_through_its_registry() -> None:
    from agentsim_env.policies.registry import baseline_names, make_policy
    from agentsim_env.uav.evaluation import strategies

    assert strategies.policy_factory() is make_policy
    assert strategies.strategy_names("uav_release") == baseline_names("uav_release")
    with pytest.raises(ValueError, match="module:attribute"):
        strategies.load("no_colon")
    with pytest.raises(ValueError, match="cannot load"):
        strategies.load("agentsim_env.policies.registry:nope")

"""The package's layers (DESIGN section 2) hold: each package imports only packages below it, and no module
imports itself back through others. Every import counts, lazy ones inside functions included."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# package -> layer; a package may import its own modules and packages of lower layers only
LAYERS: dict[str, float] = {
    "_numba_cache": 0,
    "_compile_notice": 0,  # the one-line notice when a kernel compiles; imports only numba and the standard library
    "core": 0,
    "motion": 1,
    "physics": 1,
    "payloads": 1,
    "sensors": 1,
    "comms": 1,
    "groups": 1,
    "wsn": 1,
    "sim": 2,
    "scenarios": 3,
    "wrappers": 3.5,  # the wrapper bases (ParallelEnvWrapper, BatchedEnvWrapper): below render's RecordVideo
    "render": 4,
    "env": 5,
    "": 5.5,  # agentsim_env/__init__.py: the public entry points (make, list_scenarios) over env and scenarios
    "recorder": 6,
    "evaluation": 6,
    "distributed": 6,
    "policies": 7,
    "train": 8,
    "cli": 9,  # the command line: over everything, train's subcommand included
    "outdirs": 0.5,  # output folders checked before work (cli and the store's export); imports nothing of ours
    "cli_set": 7.5,  # the --set parser of cli; imports nothing from the package
    "cli_replay": 7.5,  # the replay subcommand of cli; over the recorder and render
    "cli_store": 7.5,  # the export and runs subcommands of cli; over the recorder
    "cli_view": 7.7,  # the view and zones subcommands of cli; over the recorder, render, policies and cli_set
    "warmup": 7.6,
    "cli_live": 4.5,  # the run's display check and signal handling of cli; over render
    "cli_kernels": 5.6,  # whether numba's cache is warm, the compile notice; over the package's version
    "cli_run": 8.5,  # the run subcommand of cli; over policies, render, the recorder, distributed and cli_live
    "gymnasium_envs": 5.6,
    "zoo": 5.6,  # each scenario as a PettingZoo-style module (navigation_v0, ...); over env  # importing it registers the Gymnasium ids; over env  # agentsim warmup's runs; over env, distributed and policies
}
# folders installed under the package's name (pyproject's package-dir)
MAPPED = {"policies": ROOT / "policies", "train": ROOT / "train"}


def modules() -> dict[str, Path]:
    """Every module of the installed package: dotted name -> file."""
    out = {}
    for path in (ROOT / "agentsim_env").rglob("*.py"):
        rel = path.relative_to(ROOT).with_suffix("")
        out[".".join(rel.parts).removesuffix(".__init__")] = path
    for name, folder in MAPPED.items():
        for path in folder.rglob("*.py"):
            rel = path.relative_to(folder).with_suffix("")
            out[".".join(("agentsim_env", name, *rel.parts)).removesuffix(".__init__")] = path
    return out


def imports(path: Path, module: str) -> set[str]:
    """Absolute names of the agentsim_env modules a file imports (anywhere in it)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    pkg = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = pkg.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([base] if base else []))
            found.add(base)
            found |= {f"{base}.{a.name}" for a in node.names}
    return {f for f in found if f == "agentsim_env" or f.startswith("agentsim_env.")}


def package_of(module: str) -> str:
    """The layer key of a module: its first component below agentsim_env ("" for the package itself)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def resolve(name: str, known: dict[str, Path]) -> str | None:
    """The module an imported name refers to (``from pkg.mod import func`` -> ``pkg.mod``)."""
    while name and name not in known:
        name = name.rpartition(".")[0]
    return name or None


def graph() -> dict[str, set[str]]:
    """Module -> modules it imports."""
    known = modules()
    out = {}
    for mod, path in known.items():
        targets = {resolve(n, known) for n in imports(path, mod)}
        out[mod] = {t for t in targets if t is not None and t != mod}
    return out


def test_every_package_has_a_layer() -> None:
    missing = sorted({package_of(m) for m in modules()} - set(LAYERS))
    assert not missing, f"packages without a layer in this test: {missing}"


def test_each_package_imports_only_lower_layers() -> None:
    bad = []
    for mod, targets in graph().items():
        src = package_of(mod)
        for t in targets:
            dst = package_of(t)
            if dst != src and LAYERS[dst] >= LAYERS[src]:
                bad.append(f"{mod} (layer {LAYERS[src]}) -> {t} (layer {LAYERS[dst]})")
    assert not bad, "layer violations:\n" + "\n".join(sorted(bad))


def test_no_import_cycles() -> None:
    g = graph()
    state: dict[str, int] = {}
    stack: list[str] = []
    cycles = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for t in sorted(g.get(m, ())):
            if state.get(t) == 1:
                cycles.append(stack[stack.index(t) :] + [t])
            elif t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(g):
        if m not in state:
            visit(m)
    assert not cycles, "import cycles:\n" + "\n".join(" -> ".join(c) for c in cycles)


def test_the_checker_sees_violations(tmp_path: Path) -> None:
    """The parser finds lazy and relative imports (so the tests above can fail)."""
    f = tmp_path / "mod.py"
    f.write_text("def f():\n    from agentsim_env.env.vector import BatchedEnv\nfrom ..sim import world\n")
    found = imports(f, "agentsim_env.core.mod")
    assert "agentsim_env.env.vector" in found and "agentsim_env.sim" in found

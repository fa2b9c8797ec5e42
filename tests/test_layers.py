"""The package's layers (DESIGN section 2) hold: each package imports only packages below it, and no module
imports itself back through others. Every import counts, lazy ones inside functions included."""

from __future__ import annotations

import ast
from pathlib import Path

from agentsim_env._moved import MOVED

ROOT = Path(__file__).resolve().parents[1]
# package -> layer; a package may import its own modules and packages of lower layers only. A top-level module
# (cli_run.py, ...) is a package of its own here.
LAYERS: dict[str, int] = {
    # 0: nothing of ours
    "_numba_cache": 0,  # where numba caches the package's kernels
    "_moved": 0,  # the import hook of the UAV modules' old paths; imports nothing of the package
    "_compile_notice": 0,  # the one-line notice when a kernel compiles; numba and the standard library only
    "core": 0,
    "outdirs": 0,  # output folders checked before work (cli, uav's evaluate, the store's export)
    "cli_set": 0,  # the --set parser (KEY=VALUE against a config class) of cli, train and uav's subcommands
    # 1: the subsystems, over core
    "motion": 1,
    "physics": 1,
    "payloads": 1,
    "sensors": 1,
    "comms": 1,
    "groups": 1,
    "sim": 2,  # the World: the step's pipeline over the subsystems
    "scenarios": 3,  # the Scenario contract, the registry and the generic scenarios; over sim
    "wrappers": 4,  # the wrapper bases (ParallelEnvWrapper, BatchedEnvWrapper); below render's RecordVideo
    "render": 5,  # rgb_array renderer, the web viewer's server (and bind options); over sim, not scenarios
    "env": 6,  # the PettingZoo env, spaces, batched env; over scenarios, sim and render
    "cli_live": 6,  # the run's display check and signal handling of cli; over render
    "": 7,  # agentsim_env/__init__.py: the public entry points (make, list_scenarios) over env and scenarios
    "distributed": 7,  # one simulation over Ray shards; over env
    "gymnasium_envs": 7,  # importing it registers the Gymnasium ids; over env
    "zoo": 7,  # each scenario as a PettingZoo-style module (navigation_v0, ...); over env
    "recorder": 8,  # the store, replay and export; over the package's make, env and render
    "cli_kernels": 8,  # whether numba's cache is warm, the compile notice; over the package's version
    "uav": 9,  # the UAV case study; over scenarios, render, env, the recorder, cli_kernels and cli_set
    "cli_replay": 9,  # the replay subcommand of cli; over the recorder and render
    "cli_store": 9,  # the export and runs subcommands of cli; over the recorder
    "policies": 10,  # the algorithms library; over env and uav (the release strategies)
    "train": 11,  # training entry points; over policies
    "warmup": 11,  # agentsim warmup's runs; over env, distributed and policies
    "cli_view": 11,  # the view subcommand of cli; over the recorder, render, policies and cli_set
    "cli_run": 11,  # the run subcommand of cli; over policies, render, the recorder, distributed and cli_live
    "cli": 12,  # the command line: over everything (train's subcommand, uav's by name: SUBCOMMAND_PROVIDERS)
}
# the old paths of modules that moved into uav (old module -> new module): no file stands there; the package's
# import hook (agentsim_env._moved) resolves each to its new module with a DeprecationWarning
DEPRECATED: dict[str, str] = MOVED
# the only modules outside uav that import it: the release strategies
UAV_IMPORTERS = "agentsim_env.policies.release"
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


def test_layers_are_whole_numbers() -> None:
    assert all(type(v) is int and v >= 0 for v in LAYERS.values()), LAYERS


def test_old_paths_have_no_file_and_nothing_imports_them() -> None:
    g = graph()
    standing = sorted(set(DEPRECATED) & set(g))
    assert not standing, f"a file stands at an old path (the import hook serves it): {standing}"
    gone = sorted(set(DEPRECATED.values()) - set(g))
    assert not gone, f"old paths pointing at no module: {gone}"
    importers = sorted(f"{m} -> {t}" for m, path in modules().items() for t in imports(path, m) if t in DEPRECATED)
    assert not importers, f"modules importing a deprecated path: {importers}"


def test_only_the_release_strategies_import_uav() -> None:
    outside = sorted(
        f"{m} -> {t}"
        for m, ts in graph().items()
        for t in ts
        if package_of(t) == "uav"
        and package_of(m) != "uav"
        and not (m == UAV_IMPORTERS or m.startswith(UAV_IMPORTERS + "."))
    )
    assert not outside, "generic code importing the UAV case study:\n" + "\n".join(outside)


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


def test_no_cycles_between_packages() -> None:
    edges: dict[str, set[str]] = {}
    for mod, targets in graph().items():
        for t in targets:
            if package_of(t) != package_of(mod):
                edges.setdefault(package_of(mod), set()).add(package_of(t))
    done: set[str] = set()

    def walk(pkg: str, path: list[str]) -> None:
        assert pkg not in path, "packages importing each other round: " + " -> ".join([*path, pkg])
        if pkg not in done:
            for nxt in sorted(edges.get(pkg, ())):
                walk(nxt, [*path, pkg])
            done.add(pkg)

    for pkg in sorted(edges):
        walk(pkg, [])

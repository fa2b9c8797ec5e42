"""The notebooks of ``notebooks/``: stored clean (fast tests) and executed end to end (slow tests).

Every ``notebooks/*.ipynb`` is picked up. The fast tests check that each file is a valid nbformat v4 notebook
stored without outputs or execution counts, that its code imports nothing from the test suite, and that
``notebooks/README.md`` names it. The slow tests execute each notebook with nbclient in a fresh kernel of the
interpreter running the tests, with a temporary folder as working directory (nothing is written into the
repository), a time limit per cell and the matplotlib inline backend; they need the ``notebooks`` extra
(``pip install -e ".[notebooks]"``) and are skipped without it. A notebook that uses ``agentsim_env.train``
also needs the ``train`` extra.
"""

from __future__ import annotations

import ast
import importlib.util
import json
import os
import time
from pathlib import Path
from typing import Any

import pytest

NOTEBOOKS_DIR = Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOKS = sorted(NOTEBOOKS_DIR.glob("*.ipynb"))
CELL_TIMEOUT_S = 300
#: The slowest a notebook may take here (all four together must stay under 10 minutes).
NOTEBOOK_BUDGET_S = 300
#: Modules a notebook needs beyond the ``notebooks`` extra, by what its code imports.
EXTRA_MODULES = {"agentsim_env.train": ("torch", "stable_baselines3")}


def _load(path: Path) -> dict[str, Any]:
    with path.open(encoding="utf-8") as f:
        return json.load(f)


def _code(nb: dict[str, Any]) -> str:
    """The notebook's code cells as one Python source, IPython magics and shell lines left out."""
    lines = []
    for cell in nb["cells"]:
        if cell["cell_type"] != "code":
            continue
        src = "".join(cell["source"]) if isinstance(cell["source"], list) else cell["source"]
        lines += [ln for ln in src.splitlines() if not ln.lstrip().startswith(("%", "!"))]
    return "\n".join(lines)


def _imported_modules(source: str) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                names.add("." * node.level + (node.module or ""))
            elif node.module:
                names.add(node.module)
    return names


ids = [p.name for p in NOTEBOOKS]


def test_notebooks_found() -> None:
    assert len(NOTEBOOKS) >= 3, f"expected the notebooks in {NOTEBOOKS_DIR}, found {ids}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=ids)
def test_notebook_is_stored_clean(path: Path) -> None:
    nb = _load(path)
    assert nb["nbformat"] == 4
    assert nb["metadata"]["kernelspec"]["name"] == "python3"
    assert nb["cells"], "empty notebook"
    for i, cell in enumerate(nb["cells"]):
        if cell["cell_type"] == "code":
            assert cell["outputs"] == [], f"cell {i} has stored outputs"
            assert cell["execution_count"] is None, f"cell {i} has an execution count"
        assert "attachments" not in cell or not cell["attachments"], f"cell {i} has attachments"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=ids)
def test_notebook_imports_nothing_from_the_tests(path: Path) -> None:
    modules = _imported_modules(_code(_load(path)))
    bad = sorted(m for m in modules if m.split(".")[0] in {"tests", "conftest"} or m.startswith("."))
    assert not bad, f"{path.name} imports {bad}"
    assert "sys.path" not in _code(_load(path)), f"{path.name} edits sys.path"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=ids)
def test_notebook_is_valid_nbformat(path: Path) -> None:
    nbformat = pytest.importorskip("nbformat", reason="nbformat not installed: pip install -e '.[notebooks]'")
    nb = nbformat.read(path, as_version=nbformat.NO_CONVERT)
    nbformat.validate(nb)
    assert nb.nbformat == 4


def test_readme_lists_every_notebook() -> None:
    text = (NOTEBOOKS_DIR / "README.md").read_text(encoding="utf-8")
    missing = [p.name for p in NOTEBOOKS if p.name not in text]
    assert not missing, f"notebooks/README.md does not name {missing}"


# ------------------------------------------------------------------------------------------ execution
def _kernel_manager(spec_dir: Path) -> Any:
    """A kernel manager whose ``python3`` kernel runs this interpreter (not whatever ``python3`` is on PATH)."""
    from ipykernel.kernelspec import write_kernel_spec
    from jupyter_client.kernelspec import KernelSpecManager
    from jupyter_client.manager import AsyncKernelManager

    write_kernel_spec(spec_dir / "python3")  # its argv starts with sys.executable
    ksm = KernelSpecManager(kernel_dirs=[str(spec_dir)], ensure_native_kernel=False)
    return AsyncKernelManager(kernel_name="python3", kernel_spec_manager=ksm)


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=ids)
def test_notebook_runs(path: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    reason = "nbclient not installed: pip install -e '.[notebooks]'"
    nbclient = pytest.importorskip("nbclient", reason=reason)
    nbformat = pytest.importorskip("nbformat", reason=reason)
    pytest.importorskip("ipykernel", reason=reason)
    pytest.importorskip("pandas", reason=reason)
    source = _code(_load(path))
    for prefix, needed in EXTRA_MODULES.items():
        if prefix in source:
            missing = [m for m in needed if importlib.util.find_spec(m) is None]
            if missing:
                pytest.skip(f"{path.name} needs {missing} (pip install -e '.[train]')")

    # the kernel inherits the environment: one thread each, inline figures, no window
    for var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.setenv(var, os.environ.get(var, "1"))
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    work, scratch = tmp_path / "work", tmp_path / "tmp"
    work.mkdir()
    scratch.mkdir()
    monkeypatch.setenv("TMPDIR", str(scratch))  # the notebooks' temporary folders are cleaned with tmp_path
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        nb,
        km=_kernel_manager(tmp_path / "kernels"),
        timeout=CELL_TIMEOUT_S,
        allow_errors=False,
        resources={"metadata": {"path": str(work)}},
    )
    t0 = time.perf_counter()
    client.execute()
    elapsed = time.perf_counter() - t0
    print(f"{path.name}: {elapsed:.1f} s")
    assert elapsed < NOTEBOOK_BUDGET_S, f"{path.name} took {elapsed:.0f} s (budget {NOTEBOOK_BUDGET_S} s)"
    assert not list(work.iterdir()), f"{path.name} wrote into its working folder: {list(work.iterdir())}"
    images = sum("image/png" in out.get("data", {}) for c in nb.cells if c.cell_type == "code" for out in c.outputs)
    assert images, f"{path.name} displayed no figure"

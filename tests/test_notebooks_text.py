"""What the notebooks say and list matches what the library does (fast: read, not executed)."""

from __future__ import annotations

import json
from pathlib import Path

NOTEBOOKS_DIR = Path(__file__).resolve().parents[1] / "notebooks"


def _cells(name: str, kind: str) -> list[str]:
    nb = json.loads((NOTEBOOKS_DIR / name).read_text(encoding="utf-8"))
    return ["".join(c["source"]) for c in nb["cells"] if c["cell_type"] == kind]


def test_release_notebook_says_where_a_mission_ends() -> None:
    text = " ".join(" ".join(_cells("02_release_strategies.ipynb", "markdown")).split())
    # fly_mission stops when the sensors are down (or the policy is done, or max_steps); nobody flies home
    assert "back at base" not in text
    assert "do not fly back" in text and "max_steps" in text


def test_train_notebook_lists_checkpoints_in_step_order() -> None:
    code = "\n".join(_cells("03_train_and_evaluate.ipynb", "code"))
    # sorting the names puts step_100032 before step_50048; checkpoints() orders by the step number
    assert '"checkpoints").iterdir()' not in code
    assert "from agentsim_env.train.checkpoints import checkpoints" in code and "checkpoints(out)" in code

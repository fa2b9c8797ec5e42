"""Static checks of the web viewer's page (no browser): ids, import map, vendored three.js, no network URLs."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

STATIC = Path(__file__).resolve().parents[1] / "agentsim_env" / "render" / "web" / "static"
PAGE_FILES = ["viewer.html", "viewer.js", "scene3d.js", "protocol.js", "viewer.css"]
IDS = [
    "canvas",
    "log",
    "log-pause",
    "sim-pause",
    "sim-step",
    "speed",
    "status",
    "agent-panel",
    "error-banner",
    "replay-bar",
    "replay-slider",
    "replay-play",
    "replay-step",
    "filters",
]
HOOKS = ["ready", "framesDrawn", "lastStep", "lastSeq", "episode", "logLines", "project", "send", "selected"]


def read(name: str) -> str:
    return (STATIC / name).read_text(encoding="utf-8")


def test_page_has_the_stable_ids() -> None:
    html = read("viewer.html")
    for i in IDS:
        assert re.search(rf'\bid="{i}"', html), f"#{i} missing from viewer.html"


def test_import_map_points_at_the_vendored_three() -> None:
    html = read("viewer.html")
    block = re.search(r'<script type="importmap">(.*?)</script>', html, re.S)
    assert block, "no import map"
    imports = json.loads(block.group(1))["imports"]
    assert imports["three"] == "/static/vendor/three.module.js"
    # three.module.js pulls in three.core.js relatively, i.e. /static/vendor/three.core.js
    assert "from './three.core.js'" in (STATIC / "vendor" / "three.module.js").read_text(encoding="utf-8")


def test_vendored_three_is_complete() -> None:
    vendor = STATIC / "vendor"
    for name in ["three.core.js", "three.module.js", "OrbitControls.js", "LICENSE-three.txt", "VERSION.txt"]:
        assert (vendor / name).is_file(), name
    assert "three 0.187.0" in (vendor / "VERSION.txt").read_text(encoding="utf-8")
    assert "MIT" in (vendor / "LICENSE-three.txt").read_text(encoding="utf-8")


@pytest.mark.parametrize("name", PAGE_FILES)
def test_no_network_urls(name: str) -> None:
    text = read(name)
    assert not re.search(r"https?://|//cdn|unpkg|jsdelivr", text), f"{name} refers to the network"


@pytest.mark.parametrize("name", ["viewer.js", "scene3d.js", "protocol.js"])
def test_module_imports_resolve_to_package_files(name: str) -> None:
    for spec in re.findall(r"""^\s*(?:import|export)\b[^'"]*?from\s+['"]([^'"]+)['"]""", read(name), re.M):
        if spec == "three":
            continue
        assert spec.startswith("/static/"), f"{name}: import {spec!r} is not a /static/ URL"
        assert (STATIC / spec.removeprefix("/static/")).is_file(), f"{name}: {spec} is not a file"


def test_test_hooks_are_defined() -> None:
    js = read("viewer.js")
    assert "window.agentsim = hooks" in js
    for hook in HOOKS:
        assert re.search(rf"^\s+{hook}[:(]", js, re.M), f"window.agentsim.{hook} missing"

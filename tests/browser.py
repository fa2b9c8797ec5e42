"""Headless Chromium for the browser tests, driven by Playwright (the system's Chromium; nothing is downloaded).

``make test`` installs Debian's ``chromium`` when it is missing (the Makefile's ``browser`` target). The flags keep
Chromium off the network (this machine has none) and quiet: no background networking, sync or component updates.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest

from agentsim_env.recorder.web_video import CHROMIUM_FLAGS  # the flags the package launches Chromium with


def chromium_path() -> str:
    """The system Chromium (``AGENTSIM_CHROMIUM`` overrides); fails the test with the fix when there is none."""
    path = os.environ.get("AGENTSIM_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
    if not path:
        pytest.fail("no Chromium on this machine: run `make browser` (installs Debian's chromium package)")
    return path


@contextmanager
def browser_page(width: int = 1000, height: int = 700) -> Iterator[tuple[Any, list[str]]]:
    """A fresh page in headless Chromium and the list its console errors and page errors are appended to."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="the dev extra installs playwright")
    errors: list[str] = []
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium_path(), headless=True, args=CHROMIUM_FLAGS)
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            page.on(
                "console",
                lambda m: errors.append(f"console {m.type}: {m.text}") if m.type == "error" else None,
            )
            page.on("pageerror", lambda e: errors.append(f"page error: {e}"))
            yield page, errors
        finally:
            browser.close()

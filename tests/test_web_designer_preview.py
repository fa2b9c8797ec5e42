"""The designer's previews run off the server's loop: one page's previews never hold up another page, each page
has one preview at a time, and of the requests that waited meanwhile only the newest is answered."""

from __future__ import annotations

import asyncio
import json
import threading
import time
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("websockets", reason="the viewer extra installs websockets")

from websockets.asyncio.client import connect  # noqa: E402

from agentsim_env.render.web.server import ClientError, WebServer  # noqa: E402
from agentsim_env.uav import designer  # noqa: E402
from agentsim_env.uav.designer import designer_handlers, designer_hello  # noqa: E402
from agentsim_env.uav.zones import ZoneSet  # noqa: E402


def one_zone(n_sensors: int) -> dict[str, Any]:
    """A zone file with one gauss zone of ``n_sensors`` sensors (the preview's reply names that number)."""
    z = {"name": "z", "centre": [300, 200], "radius": 80, "n_sensors": n_sensors, "profile": "gauss"}
    return {"version": 1, "map_size": [600, 400], "zones": [z]}


async def _replies(ws: Any, seconds: float) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            out.append(json.loads(await asyncio.wait_for(ws.recv(), 0.1)))
        except asyncio.TimeoutError:
            continue
    return out


def test_a_slow_preview_holds_up_neither_other_pages_nor_its_own_newest_request(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    release = threading.Event()
    computed: list[int] = []
    real = designer.preview

    def held(zs: ZoneSet) -> dict[str, Any]:  # a preview that takes as long as the test says
        computed.append(zs.zones[0].n_sensors)
        release.wait(10)
        return real(zs)

    monkeypatch.setattr(designer, "preview", held)
    path = tmp_path / "z.json"
    path.write_text(json.dumps(one_zone(5)), encoding="utf-8")
    srv = WebServer(
        "designer.html",
        handlers=designer_handlers(path),
        on_connect=lambda: designer_hello(path),
        static_dir=designer.STATIC_DIR,
    )
    url = srv.start().replace("http", "ws") + "ws"
    result: dict[str, Any] = {}

    async def pages() -> None:
        async with connect(url, max_size=None) as a, connect(url, max_size=None) as b:
            assert json.loads(await a.recv())["type"] == json.loads(await b.recv())["type"] == "zones.hello"
            for i, n in enumerate((10, 11, 12, 13, 14), 1):  # the first is held; the others arrive while it runs
                await a.send(json.dumps({"cmd": "zones.preview", "zones": one_zone(n), "id": i}))
            await asyncio.sleep(0.2)
            t0 = time.monotonic()
            await b.send(json.dumps({"cmd": "zones.load"}))
            result["loaded"] = json.loads(await asyncio.wait_for(b.recv(), 3.0))
            result["load_s"] = time.monotonic() - t0
            result["held_meanwhile"] = list(computed)
            release.set()
            result["a"] = await _replies(a, 1.5)

    try:
        asyncio.run(pages())
    finally:
        release.set()
        srv.stop()
    assert result["loaded"]["type"] == "zones.loaded" and result["load_s"] < 1.0
    assert result["held_meanwhile"] == [10]  # one preview at a time for page a
    previews = [m for m in result["a"] if m["type"] == "zones.preview"]
    assert [p["zones"][0]["n_sensors"] for p in previews] == [10, 14]  # the running one, then the newest
    assert [p["id"] for p in previews] == [1, 5]  # the page can tell that its newest request was answered
    assert computed == [10, 14] and all(p["ok"] for p in previews)


def test_previews_of_one_page_do_not_wait_for_another_pages(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    release = threading.Event()
    real = designer.preview

    def held(zs: ZoneSet) -> dict[str, Any]:  # page a's previews (100 sensors) hang until released
        if zs.zones[0].n_sensors == 100:
            release.wait(10)
        return real(zs)

    monkeypatch.setattr(designer, "preview", held)
    srv = WebServer(
        "designer.html",
        handlers=designer_handlers(None),
        on_connect=lambda: designer_hello(None),
        static_dir=designer.STATIC_DIR,
    )
    url = srv.start().replace("http", "ws") + "ws"
    got: list[dict[str, Any]] = []

    async def pages() -> None:
        async with connect(url, max_size=None) as a, connect(url, max_size=None) as b:
            await a.recv()
            await b.recv()
            await a.send(json.dumps({"cmd": "zones.preview", "zones": one_zone(100)}))
            await asyncio.sleep(0.1)
            await b.send(json.dumps({"cmd": "zones.preview", "zones": one_zone(7)}))
            got.append(json.loads(await asyncio.wait_for(b.recv(), 3.0)))
            await b.send(json.dumps({"cmd": "zones.preview", "zones": {"version": 1}}))  # invalid: the message
            got.append(json.loads(await asyncio.wait_for(b.recv(), 3.0)))
            release.set()

    try:
        asyncio.run(pages())
    finally:
        release.set()
        srv.stop()
    assert got[0]["type"] == "zones.preview" and got[0]["zones"][0]["n_sensors"] == 7
    assert got[1]["type"] == "zones.preview" and got[1]["ok"] is False and got[1]["error"]


def test_the_preview_echoes_an_integer_id_and_refuses_any_other() -> None:
    on_preview = designer_handlers(None)["zones.preview"]
    good = on_preview({"cmd": "zones.preview", "zones": one_zone(3), "id": 7})
    assert good is not None and good["ok"] is True and good["id"] == 7
    bad = on_preview({"cmd": "zones.preview", "zones": {"version": 1}, "id": 8})
    assert bad is not None and bad["ok"] is False and bad["id"] == 8
    assert "id" not in (on_preview({"cmd": "zones.preview", "zones": one_zone(3)}) or {})
    for rid in ("7", 1.5, True, None, [1]):
        with pytest.raises(ClientError, match="zones.preview: 'id' must be an integer"):
            on_preview({"cmd": "zones.preview", "zones": one_zone(3), "id": rid})

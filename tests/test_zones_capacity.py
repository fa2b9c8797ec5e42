"""The fleet's capacity where zones are made: ``agentsim zones check`` and the designer's live display."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from agentsim_env.cli import main
from agentsim_env.uav.capacity import default_fleet, fleet_capacity
from agentsim_env.uav.zones import default_zones_path, load_zones


def big_zones(tmp_path: Path, n_sensors: int = 200) -> Path:
    """A one-zone file asking for ``n_sensors`` sensors."""
    z = {"name": "big", "centre": [300, 200], "radius": 80, "n_sensors": n_sensors, "profile": "gauss"}
    path = tmp_path / "big.json"
    path.write_text(json.dumps({"version": 1, "map_size": [600, 400], "zones": [z]}), encoding="utf-8")
    return path


def test_fleet_capacity_numbers() -> None:
    zs = load_zones(default_zones_path())
    assert default_fleet() == (4, 40)
    cap = fleet_capacity(zs, 4, 40)
    assert cap == {
        "n_uavs": 4,
        "payload": 40,
        "capacity": 160,
        "needed": 150,
        "carried": True,
        "spare": 10,
        "n_uavs_needed": 4,
        "payload_needed": 38,
    }
    short = fleet_capacity(zs, 3, 40)
    assert short["carried"] is False and short["spare"] == -30 and short["n_uavs_needed"] == 4
    assert short["payload_needed"] == 50


def test_check_reports_the_default_fleet(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["zones", "check", str(default_zones_path())]) == 0
    out = capsys.readouterr().out
    assert "default fleet: 4 UAVs x 40 sensors = 160; the zones need 150: carried (10 spare)" in out


def test_check_refuses_zones_the_default_fleet_cannot_carry(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = big_zones(tmp_path)
    assert main(["zones", "check", str(path)]) == 2
    cap = capsys.readouterr()
    assert "| 0 | big |" in cap.out  # the zones are still listed
    err = cap.err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("agentsim: error: "), err
    assert "default fleet" in err and "raise n_uavs or payload" in err and "--set n_uavs=5" in err


@pytest.mark.parametrize(
    ("sets", "code", "needle"),
    [
        (["n_uavs=5"], 0, "fleet (--set): 5 UAVs x 40 sensors = 200; the zones need 200: carried (0 spare)"),
        (["payload=50"], 0, "fleet (--set): 4 UAVs x 50 sensors = 200"),
        (["payload=30"], 2, "--set n_uavs=7"),
        (["n_uavs=5", "sensor_mass=1000"], 2, "sensor_mass"),  # the other values are checked too
        (["payload_per_uav=50"], 2, "payload_per_uav"),
        (["zones=tiny"], 2, "zones"),
    ],
)
def test_check_with_set_values(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], sets: list[str], code: int, needle: str
) -> None:
    assert main(["zones", "check", str(big_zones(tmp_path)), "--set", *sets]) == code
    cap = capsys.readouterr()
    assert needle in (cap.out if code == 0 else cap.err)
    if code:
        assert len(cap.err.strip().splitlines()) == 1


# ------------------------------------------------------------------------------------------ designer
def _preview(d: dict[str, Any]) -> dict[str, Any]:
    from agentsim_env.uav.designer import designer_handlers

    reply = designer_handlers(None)["zones.preview"]({"cmd": "zones.preview", "zones": d})
    assert reply is not None
    json.dumps(reply)
    return reply


def test_designer_hello_and_preview_carry_the_fleet(tmp_path: Path) -> None:
    pytest.importorskip("websockets", reason="the viewer extra installs websockets")
    from agentsim_env.uav.designer import designer_hello

    (hello,) = designer_hello(None)
    assert hello["fleet"] == {"n_uavs": 4, "payload": 40, "capacity": 160}
    d = json.loads(big_zones(tmp_path).read_text(encoding="utf-8"))
    reply = _preview(d)
    assert reply["fleet"]["carried"] is False and reply["fleet"]["n_uavs_needed"] == 5
    assert "cannot carry" in reply["fleet"]["text"] and "--set n_uavs=5" in reply["fleet"]["text"]
    d["zones"][0]["n_sensors"] = 100
    ok = _preview(d)["fleet"]
    assert ok["carried"] is True and ok["text"].endswith("carried (60 spare)")


@pytest.mark.slow
def test_designer_page_shows_the_capacity_live(tmp_path: Path) -> None:
    pytest.importorskip("websockets", reason="the viewer extra installs websockets")
    from tests.browser import browser_page
    from tests.test_web_designer import serve, settle

    srv = serve(tmp_path / "z.json")
    try:
        with browser_page(1200, 800) as (page, errors):
            page.goto(srv.url)
            page.wait_for_function("window.designer && window.designer.ready")
            settle(page)
            assert "carried (10 spare)" in page.text_content("#capacity")
            assert "short" not in (page.get_attribute("#capacity", "class") or "")
            page.locator("#zone-list > [data-index='0']").click()
            page.fill("#f-n_sensors", "100")  # 60 -> 100: 190 sensors, over the 160 the fleet carries
            settle(page)
            text = page.text_content("#capacity")
            assert "cannot carry" in text and "--set n_uavs=5" in text, text
            assert "short" in (page.get_attribute("#capacity", "class") or "")
            assert errors == [] and srv.errors == []
    finally:
        srv.stop()

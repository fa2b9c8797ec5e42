"""The hot-zone designer: its message handlers (previews, save, load, refusals) and, in a browser, its page."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("websockets", reason="the viewer extra installs websockets")

from agentsim_env.render.web.server import ClientError, WebServer  # noqa: E402
from agentsim_env.uav import designer  # noqa: E402
from agentsim_env.uav.designer import (  # noqa: E402
    DENSITY_SAMPLES,
    MAX_POINTS_PER_ZONE,
    designer_handlers,
    designer_hello,
    run_designer,
)
from agentsim_env.uav.wsn.profiles import PROFILE_KINDS  # noqa: E402
from agentsim_env.uav.zones import (  # noqa: E402
    default_zones_path,
    load_zones,
    zones_from_dict,
    zones_to_dict,
)


def default_dict() -> dict[str, Any]:
    """The packaged default zone file as a dict."""
    return json.loads(default_zones_path().read_text(encoding="utf-8"))


def one_zone(**zone: Any) -> dict[str, Any]:
    """A 600 x 400 m zone file with one zone (fields override a gauss zone at (300, 200), radius 80)."""
    z = {"name": "z", "centre": [300, 200], "radius": 80, "n_sensors": 100, "profile": "gauss", **zone}
    return {"version": 1, "map_size": [600, 400], "zones": [z]}


def validator_message(d: Any) -> str:
    """The message ``zones_from_dict`` gives for an invalid zone file."""
    with pytest.raises(ValueError) as info:
        zones_from_dict(d)
    return str(info.value)


# ------------------------------------------------------------------------------------------ hello
def test_hello_without_a_file_shows_the_defaults_and_cannot_save() -> None:
    (hello,) = designer_hello(None)
    assert hello["type"] == "zones.hello" and hello["source"] == "default"
    assert hello["can_save"] is False and hello["path"] is None
    assert zones_from_dict(hello["zones"]) == load_zones(default_zones_path())
    assert hello["profile_kinds"] == list(PROFILE_KINDS)
    assert hello["limits"]["n_sensors"] == [1, 100_000]
    json.dumps(hello)  # sendable


def test_hello_reads_the_file_or_falls_back(tmp_path: Path) -> None:
    path = tmp_path / "z.json"
    (hello,) = designer_hello(path)  # not there yet: the defaults, and Save creates it
    assert hello["source"] == "default" and hello["can_save"] is True and hello["path"] == str(path)
    path.write_text(json.dumps(one_zone()), encoding="utf-8")
    (hello,) = designer_hello(path)
    assert hello["source"] == "file" and zones_from_dict(hello["zones"]) == zones_from_dict(one_zone())
    path.write_text(json.dumps(one_zone(radius=-1)), encoding="utf-8")
    hello, err = designer_hello(path)
    assert hello["source"] == "default" and err["type"] == "error"
    assert validator_message(one_zone(radius=-1)) in err["message"] and str(path) in err["message"]


# ---------------------------------------------------------------------------------------- preview
def preview(d: dict[str, Any]) -> dict[str, Any]:
    """The preview handler's reply for a zone file (no file involved)."""
    reply = designer_handlers(None)["zones.preview"]({"cmd": "zones.preview", "zones": d})
    assert reply is not None
    json.dumps(reply)
    return reply


def test_preview_of_the_defaults() -> None:
    d = default_dict()
    zs = zones_from_dict(d)
    reply = preview(d)
    assert reply["type"] == "zones.preview" and reply["ok"] is True
    assert reply["overlaps"] == []
    assert len(reply["zones"]) == len(zs.zones)
    for z, pz in zip(zs.zones, reply["zones"], strict=True):
        dens = np.array(pz["density"])
        assert dens.shape == (DENSITY_SAMPLES,) and np.all(np.isfinite(dens))
        assert dens.max() == pytest.approx(1.0) and dens.min() >= 0.0
        assert pz["shown"] == pz["n_sensors"] == z.n_sensors
        prof = z.radial_profile()
        b8 = np.array(pz["b8"])
        np.testing.assert_allclose(b8, prof.low_discrepancy(z.n_sensors) + z.centre, atol=1e-3)
        b1 = np.array(pz["b1"])
        np.testing.assert_allclose(b1, prof.sample(z.n_sensors, np.random.default_rng(0)) + z.centre, atol=1e-3)
        assert np.all(np.hypot(*(b1 - z.centre).T) <= z.radius + 1e-3)
    assert preview(d) == reply  # stable: the same zones give the same picture


@pytest.mark.parametrize("kind", PROFILE_KINDS)
def test_density_is_monotone_and_normalised(kind: str) -> None:
    dens = np.array(preview(one_zone(profile=kind, alpha=1.5, floor=0.1))["zones"][0]["density"])
    assert dens.shape == (DENSITY_SAMPLES,) and np.all(np.isfinite(dens))
    assert dens.max() == pytest.approx(1.0)
    assert np.all(np.diff(dens) <= 1e-9)
    if kind == "gauss":  # sigma = radius / 2 without a floor: exp(-2) at the rim
        plain = np.array(preview(one_zone())["zones"][0]["density"])
        assert plain[0] == 1.0 and plain[-1] == pytest.approx(np.exp(-2.0), abs=1e-5)
        assert np.all(np.diff(plain) < 0)


def test_points_are_capped_per_zone() -> None:
    n = 5 * MAX_POINTS_PER_ZONE + 3
    d = one_zone(n_sensors=n, profile="power", alpha=1.0, floor=0.05)
    pz = preview(d)["zones"][0]
    assert pz["n_sensors"] == n and pz["shown"] == MAX_POINTS_PER_ZONE
    assert len(pz["b1"]) == len(pz["b8"]) == MAX_POINTS_PER_ZONE
    z = zones_from_dict(d).zones[0]
    full = z.radial_profile().low_discrepancy(n) + z.centre
    idx = np.unique(np.round(np.linspace(0, n - 1, MAX_POINTS_PER_ZONE)).astype(np.int64))
    np.testing.assert_allclose(np.array(pz["b8"]), full[idx], atol=1e-3)  # evenly thinned: keeps the rim
    assert np.hypot(*(np.array(pz["b8"]) - z.centre).T).max() > 0.99 * z.radius


def test_preview_reports_overlaps_in_map_coordinates() -> None:
    d = one_zone()
    d["zones"].append({"centre": [420, 200], "radius": 60, "n_sensors": 10, "profile": "uniform"})
    d["zones"].append({"centre": [60, 60], "radius": 40, "n_sensors": 10})
    reply = preview(d)
    assert reply["overlaps"] == [[0, 1]]
    b1 = np.array(reply["zones"][1]["b1"])
    assert np.all(np.hypot(b1[:, 0] - 420, b1[:, 1] - 200) <= 60 + 1e-3)


@pytest.mark.parametrize(
    "change",
    [
        {"radius": 700},
        {"n_sensors": 0},
        {"n_sensors": 2.5},
        {"profile": "exp"},
        {"alpha": 2},
        {"floor": 1},
        {"sigma": 0.001},
        {"weight": "heavy"},
        {"altitude": 500},
        {"radus": 30},
        {"centre": [300]},
        {"radius": True},
    ],
)
def test_bad_values_give_the_validators_message(change: dict[str, Any]) -> None:
    d = one_zone(**change)
    reply = preview(d)
    assert reply == {"type": "zones.preview", "ok": False, "error": validator_message(d)}
    assert "zones[0] 'z'" in reply["error"]


@pytest.mark.parametrize(
    "d",
    [
        {"map_size": [600, 400], "zones": []},
        {"map_size": [0, 400], "zones": one_zone()["zones"]},
        {"map_size": [600, 400], "base": [700, 0], "zones": one_zone()["zones"]},
        {"zones": one_zone()["zones"]},
        {"map_size": [600, 400], "zones": ["not a zone"]},
        {"map_size": [600, 400], "zones": one_zone()["zones"], "version": 2},
    ],
)
def test_bad_files_give_the_validators_message(d: dict[str, Any]) -> None:
    assert preview(d) == {"type": "zones.preview", "ok": False, "error": validator_message(d)}


# ------------------------------------------------------------------------------- malformed messages
@pytest.mark.parametrize("cmd", ["zones.preview", "zones.save"])
@pytest.mark.parametrize(
    ("msg", "words"),
    [
        ({}, "missing 'zones'"),
        ({"zones": [1, 2]}, "'zones' must be a zone file object, got list"),
        ({"zones": "x"}, "got str"),
        ({"zones": None}, "got NoneType"),
        ({"zones": {}, "extra": 1, "more": 2}, "unknown key(s) ['extra', 'more']"),
        ({"zones": {}, "path": "/etc/passwd"}, "cannot choose the file"),
    ],
)
def test_malformed_messages_are_client_errors(tmp_path: Path, cmd: str, msg: dict[str, Any], words: str) -> None:
    handlers = designer_handlers(tmp_path / "z.json")
    with pytest.raises(ClientError) as info:
        handlers[cmd]({"cmd": cmd, **msg})
    assert words in str(info.value) and cmd in str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_load_takes_no_other_keys(tmp_path: Path) -> None:
    handlers = designer_handlers(tmp_path / "z.json")
    with pytest.raises(ClientError, match="cannot choose the file"):
        handlers["zones.load"]({"cmd": "zones.load", "path": "/etc/hosts"})
    with pytest.raises(ClientError, match=r"unknown key\(s\) \['zones'\]"):
        handlers["zones.load"]({"cmd": "zones.load", "zones": {}})


# ------------------------------------------------------------------------------------- save and load
def test_save_writes_only_the_given_file_and_round_trips(tmp_path: Path) -> None:
    path = tmp_path / "zones.json"
    handlers = designer_handlers(path)
    d = default_dict()
    d["zones"][1]["name"] = "renamed"
    reply = handlers["zones.save"]({"cmd": "zones.save", "zones": copy.deepcopy(d)})
    assert reply == {"type": "zones.saved", "path": str(path), "n_zones": 3}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["zones.json"]  # no temporary file left behind
    assert load_zones(path) == zones_from_dict(d)
    loaded = handlers["zones.load"]({"cmd": "zones.load"})
    assert loaded is not None and loaded["type"] == "zones.loaded" and loaded["path"] == str(path)
    assert loaded["zones"] == zones_to_dict(zones_from_dict(d))
    d["zones"].pop()  # saving again replaces the file
    assert handlers["zones.save"]({"cmd": "zones.save", "zones": d})["n_zones"] == 2  # type: ignore[index]
    assert load_zones(path) == zones_from_dict(d)


def test_invalid_zones_are_not_saved(tmp_path: Path) -> None:
    path = tmp_path / "zones.json"
    path.write_text(json.dumps(one_zone()), encoding="utf-8")
    before = path.read_bytes()
    bad = one_zone(n_sensors=-3)
    with pytest.raises(ClientError) as info:
        designer_handlers(path)["zones.save"]({"cmd": "zones.save", "zones": bad})
    assert str(info.value) == validator_message(bad)
    assert path.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["zones.json"]


def test_without_a_file_nothing_is_saved_or_loaded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    handlers = designer_handlers(None)
    with pytest.raises(ClientError, match="started without a file: nothing is written; use Download"):
        handlers["zones.save"]({"cmd": "zones.save", "zones": default_dict()})
    with pytest.raises(ClientError, match="started without a file"):
        handlers["zones.load"]({"cmd": "zones.load"})
    assert list(tmp_path.iterdir()) == []


def test_load_errors(tmp_path: Path) -> None:
    path = tmp_path / "zones.json"
    handlers = designer_handlers(path)
    with pytest.raises(ClientError, match="does not exist yet"):
        handlers["zones.load"]({"cmd": "zones.load"})
    path.write_text(json.dumps(one_zone(profile="rings")), encoding="utf-8")
    with pytest.raises(ClientError) as info:
        handlers["zones.load"]({"cmd": "zones.load"})
    assert str(info.value) == f"{path}: {validator_message(one_zone(profile='rings'))}"
    path.write_text("{not json", encoding="utf-8")
    with pytest.raises(ClientError, match="not valid JSON"):
        handlers["zones.load"]({"cmd": "zones.load"})


def test_save_reports_an_unwritable_folder(tmp_path: Path) -> None:
    path = tmp_path / "gone" / "zones.json"
    with pytest.raises(ClientError, match="cannot write"):
        designer_handlers(path)["zones.save"]({"cmd": "zones.save", "zones": one_zone()})


# -------------------------------------------------------------------------------------- run_designer
def test_run_designer_serves_until_interrupted(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def interrupt() -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(designer, "_wait_forever", interrupt)
    run_designer(str(tmp_path / "new.json"))
    out = capsys.readouterr().out
    assert "http://127.0.0.1:" in out and f"Save writes {(tmp_path / 'new.json').resolve()}" in out
    run_designer(None)
    assert "Save is off" in capsys.readouterr().out


def test_run_designer_refuses_an_invalid_file(tmp_path: Path) -> None:
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(one_zone(radius=0)), encoding="utf-8")
    with pytest.raises(ValueError, match="field 'radius'"):
        run_designer(str(path))
    with pytest.raises(ValueError, match="is a folder"):
        run_designer(str(tmp_path))


# ------------------------------------------------------------------------------------------ browser
def serve(path: Path | None) -> WebServer:
    """A started designer server for ``path``."""
    srv = WebServer(
        page="designer.html",
        title="Hot-zone designer",
        handlers=designer_handlers(path),
        on_connect=lambda: designer_hello(path),
        static_dir=designer.STATIC_DIR,
    )
    srv.start()
    return srv


def settle(page: Any) -> None:
    """Wait until the page has no preview pending."""
    page.wait_for_function("window.designer.idle() && window.designer.lastPreview !== null")


def draw_zone(page: Any, centre: tuple[float, float], radius: float) -> None:
    """Press at ``centre`` on the map and drag out ``radius`` (map metres)."""
    a = page.evaluate("p => designer.toPixel(p)", list(centre))
    b = page.evaluate("p => designer.toPixel(p)", [centre[0] + radius, centre[1]])
    page.mouse.move(*a)
    page.mouse.down()
    page.mouse.move(*b, steps=6)
    page.mouse.up()


@pytest.mark.slow
def test_page_draws_edits_and_saves_two_zones(tmp_path: Path) -> None:
    from tests.browser import browser_page

    path = tmp_path / "two.json"
    srv = serve(path)
    try:
        with browser_page(1200, 800) as (page, errors):
            page.goto(srv.url)
            page.wait_for_function("window.designer && window.designer.ready")
            settle(page)
            assert page.locator("#zone-list > [data-index]").count() == 3  # the defaults, as the file is new
            while page.locator("#zone-list > [data-index]").count():
                page.locator("#zone-list > [data-index] button").first.click()
            px = page.evaluate("designer.toPixel([100, 0])[0] - designer.toPixel([0, 0])[0]") / 100.0
            draw_zone(page, (150, 200), 80)
            page.fill("#f-name", "alpha")
            page.fill("#f-n_sensors", "80")
            draw_zone(page, (420, 150), 60)
            page.fill("#f-name", "beta")
            page.fill("#f-n_sensors", "35")
            page.select_option("#f-profile", "power")
            page.fill("#f-alpha", "1.2")
            page.fill("#f-weight", "2")
            settle(page)
            assert page.locator("#zone-list > [data-index]").count() == 2
            assert page.locator("#error").is_hidden()
            preview_ = page.evaluate("designer.lastPreview")
            assert preview_["ok"] and [z["n_sensors"] for z in preview_["zones"]] == [80, 35]
            page.screenshot(path=str(tmp_path / "designer.png"))
            page.click("#save")
            page.wait_for_function("document.querySelector('#status').textContent.startsWith('saved to')")
            assert str(path) in page.text_content("#status")

            zs = load_zones(path)
            assert [(z.name, z.n_sensors) for z in zs.zones] == [("alpha", 80), ("beta", 35)]
            tol = 1.0 / px + 0.1  # a pixel's worth of metres, and the page's 0.1 m rounding
            for z, (cx, cy, r) in zip(zs.zones, [(150, 200, 80), (420, 150, 60)], strict=True):
                assert abs(z.centre[0] - cx) <= tol and abs(z.centre[1] - cy) <= tol and abs(z.radius - r) <= tol
            assert zs.zones[1].profile == "power" and zs.zones[1].alpha == 1.2 and zs.zones[1].weight == 2.0
            assert zs.zones[0].profile == "gauss" and zs.zones[0].floor == 0.0 and zs.zones[0].weight == 1.0
            assert zs.map_size == (600.0, 400.0) and zs.base == (20.0, 20.0)
            import agentsim_env  # the saved file runs in uav_release (what `agentsim evaluate --zones FILE` builds)

            uav = agentsim_env.make("uav_release", zones=str(path))
            assert uav.scenario.zones == zs
            uav.reset(seed=0)

            page.fill("#f-radius", "700")  # a bad value: the validator's own message, verbatim
            settle(page)
            expected = validator_message(page.evaluate("designer.zones()"))
            assert page.locator("#error").is_visible() and page.text_content("#error") == expected
            assert "zones[1] 'beta': field 'centre'/'radius'" in expected
            page.click("#load")  # back to the saved file
            page.wait_for_function("document.querySelector('#status').textContent.startsWith('loaded')")
            settle(page)
            assert page.locator("#error").is_hidden()
            assert zones_from_dict(page.evaluate("designer.zones()")) == zs
            assert errors == [] and srv.errors == []
    finally:
        srv.stop()


@pytest.mark.slow
def test_page_without_a_file_refuses_save(tmp_path: Path) -> None:
    from tests.browser import browser_page

    srv = serve(None)
    try:
        with browser_page() as (page, errors):
            page.goto(srv.url)
            page.wait_for_function("window.designer && window.designer.ready")
            settle(page)
            page.click("#save")
            page.wait_for_function("!document.querySelector('#error').hidden")
            assert page.text_content("#error").startswith("started without a file: nothing is written")
            page.locator("#zone-list > [data-index='0']").click()
            page.fill("#f-n_sensors", "0")
            settle(page)
            bad = page.evaluate("designer.zones()")
            message = validator_message(bad)
            assert page.text_content("#error") == message and "field 'n_sensors'" in message
            with page.expect_download() as info:
                page.click("#download")
            assert json.loads(Path(info.value.path()).read_text(encoding="utf-8")) == bad
            assert errors == [] and srv.errors == []
    finally:
        srv.stop()

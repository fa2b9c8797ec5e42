"""Zone files and text fields that must be refused: devices and FIFOs, control characters, bidirectional
overrides and unpaired surrogates in names, duplicate keys and deep nesting in zone JSON."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

import agentsim_env
from agentsim_env.cli import main
from agentsim_env.core import validation
from agentsim_env.uav import zones as uav_zones
from agentsim_env.uav.zones import load_zones, zones_from_dict

ZONE = {"centre": [100, 100], "radius": 30, "n_sensors": 10}

#: One sample of each kind of character a text field refuses, with the code point the message names.
BAD_CHARACTERS = [
    ("\x00", "U+0000"),  # NUL
    ("\x1b[31m", "U+001B"),  # ESC: a terminal colour sequence
    ("\x7f", "U+007F"),  # DEL
    ("\x85", "U+0085"),  # C1 next line
    ("\u202e", "U+202E"),  # right-to-left override
    ("\u2066", "U+2066"),  # left-to-right isolate
    ("\ud800", "U+D800"),  # a lone surrogate (what json.loads makes of "\ud800")
]


def zone_file(**zone: Any) -> dict[str, Any]:
    """A one-zone file on a 200 m map (fields of the zone overridden by ``zone``)."""
    return {"map_size": [200, 200], "zones": [{**ZONE, **zone}]}


# ------------------------------------------------------------------------------------- check_text
@pytest.mark.parametrize(("bad", "code"), BAD_CHARACTERS)
def test_check_text_refuses_control_bidi_and_surrogates(bad: str, code: str) -> None:
    with pytest.raises(ValueError) as info:
        validation.check_text("label", f"ab{bad}c")
    message = str(info.value)
    assert message.startswith("label ") and code in message and "position 2" in message
    message.encode("ascii")  # the message itself never carries the character


@pytest.mark.parametrize("good", ["north-west", "café", "北区", "zone 🚁", "a-b_c.d (2)", ""])
def test_check_text_accepts_ordinary_text(good: str) -> None:
    assert validation.check_text("label", good) == good


def test_check_text_newlines_only_where_allowed() -> None:
    with pytest.raises(ValueError, match="U\\+000A"):
        validation.check_text("label", "two\nlines")
    assert validation.check_text("label", "two\nlines\tand a tab", allow_newlines=True) == "two\nlines\tand a tab"
    with pytest.raises(ValueError, match="U\\+001B"):
        validation.check_text("label", "two\n\x1b[2J", allow_newlines=True)
    with pytest.raises(ValueError, match="label must be a string"):
        validation.check_text("label", 3)


# ------------------------------------------------------------------------------- zone names (item 17)
@pytest.mark.parametrize(("bad", "code"), BAD_CHARACTERS)
def test_zone_names_with_control_characters_are_refused(bad: str, code: str) -> None:
    with pytest.raises(ValueError) as info:
        zones_from_dict(zone_file(name=f"north{bad}"))
    message = str(info.value)
    assert "zones[0]" in message and "field 'name'" in message and code in message
    message.encode("ascii")


def test_the_description_takes_newlines_but_no_escapes() -> None:
    assert zones_from_dict({**zone_file(), "description": "two\nlines"}) == zones_from_dict(zone_file())
    with pytest.raises(ValueError, match="field 'description'.*U\\+001B"):
        zones_from_dict({**zone_file(), "description": "\x1b]0;title\x07"})
    with pytest.raises(ValueError, match="field 'description' must be a string"):
        zones_from_dict({**zone_file(), "description": ["a", "list"]})


def test_zones_check_refuses_a_bad_name_in_one_ascii_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "z.json"
    # json.dumps writes the NUL, ESC, override and lone surrogate as \u escapes: a file that really holds them
    path.write_text(json.dumps(zone_file(name="a\x00\x1b[2J\u202e\ud800")), encoding="utf-8")
    assert main(["zones", "check", str(path)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    (line,) = captured.err.splitlines()
    assert line.startswith(f"agentsim: error: {path}: zones[0]") and "field 'name'" in line and "U+0000" in line
    line.encode("ascii")


def test_a_config_string_field_names_the_field_and_the_character() -> None:
    with pytest.raises(ValueError, match="action_mode.*U\\+001B"):
        agentsim_env.make("navigation", action_mode="velo\x1bcity")
    with pytest.raises(ValueError, match="physics.*U\\+202E"):
        agentsim_env.make("navigation", physics="kine\u202ematic")


def test_a_zones_path_with_an_escape_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "z\x1b[31m.json"
    path.write_text(json.dumps(zone_file()), encoding="utf-8")
    with pytest.raises(ValueError, match="zones.*U\\+001B") as info:
        agentsim_env.make("uav_release", n_agents=1, zones=str(path))
    assert "\x1b" not in str(info.value)


# --------------------------------------------------------------------- duplicate keys and nesting (18)
@pytest.mark.parametrize(
    ("text", "key"),
    [
        ('{"map_size": [200, 200], "map_size": [300, 300], "zones": [ZONE]}', "map_size"),
        (
            '{"map_size": [200, 200], "zones": [{"centre": [100, 100], "radius": 30, "n_sensors": 10, '
            '"name": "a", "name": "b"}]}',
            "name",
        ),
    ],
)
def test_duplicate_keys_are_refused(tmp_path: Path, text: str, key: str) -> None:
    path = tmp_path / "dup.json"
    path.write_text(text.replace("ZONE", json.dumps(ZONE)), encoding="utf-8")
    with pytest.raises(ValueError, match=f"duplicate key '{key}'") as info:
        load_zones(path)
    assert str(info.value).startswith(f"{path}: ")


def test_nesting_past_the_bound_is_refused(tmp_path: Path) -> None:
    deep = json.loads("[" * 40 + "]" * 40)
    path = tmp_path / "deep.json"
    path.write_text(json.dumps({**zone_file(), "description": deep}), encoding="utf-8")
    with pytest.raises(ValueError, match=f"nested .* at most {uav_zones.MAX_JSON_DEPTH}") as info:
        load_zones(path)
    assert str(info.value).startswith(f"{path}: ")
    with pytest.raises(ValueError, match=f"at most {uav_zones.MAX_JSON_DEPTH}"):
        zones_from_dict({**zone_file(), "description": deep})
    path.write_text("[" * 100_000 + "]" * 100_000, encoding="utf-8")  # past the parser's own recursion
    with pytest.raises(ValueError, match="nested too deeply"):
        load_zones(path)


# ------------------------------------------------------------------ devices and FIFOs (item 6)
@pytest.fixture
def fifo(tmp_path: Path) -> Iterator[Path]:
    """A FIFO nobody writes to; whatever still waits on it at the end is let go (a writer opens and closes)."""
    path = tmp_path / "zones.fifo"
    os.mkfifo(path)
    yield path
    try:
        os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
    except OSError:  # no reader left waiting: nothing to let go
        pass


def _store_naming(zones: Path, tmp_path: Path) -> Path:
    """A store whose one run claims to be ``uav_release`` with ``zones`` in its config."""
    import sqlite3

    from agentsim_env.recorder import record

    path = tmp_path / "run.db"
    env = record(agentsim_env.make("navigation", n_agents=2, max_steps=3), path)
    env.reset(seed=0)
    while env.agents:
        env.step({a: env.action_space(a).sample() for a in env.agents})
    env.close()
    con = sqlite3.connect(path)
    with con:
        con.execute("UPDATE runs SET scenario = 'uav_release', config = ?", (json.dumps({"zones": str(zones)}),))
    con.close()
    return path


def _designer_load(path: Path) -> None:
    from agentsim_env.uav.designer import designer_handlers

    designer_handlers(path)["zones.load"]({"cmd": "zones.load"})


def _designer_hello(path: Path) -> list[dict[str, Any]]:
    from agentsim_env.uav.designer import designer_hello

    return designer_hello(path)


def _replay_info(path: Path, tmp_path: Path) -> Any:
    from agentsim_env.recorder.replay import replay_info

    return replay_info(_store_naming(path, tmp_path))


READERS: dict[str, Callable[[Path, Path], Any]] = {
    "load_zones": lambda p, _: load_zones(p),
    "make": lambda p, _: agentsim_env.make("uav_release", zones=str(p)),
    "zones check": lambda p, _: main(["zones", "check", str(p)]),
    "designer load": lambda p, _: _designer_load(p),
    "designer hello": lambda p, _: _designer_hello(p),
    "store config": _replay_info,
}


@pytest.mark.parametrize("reader", list(READERS))
def test_a_fifo_is_refused_without_waiting(reader: str, fifo: Path, tmp_path: Path) -> None:
    outcome: list[Any] = []

    def read() -> None:
        try:
            outcome.append(READERS[reader](fifo, tmp_path))
        except Exception as exc:  # noqa: BLE001 - the test inspects it
            outcome.append(exc)

    thread = threading.Thread(target=read, daemon=True)
    thread.start()
    thread.join(timeout=30)
    assert not thread.is_alive(), f"{reader} waits on a FIFO"
    (result,) = outcome
    if reader in ("load_zones", "make", "designer load"):
        assert isinstance(result, ValueError) and "not a regular file" in str(result) and "FIFO" in str(result)
    elif reader == "designer hello":
        assert result[0]["source"] == "default" and "not a regular file" in result[1]["message"]
    elif reader == "zones check":
        assert result == 2
    elif isinstance(result, Exception):  # the store's reader refuses the config with the loader's message
        assert "not a regular file" in str(result) and "FIFO" in str(result)
    else:  # or draws the replay without the scenario's map: from the recorded positions
        assert result.scenario == "uav_release"


_DEVICE_SCRIPT = """
import io, contextlib, resource
import agentsim_env
from agentsim_env.cli import main
from agentsim_env.uav.zones import load_zones
vm = int(open("/proc/self/status").read().split("VmSize:")[1].split()[0]) * 1024
resource.setrlimit(resource.RLIMIT_AS, (vm + (768 << 20), resource.RLIM_INFINITY))  # reading /dev/zero stops
for name, call in [("load", lambda: load_zones("/dev/zero")),
                   ("make", lambda: agentsim_env.make("uav_release", zones="/dev/zero"))]:
    try:
        call()
        print(name, "accepted")
    except BaseException as exc:
        print(name, type(exc).__name__, exc)
err = io.StringIO()
with contextlib.redirect_stderr(err):
    code = main(["zones", "check", "/dev/zero"])
print("check", code, err.getvalue().strip())
"""


@pytest.mark.skipif(not os.path.exists("/dev/zero") or sys.platform != "linux", reason="Linux devices")
def test_a_device_is_refused_before_any_read() -> None:
    out = subprocess.run([sys.executable, "-c", _DEVICE_SCRIPT], capture_output=True, text=True, timeout=120)
    lines = out.stdout.splitlines()
    assert len(lines) == 3, out.stdout + out.stderr
    for line in lines[:2]:
        assert " ValueError " in line and "/dev/zero" in line and "not a regular file" in line, line
        assert "character device" in line
    assert lines[2].startswith("check 2 agentsim: error: /dev/zero: ") and "not a regular file" in lines[2]

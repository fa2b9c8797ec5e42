"""The viewer (``agentsim view``, ``render_mode="web"``) and the designer (``agentsim zones design``) listen on
loopback only by default: every TCP socket they open, read from ``/proc/net/tcp*`` while they serve."""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

pytest.importorskip("websockets", reason="the viewer extra installs websockets")
if not sys.platform.startswith("linux"):  # pragma: no cover - /proc/net is Linux's
    pytest.skip("reads /proc/net/tcp*", allow_module_level=True)

import agentsim_env  # noqa: E402
from agentsim_env.cli import main  # noqa: E402
from tests.listening import Listener, listeners  # noqa: E402


def _opened(before: set[int]) -> list[Listener]:
    """The listening sockets of this process opened since ``before`` (inodes) was taken."""
    return [s for s in listeners() if s.inode not in before]


def _assert_loopback(opened: list[Listener], what: str) -> None:
    assert opened, f"{what} opened no listening socket"
    exposed = [str(s) for s in opened if not s.loopback]
    assert not exposed, f"{what} listens beyond loopback: {exposed}"


def test_agentsim_view_listens_on_loopback_only(monkeypatch: pytest.MonkeyPatch) -> None:
    import agentsim_env.policies.rollout as rollout

    before = {s.inode for s in listeners()}
    seen: list[list[Listener]] = []
    real = rollout.run_episode

    def first_episode(*args: Any, **kw: Any) -> Any:  # the server is up once the first episode starts
        seen.append(_opened(before))
        return real(*args, **kw)

    monkeypatch.setattr(rollout, "run_episode", first_episode)
    assert main(["view", "navigation", "--set", "n_agents=3", "--steps", "2", "--speed", "0", "--no-wait"]) == 0
    _assert_loopback(seen[0], "agentsim view")


def test_agentsim_view_replay_listens_on_loopback_only(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import agentsim_env.cli_view as cli_view

    db = tmp_path / "r.db"
    assert (
        main(
            [
                "run",
                "navigation",
                "--episodes",
                "1",
                "--set",
                "n_agents=3",
                "max_steps=5",
                "--record",
                str(db),
                "--out",
                "",
                "--quiet",
            ]
        )
        == 0
    )
    before = {s.inode for s in listeners()}
    seen: list[list[Listener]] = []

    class Ctrl_C:  # noqa: N801 - stands for the Ctrl-C the replay waits for
        def wait(self) -> None:
            seen.append(_opened(before))
            raise KeyboardInterrupt

    monkeypatch.setattr(cli_view, "threading", SimpleNamespace(Event=Ctrl_C))
    assert main(["view", "--replay", str(db)]) == 0
    _assert_loopback(seen[0], "agentsim view --replay")


def test_render_mode_web_listens_on_loopback_only() -> None:
    before = {s.inode for s in listeners()}
    env = agentsim_env.make("navigation", n_agents=3, render_mode="web")
    try:
        env.reset(seed=0)
        opened = _opened(before)
        port = int(env.viewer.url.rstrip("/").rsplit(":", 1)[1])
    finally:
        env.close()
    _assert_loopback(opened, 'render_mode="web"')
    assert port in {s.port for s in opened}


def test_agentsim_zones_design_listens_on_loopback_only(monkeypatch: pytest.MonkeyPatch) -> None:
    from agentsim_env.uav import designer

    before = {s.inode for s in listeners()}
    seen: list[list[Listener]] = []

    def look_then_stop() -> None:  # stands for the Ctrl-C that ends the designer
        seen.append(_opened(before))
        raise KeyboardInterrupt

    monkeypatch.setattr(designer, "_wait_forever", look_then_stop)
    assert main(["zones", "design"]) == 0
    _assert_loopback(seen[0], "agentsim zones design")


def test_the_check_sees_a_socket_on_every_interface() -> None:
    # the check itself can fail: a server on 0.0.0.0 is reported as exposed
    import socket

    before = {s.inode for s in listeners()}
    with socket.socket() as sock:
        sock.bind(("0.0.0.0", 0))
        sock.listen()
        port = sock.getsockname()[1]
        opened = _opened(before)
    assert [s.port for s in opened] == [port]
    with pytest.raises(AssertionError, match="listens beyond loopback"):
        _assert_loopback(opened, "a plain socket")

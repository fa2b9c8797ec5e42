"""The UAV case study as a package of its own: its subcommands come through the CLI's provider hook, and its
designer page is served from its own folder."""

from __future__ import annotations

import pytest

from agentsim_env import cli
from agentsim_env.render.web.http_pages import STATIC_DIR, static_files


def test_the_cli_adds_uav_subcommands_through_its_providers(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.SUBCOMMAND_PROVIDERS == ("agentsim_env.uav.cli:add_commands",)
    with pytest.raises(SystemExit):
        cli.main(["--help"])
    out = capsys.readouterr().out
    assert "evaluate" in out and "zones" in out
    args = cli.build_parser().parse_args(["zones", "check", "f.json"])
    from agentsim_env.uav.cli import cmd_zones_check

    assert args.func is cmd_zones_check


@pytest.mark.parametrize("spec", ["agentsim_env.uav.cli", "agentsim_env.uav.cli:", ":add_commands"])
def test_a_malformed_provider_is_named(spec: str) -> None:
    with pytest.raises(ValueError, match="expected 'module:function'"):
        cli._provider(spec)


def test_the_designer_page_is_served_from_its_own_folder() -> None:
    from agentsim_env.render.web.server import WebServer
    from agentsim_env.uav import designer

    assert set(static_files(designer.STATIC_DIR)) == {
        "/static/designer.html",
        "/static/designer.css",
        "/static/designer.js",
    }
    assert not any("designer" in name for name in static_files(STATIC_DIR))  # the viewer's folder lacks it
    with pytest.raises(ValueError, match="is not a file of"):
        WebServer("designer.html")

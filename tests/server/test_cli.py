"""The command line exposes every package's sub-command group."""

from typer.testing import CliRunner

from server.cli import app


def test_top_level_help_lists_every_group():
    result = CliRunner().invoke(app, ["--help"])
    assert result.exit_code == 0
    for group in ("run", "nc", "plc", "drives", "cam"):
        assert group in result.output


def test_unknown_command_is_refused():
    result = CliRunner().invoke(app, ["no-such-command"])
    assert result.exit_code != 0

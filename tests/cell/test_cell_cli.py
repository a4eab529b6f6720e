"""`fmscell run` and `fmscell machine` on the command line; the built-in cell."""

from __future__ import annotations

from typer.testing import CliRunner

from server.cell import DEFAULT_PORTS, default_cell, fault_spec
from server.cli import app


def test_run_and_machine_are_mounted_with_their_options():
    result = CliRunner().invoke(app, ["run", "--help"])
    assert result.exit_code == 0, result.output
    for option in (
        "--config",
        "--clock",
        "--processes",
        "--host",
        "--port",
        "--insecure-open",
        "--faults",
    ):
        assert option in result.output
    result = CliRunner().invoke(app, ["machine", "--help"])
    assert result.exit_code == 0 and "--name" in result.output
    result = CliRunner().invoke(app, ["--help"])
    for group in ("run", "machine", "nc", "plc", "drives", "dnc"):
        assert group in result.output


def test_a_bad_clock_or_configuration_is_refused_before_anything_starts(tmp_path):
    result = CliRunner().invoke(app, ["run", "--clock", "warp"])
    assert result.exit_code == 2 and "realtime, fast" in result.output
    bad = tmp_path / "cell.yaml"
    bad.write_text("machines:\n  m1:\n    base: mill3\n    ipo_cycle_ms: 99\n")
    result = CliRunner().invoke(app, ["run", "--config", str(bad)])
    assert result.exit_code == 2
    assert "cell.yaml" in result.output and "ipo_cycle_ms" in result.output


def test_the_default_cell_is_two_mills_and_a_lathe_on_distinct_loopback_ports():
    cell = default_cell()
    assert {n: m.kind for n, m in cell.machines.items()} == {
        "mill1": "mill",
        "mill2": "mill",
        "lathe1": "lathe",
    }
    assert cell.machines["mill1"].axes == cell.machines["mill2"].axes
    ports = [p for n in cell.machines for p in DEFAULT_PORTS[n].values()]
    assert len(set(ports)) == len(ports)
    assert all(m.ports.host == "127.0.0.1" for m in cell.machines.values())
    assert all(
        m.ports.dnc == 0 and m.ports.simulation is None
        for m in default_cell(free_ports=True).machines.values()
    )


def test_fault_requests_become_fault_specs():
    cases = [
        ({"type": "encoder", "target": "X"}, "drive:X:encoder"),
        ({"type": "encoder", "target": "drive:y"}, "drive:Y:encoder"),
        (
            {"type": "mains_voltage", "target": "Z", "params": {"volts": 250}},
            "drive:Z:mains_voltage:volts=250",
        ),
        ({"type": "bus_off", "target": "bus:X"}, "bus:bus_off:X"),
        ({"type": "door_open", "target": "plc"}, "plc:door_open"),
    ]
    for request, spec in cases:
        assert fault_spec(request) == spec


def test_the_cells_machine_process_command_line_is_a_valid_fmscell_machine(tmp_path):
    """`--processes` starts `python -m server.cli machine ...`: every option it passes must
    exist in `fmscell machine` (parsed by the real CLI, nothing run)."""
    import sys

    import click
    import typer

    from server.supervisor import machine_command

    for fast, simulation, ideal in ((True, True, True), (False, False, False)):
        cmd = machine_command(
            tmp_path / "cell.yaml",
            "mill1",
            ready_file=tmp_path / "mill1.machine.json",
            fast=fast,
            simulation=simulation,
            ideal=ideal,
        )
        assert cmd[:4] == [sys.executable, "-m", "server.cli", "machine"]
        group = typer.main.get_command(app)
        with click.Context(group, info_name="fmscell") as ctx:
            sub = group.get_command(ctx, "machine")
            params = sub.make_context("machine", cmd[4:], parent=ctx).params
        assert params["name"] == "mill1" and params["power_on"] is True
        assert params["ready_file"] == tmp_path / "mill1.machine.json"
        assert params["clock"] == ("fast" if fast else "realtime")
        assert params["simulation"] is simulation and params["ideal"] is ideal


def test_machine_refuses_an_unknown_clock():
    result = CliRunner().invoke(app, ["machine", "--name", "mill3", "--clock", "warp"])
    assert result.exit_code == 2 and "--clock 'warp'" in result.output

"""`fmscell drives eds | plan | serve`."""

from __future__ import annotations

from typer.testing import CliRunner

from drives import EDS_PATH
from drives.cli import drives_app

runner = CliRunner()


def test_eds_prints_the_path():
    result = runner.invoke(drives_app, ["eds"])
    assert result.exit_code == 0
    assert result.stdout.strip() == EDS_PATH


def test_plan_ok_warn_and_refused():
    ok = runner.invoke(drives_app, ["plan", "--axes", "2", "--sync-ms", "2"])
    assert ok.exit_code == 0 and ok.stdout.startswith("OK")
    warn = runner.invoke(drives_app, ["plan", "--axes", "6", "--sync-ms", "2"])
    assert warn.exit_code == 0 and "WARNING" in warn.stdout
    refused = runner.invoke(
        drives_app, ["plan", "--axes", "6", "--sync-ms", "1", "--bitrate", "1000000"]
    )
    assert refused.exit_code == 1
    assert "REFUSED" in refused.stdout and "exceeds 100 %" in refused.stdout


def test_plan_8_byte_pdos_match_the_anchor_table():
    # 4 axes x 2 x 8 B at 1 ms: 113.5 % worst case (docs/canopen.md), refused
    result = runner.invoke(
        drives_app, ["plan", "--axes", "4", "--pdo-bytes", "8", "--heartbeat-ms", "0"]
    )
    assert result.exit_code == 1 and "113.5%" in result.stdout


def test_serve_rejects_bad_nodes():
    result = runner.invoke(drives_app, ["serve", "--nodes", "2,x"])
    assert result.exit_code == 2
    result = runner.invoke(drives_app, ["serve", "--nodes", "2,2"])
    assert result.exit_code == 2


def test_serve_answers_a_master_on_the_virtual_bus():
    import threading

    import canopen

    channel = "fmscell-cli-serve"
    network = canopen.Network()
    node = canopen.RemoteNode(4, EDS_PATH)
    network.add_node(node)
    network.connect(interface="virtual", channel=channel)
    done = {}

    def serve():
        done["result"] = runner.invoke(
            drives_app,
            [
                "serve",
                "--interface",
                "virtual",
                "--channel",
                channel,
                "--nodes",
                "4,5",
                "--seconds",
                "3",
            ],
        )

    thread = threading.Thread(target=serve)
    thread.start()
    try:
        import time

        from canopen.sdo.exceptions import SdoCommunicationError

        deadline = time.monotonic() + 5.0
        while True:  # bounded: the server thread needs a moment to come up
            try:
                assert node.sdo[0x1000].raw == 0x00020192
                break
            except SdoCommunicationError:
                assert time.monotonic() < deadline, "drive 4 never answered SDO"
        other = canopen.RemoteNode(5, EDS_PATH)
        network.add_node(other)
        assert other.sdo[0x1018][4].raw == 5
    finally:
        thread.join(timeout=10)
        network.disconnect()
    assert done["result"].exit_code == 0
    assert "serving CiA 402 drive(s) [4, 5]" in done["result"].stdout

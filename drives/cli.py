"""`fmscell drives ...`: the virtual CANopen drives' command line."""

from __future__ import annotations

import typer

from drives import EDS_PATH

drives_app = typer.Typer(help="Virtual CiA 402 drives on CANopen.", no_args_is_help=True)


@drives_app.command()
def eds() -> None:
    """Print the path of the drives' EDS file (load it in your CANopen master)."""
    typer.echo(EDS_PATH)


@drives_app.command()
def plan(
    axes: int = typer.Option(3, min=1, max=127, help="number of CSP axes on the line"),
    sync_ms: float = typer.Option(1.0, help="SYNC period = IPO cycle, ms"),
    bitrate: int = typer.Option(1_000_000, min=10_000, help="CAN bitrate, bit/s"),
    pdo_bytes: int = typer.Option(6, min=0, max=8, help="bytes per RPDO and per TPDO"),
    heartbeat_ms: float = typer.Option(100.0, help="heartbeat period per node, ms (0 = off)"),
) -> None:
    """Worst-case bus load of the cyclic CSP traffic; exit 1 above 100 %."""
    import warnings

    # deferred: drives.bus loads python-can, which only this and `serve` need
    from drives.bus import BusLoadWarning, BusOverloadError, axis_traffic, plan_load

    if sync_ms <= 0:
        typer.echo("plan: --sync-ms must be > 0", err=True)
        raise typer.Exit(2)
    frames = axis_traffic(
        axes,
        rpdo_bytes=pdo_bytes,
        tpdo_bytes=pdo_bytes,
        heartbeat_s=heartbeat_ms / 1000.0 if heartbeat_ms > 0 else None,
    )
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", BusLoadWarning)
            result = plan_load(frames, sync_period_s=sync_ms / 1000.0, bitrate=bitrate)
    except BusOverloadError as exc:
        typer.echo(f"REFUSED: {exc}")
        raise typer.Exit(1) from None
    status = "WARNING (above 70 %)" if caught else "OK"
    typer.echo(f"{status}: {axes} axes, {result.describe()}")


@drives_app.command()
def serve(
    interface: str = typer.Option("virtual", help="socketcan | virtual | sim"),
    channel: str = typer.Option("can0", help="CAN channel (socketcan: the interface name)"),
    node: int = typer.Option(2, min=1, max=127, help="node-ID of a single drive"),
    nodes: str = typer.Option("", help="comma-separated node-IDs (overrides --node)"),
    bitrate: int = typer.Option(1_000_000, help="bitrate (sim only; set real ones with ip link)"),
    substep_us: float = typer.Option(125.0, help="plant integration sub-step, us"),
    seconds: float = typer.Option(0.0, help="stop after this many seconds (0 = until Ctrl-C)"),
    socketcand: str = typer.Option(
        "",
        help="also serve the bus over TCP at [HOST:]PORT for python-can's `socketcand` "
        "interface (a master in another process or host; HOST defaults to 127.0.0.1)",
    ),
) -> None:
    """Run virtual CiA 402 drives in realtime for your own CANopen master."""
    import time

    # deferred: python-can and canopen, which only this and `plan` need
    from drives.bus import get_hub, open_bus
    from drives.bus.socketcand import SocketcandServer, parse_address
    from drives.virtual_drive import VirtualDrive

    try:
        ids = [int(n) for n in nodes.split(",") if n.strip()] if nodes else [node]
    except ValueError:
        typer.echo(f"serve: --nodes must be comma-separated integers, got {nodes!r}", err=True)
        raise typer.Exit(2) from None
    if any(not 1 <= n <= 127 for n in ids) or len(set(ids)) != len(ids):
        typer.echo(f"serve: node-IDs must be unique and 1..127, got {ids}", err=True)
        raise typer.Exit(2)
    config = {"interface": interface, "channel": channel}
    if interface == "sim":
        config["bitrate"] = bitrate
    try:
        bus = open_bus(config) if interface != "sim" else None
        if interface == "sim":
            hub = get_hub(channel, bitrate=bitrate, mode="realtime")
    except (ValueError, OSError) as exc:
        typer.echo(f"serve: cannot open {interface}:{channel}: {exc}", err=True)
        raise typer.Exit(2) from None
    server = None
    if socketcand:

        def open_endpoint(name: str):
            return hub.endpoint(name) if interface == "sim" else open_bus(config)

        try:
            host, port = parse_address(socketcand)
            server = SocketcandServer(open_endpoint, channel, host=host, port=port).start()
        except (ValueError, OSError) as exc:
            typer.echo(f"serve: cannot serve socketcand at {socketcand}: {exc}", err=True)
            raise typer.Exit(2) from None
        if host not in ("127.0.0.1", "localhost", "::1"):
            typer.echo(
                f"serve: WARNING: socketcand on {host} lets anyone who reaches it command "
                "the drives (no authentication, no encryption)",
                err=True,
            )
    drives = []
    for n in ids:
        drive_bus = hub.endpoint(f"node{n}") if interface == "sim" else bus
        if interface == "virtual" and n != ids[0]:
            drive_bus = open_bus(config)  # python-can virtual: one endpoint per receiver
        drives.append(VirtualDrive(n, drive_bus, substep=substep_us * 1e-6).start())
    where = f"{interface}:{channel}"
    if server is not None:
        where += f" and socketcand {server.address[0]}:{server.address[1]}"
    # a parent process (a test, a supervisor) waits for this line before it connects
    typer.echo(f"serving CiA 402 drive(s) {ids} on {where}; EDS: {__import__('drives').EDS_PATH}")
    try:
        deadline = time.monotonic() + seconds if seconds > 0 else None
        while deadline is None or time.monotonic() < deadline:
            time.sleep(0.1)
    except KeyboardInterrupt:
        pass
    finally:
        if server is not None:
            server.close()
        for d in drives:
            d.stop()

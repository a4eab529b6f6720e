"""`fmscell plc ...`: the soft-PLC's command line."""

from __future__ import annotations

import typer

plc_app = typer.Typer(help="Soft-PLC: check and run ladder programs.", no_args_is_help=True)


@plc_app.command("check")
def check(
    file: str = typer.Argument(
        ..., help="Ladder program: neutral text (.ld) or PLCopen TC6 (.xml)"
    ),
    watchdog_ms: float = typer.Option(
        100.0, "--watchdog-ms", help="Scan watchdog the estimated scan time is checked against"
    ),
    export: bool = typer.Option(False, "--export", help="Print the program as neutral text"),
) -> None:
    """Check a program: exit 0 when valid (warnings printed), else 1 with FILE:LINE:COL lines."""
    import os

    # deferred: the ladder compiler is not loaded for the rest of `fmscell`
    from plc.ladder import check_file, format_program, import_plcopen, load_file, parse_program

    if not os.path.isfile(file):
        typer.echo(f"{file}:1:1: error: no such file", err=True)
        raise typer.Exit(1)
    try:
        diagnostics = check_file(file, watchdog_ms=watchdog_ms)
    except UnicodeDecodeError as exc:
        typer.echo(f"{file}:1:1: error: not UTF-8 text ({exc.reason})", err=True)
        raise typer.Exit(1) from None
    errors = [d for d in diagnostics if d.severity == "error"]
    for d in diagnostics:
        typer.echo(str(d), err=d.severity == "error")
    if errors:
        typer.echo(
            f"{file}: {len(errors)} error(s), {len(diagnostics) - len(errors)} warning(s)", err=True
        )
        raise typer.Exit(1)
    program = load_file(file, watchdog_ms=watchdog_ms)
    if export:
        if file.lower().endswith(".xml"):
            tree, _ = import_plcopen(file)
        else:
            with open(file, encoding="utf-8") as f:
                tree, _ = parse_program(f.read(), file)
        typer.echo(format_program(tree), nl=False)
    else:
        typer.echo(
            f"{file}: OK, program {program.name!r}: {len(program.rungs)} rungs, "
            f"{len([t for t in program.tags.values() if not t.name.startswith('S_')])} tags, "
            f"estimated scan {program.estimate_us:.1f} us, {len(program.warnings)} warning(s)"
        )


@plc_app.command("run")
def run(
    file: str = typer.Argument(
        ..., help="Ladder program: neutral text (.ld) or PLCopen TC6 (.xml)"
    ),
    period_ms: int = typer.Option(10, "--period-ms", min=1, help="Scan period"),
    modbus_host: str = typer.Option("127.0.0.1", "--modbus-host", help="Modbus TCP bind address"),
    modbus_port: int = typer.Option(5020, "--modbus-port", help="Modbus TCP port (0 = any free)"),
    writable: str = typer.Option(
        "",
        "--writable",
        help="Modbus write allow-list, e.g. 'coil:0-15,%MW0-99' (default: everything read-only)",
    ),
    watchdog_ms: float = typer.Option(None, "--watchdog-ms", help="Watchdog (default 10 x period)"),
    debounce: int = typer.Option(
        0, "--debounce", min=0, help="Input debounce samples (4 = GE filter)"
    ),
    retain: str = typer.Option("", "--retain", help="File keeping RETAIN data over restarts"),
    duration_s: float = typer.Option(
        0.0, "--duration-s", help="Stop after this long (0 = until ^C)"
    ),
    machine_io: bool = typer.Option(
        False,
        "--machine-io",
        help="Wire the simulated machine (spindle, coolant, tool changer, door, E-stop chain, "
        "air, lube) as the I/O, for the machine-tool program; also opens the remote panel "
        "allow-list unless --writable is given",
    ),
    scan_gate: bool = typer.Option(
        False,
        "--scan-gate",
        help="The Modbus face steps aside (GIL released) just before each scan: steadier "
        "scans under heavy Modbus load, somewhat fewer requests/s",
    ),
    rt_priority: int = typer.Option(
        0,
        "--rt-priority",
        min=0,
        max=99,
        help="SCHED_FIFO priority for the scan thread (the face gets one below); 0 = off. "
        "Needs CAP_SYS_NICE; refused quietly, reported at the end",
    ),
) -> None:
    """Run a program standalone in realtime with its Modbus TCP face until interrupted."""
    import signal
    import threading

    # deferred: the ladder compiler, the runtime and the Modbus face are not loaded for the
    # rest of `fmscell`
    from plc.ladder import LadderError, load_file
    from plc.machine_io import MachineIO
    from plc.modbus import AllowListError, ModbusFace
    from plc.remote_panel import WRITABLE
    from plc.runtime import FileRetainStore, RealtimeRunner, Runtime, RuntimeConfig

    try:
        program = load_file(file)
    except LadderError as exc:
        for d in exc.diagnostics:
            typer.echo(str(d), err=True)
        raise typer.Exit(1) from None
    except OSError as exc:
        typer.echo(f"{file}:1:1: error: {exc.strerror}", err=True)
        raise typer.Exit(1) from None
    config = RuntimeConfig(period_ms=period_ms, watchdog_ms=watchdog_ms, debounce_samples=debounce)
    store = FileRetainStore(retain) if retain else None
    io = None
    if machine_io:
        io = MachineIO()
        writable = writable or WRITABLE
    runtime = Runtime(program, config, retain_store=store, io=io)
    try:  # built before the face: the face takes its gate
        runner = RealtimeRunner(runtime, rt_priority=rt_priority or None)
    except ValueError as exc:  # e.g. a malformed FMSCELL_PLC_RT_PRIORITY
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    try:
        face = ModbusFace(
            lambda: runtime.snapshot,
            runtime.writes,
            runtime.image.size,
            host=modbus_host,
            port=modbus_port,
            writable=writable or None,
            scan_gate=runner.gate if scan_gate else None,
        )
    except (AllowListError, ValueError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        face.start_in_thread(rt_priority=max(0, rt_priority - 1))
    except OSError as exc:
        typer.echo(f"error: Modbus TCP on {modbus_host}:{modbus_port}: {exc.strerror}", err=True)
        raise typer.Exit(2) from None
    runner.start()
    typer.echo(
        f"PLC {program.name!r} running: {len(program.rungs)} rungs every {period_ms} ms, "
        f"Modbus TCP on {modbus_host}:{face.bound_port}",
        err=False,
    )
    try:
        stop.wait(duration_s if duration_s > 0 else None)
    except KeyboardInterrupt:
        pass
    finally:
        runner.stop()
        face.stop_thread()
        signal.signal(signal.SIGTERM, previous)
    s = runtime.stats.as_dict()
    typer.echo(
        f"stopped after {s['scans']} scans: exec p99 {s['exec_us']['p99']:.1f} us, "
        f"lateness p99 {s['late_ms']['p99']:.3f} ms, overruns {s['overruns']}, "
        f"missed {s['missed']}, mode {runtime.mode}"
    )
    if rt_priority and runner.scheduling:
        typer.echo(f"scan thread scheduling: {runner.scheduling}")
    if runner.error is not None:
        typer.echo(f"scan thread failed: {runner.error!r}", err=True)
        raise typer.Exit(1)

"""`fmscell cam ...`: the APT processor and the post-processors on the command line."""

from __future__ import annotations

import hashlib
import json
import os
import sys
import tempfile
from pathlib import Path

import typer

from cam.apt import process
from cam.chain import records_from_file
from cam.cl import write_cl
from cam.errors import CamError
from cam.post import PostOptions, load_machine, post
from cnc.interp import check

cam_app = typer.Typer(
    help="CAM to machine: APT source -> CL data -> a machine's NC program.", no_args_is_help=True
)

NOT_CHECKED_5AXIS = "not available: the NC kernel has no machine of this kind"


def _fail(msg: str, code: int) -> typer.Exit:
    typer.echo(msg, err=True)
    return typer.Exit(code)


@cam_app.command("cl")
def cl_cmd(
    file: Path = typer.Argument(..., help="APT part program"),
    out: Path | None = typer.Option(None, "-o", "--output", help="write the CL data here"),
) -> None:
    """Process an APT program and print its CL data (one statement a line)."""
    try:
        text = file.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise _fail(f"{file}:0:0: cannot read: {e}", 2) from None
    warnings: list = []
    try:
        records = list(process(text, str(file), warnings.append))
    except CamError as e:
        for w in warnings:
            typer.echo(str(w), err=True)
        raise _fail(str(e), 1) from None
    for w in warnings:
        typer.echo(str(w), err=True)
    if out is None:
        write_cl(records, sys.stdout)
    else:
        _atomic_write(out, lambda fh: write_cl(records, fh))


def _atomic_write(path: Path, writer) -> None:
    fd, tmp = tempfile.mkstemp(prefix=".cam-", dir=str(path.resolve().parent))
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as fh:
            writer(fh)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@cam_app.command("post")
def post_cmd(
    file: Path = typer.Argument(..., help="APT source or CL data"),
    machine: str = typer.Option(..., "--machine", help="mill3, lathe2, mill5 or a machine YAML"),
    tolerance: float | None = typer.Option(
        None, "--tolerance", help="5-axis linearisation (and merging) tolerance T, mm (0.01)"
    ),
    out: Path | None = typer.Option(None, "-o", "--output", help="write the NC program here"),
    as_json: bool = typer.Option(False, "--json", help="print a JSON summary"),
    fmt: str | None = typer.Option(None, "--format", help="apt or cl (default: by suffix/content)"),
    program_number: int | None = typer.Option(None, "--program-number", help="O number"),
    merge: bool = typer.Option(False, "--merge", help="merge collinear blocks within T"),
    g54: str = typer.Option(
        "", "--g54", help="work offset 'X,Y,Z' mm for the travel check (3-axis kinds)"
    ),
) -> None:
    """Post APT source or CL data for a machine. The program is written only when the whole
    post (and, for mill and lathe kinds, `nc check`) succeeds."""
    if fmt not in (None, "apt", "cl"):
        raise _fail(f"--format must be apt or cl, not {fmt!r}", 2)
    if tolerance is not None and not tolerance > 0:
        raise _fail(f"--tolerance must be > 0 mm, not {tolerance:g}", 2)
    offsets = None
    if g54:
        try:
            xyz = tuple(float(v) for v in g54.split(","))
            if len(xyz) != 3:
                raise ValueError
        except ValueError:
            raise _fail(f"--g54 must be 'X,Y,Z' in mm, not {g54!r}", 2) from None
        offsets = {1: xyz}
    try:
        mach = load_machine(machine)
    except CamError as e:
        raise _fail(str(e), 2) from None
    opts = PostOptions(tolerance_mm=tolerance, program_number=program_number, merge=merge)
    dest_dir = out.resolve().parent if out else Path(tempfile.gettempdir())
    fd, tmp = tempfile.mkstemp(prefix=".cam-post-", suffix=".nc", dir=str(dest_dir))
    tmp_path = Path(tmp)
    try:
        try:
            kind, records = records_from_file(file, fmt)
            p, blocks = post(records, mach, opts, str(file))
            digest = hashlib.sha256()
            with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as fh:
                for b in blocks:
                    line = b.text + "\n"
                    fh.write(line)
                    digest.update(line.encode())
        except (OSError, UnicodeDecodeError) as e:
            raise _fail(f"{file}:0:0: cannot read: {e}", 2) from None
        except CamError as e:
            raise _fail(str(e), 1) from None
        summary = p.summary
        check = _nc_check(
            tmp_path,
            mach,
            offsets,
            file,
            lambda: post(records_from_file(file, fmt)[1], mach, opts, str(file))[1],
        )
        result = {
            "file": str(file),
            "format": kind,
            "machine": mach.name,
            "kind": mach.kind,
            "post": p.name,
            "post_version": p.version,
            "tolerance_mm": getattr(p, "tol_mm", None),
            **summary.as_dict(),
            "nc_check": check["status"],
            "travel_checked": check["travel"],
            "sha256": digest.hexdigest(),
            "output": str(out) if out else None,
        }
        if check["errors"]:
            for e in check["errors"]:
                typer.echo(e, err=True)
            if as_json:
                typer.echo(json.dumps(result, sort_keys=True))
            raise typer.Exit(1)
        if out is not None:
            os.replace(tmp_path, out)
        elif not as_json:
            sys.stdout.write(tmp_path.read_text(encoding="utf-8"))
        if as_json:
            typer.echo(json.dumps(result, sort_keys=True))
        else:
            for w in summary.warnings:
                typer.echo(str(w), err=True)
    finally:
        tmp_path.unlink(missing_ok=True)


def _nc_check(path: Path, mach, offsets, source: Path, repost) -> dict:
    """`nc check` of the posted program for the kinds the NC kernel runs; an error's NC line
    is traced back to the CL/APT line that produced it."""
    from dataclasses import replace

    machine_data = None
    if mach.kind == "mill5":
        # the NC's mill5 (cnc/machines/mill5.yaml, the post's geometry and travel): its
        # G54 is 0, so the post's travel check is the machine's
        from cnc.config import builtin_machine  # deferred: not loaded for `fmscell --help`

        params = builtin_machine("mill5").params
        travel = True
    elif mach.kind not in ("mill", "lathe"):
        return {"status": NOT_CHECKED_5AXIS, "travel": False, "errors": []}
    else:
        params = mach.config.params
        if offsets is None and mach.config.machine_data is not None:
            # no --g54: the machine's own setup (its shipped or configured machine data,
            # work offsets and tool lengths) places the program, as it will on the machine
            machine_data = mach.config.machine_data.initial()
        travel = offsets is not None or machine_data is not None
    if not travel:
        big = 1e9
        params = replace(
            params, axes=tuple(replace(a, min_mm=-big, max_mm=big) for a in params.axes)
        )
    with open(path, encoding="utf-8") as fh:
        errors = check(fh, params, file=str(path), work_offsets=offsets, machine_data=machine_data)
    if not errors:
        return {"status": "passed", "travel": travel, "errors": []}
    wanted = {e.line for e in errors}
    cl_line: dict[int, int] = {}
    for n, b in enumerate(repost(), 1):
        if n in wanted:
            cl_line[n] = b.cl_line
    msgs = [
        f"{source}:{cl_line.get(e.line, 0)}:0: posted block {e.line}: {e.message}" for e in errors
    ]
    return {"status": "failed", "travel": travel, "errors": msgs}

"""`fmscell nc check` and `fmscell nc plan` as whole processes on the corpus's largest CAM files.

What a user waits for: `python -m server.cli nc check FILE` and `... nc plan --json FILE`
run as subprocesses (interpreter start-up and imports included) on the three largest CAM
files of `../shared/reference/corpus/gcode` (by size, `origin` CAM in SOURCES.md): wall time
(best of REPEATS) and blocks/s, blocks being the file's non-blank lines. Lathe files get
`--kind lathe` (check) and the shipped lathe (plan). `--no-soft-limits` is added when the
command has it: the figure is the reading speed of the whole file, not how far a program
gets on one particular setup. A run that exits non-zero is still timed and reported with
its exit code and first error (`"ok": false`); a file that does not plan is an error in the
JSON, never a crash of the benchmark.

Peer, same run, same file: LinuxCNC's standalone interpreter `rs274 -g` (Debian package
linuxcnc-uspace; the C++ rs274ngc, interpretation only, writing its canonical calls to a
file), with a tool table of T1..T99. Where it is not installed, or does not read the file,
`"peer"` is null with the reason. Prints one JSON object.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.reference import GCODE_CORPUS, MISSING  # noqa: E402

REPEATS = 3
N_FILES = 3
LATHE_CONFIG = ROOT / "cnc" / "machines" / "lathe2.yaml"


def cam_files(corpus: Path, n: int) -> list[tuple[Path, str]]:
    """The n largest files whose SOURCES.md origin is CAM, with their kind."""
    from tests.cnc.corpus_report import sources_rows

    rows = [
        (corpus / row["file"], row["kind"])
        for row in sources_rows(corpus / "SOURCES.md")
        if row["origin"].startswith("CAM") and (corpus / row["file"]).is_file()
    ]
    rows.sort(key=lambda r: r[0].stat().st_size, reverse=True)
    return rows[:n]


def blocks_of(path: Path) -> int:
    with open(path, encoding="latin-1") as fh:
        return sum(1 for ln in fh if ln.strip())


def options_of(command: str) -> str:
    out = subprocess.run([sys.executable, "-m", "server.cli", "nc", command, "--help"],
                         capture_output=True, text=True, cwd=ROOT, env={**os.environ,
                         "COLUMNS": "200"})  # fmt: skip
    return out.stdout


def argv_for(command: str, path: Path, kind: str, help_text: str) -> list[str]:
    args = [sys.executable, "-m", "server.cli", "nc", command]
    if kind == "lathe":
        if "--kind" in help_text:
            args += ["--kind", "lathe"]
        else:
            args += ["--config", str(LATHE_CONFIG)]
    if "--no-soft-limits" in help_text:
        args.append("--no-soft-limits")
    if command == "plan":
        args.append("--json")
    return [*args, str(path)]


def timed(argv: list[str], cwd: Path) -> tuple[float, subprocess.CompletedProcess[str]]:
    best, proc = float("inf"), None
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        proc = subprocess.run(argv, capture_output=True, text=True, cwd=cwd)
        best = min(best, time.perf_counter() - t0)
    assert proc is not None
    return best, proc


def first_line(text: str) -> str:
    for ln in text.splitlines():
        if ln.strip():
            return ln.strip()[:300]
    return ""


def ours(command: str, path: Path, kind: str, blocks: int, help_text: str) -> dict:
    argv = argv_for(command, path, kind, help_text)
    wall, proc = timed(argv, ROOT)
    out = {
        "argv": " ".join(["fmscell", *argv[3:-1], path.name]).replace(f"{ROOT}/", ""),
        "wall_s": round(wall, 3),
        # a run that stopped early (an error, 1000 errors at most) read less than the file
        "blocks_per_s": round(blocks / wall) if proc.returncode == 0 else None,
        "ok": proc.returncode == 0,
    }
    if proc.returncode != 0:
        out["exit_code"] = proc.returncode
        msg = first_line(proc.stdout if command == "check" else proc.stderr or proc.stdout)
        out["error"] = msg.replace(str(path), path.name)
        if command == "check":
            out["errors"] = sum(1 for ln in proc.stdout.splitlines() if ln.strip())
    elif command == "plan":
        try:
            figures = json.loads(proc.stdout)
        except ValueError:
            figures = {}
        for key in ("machining_s", "duration_s", "samples", "blocks"):
            if key in figures:
                out[key] = figures[key]
    return out


def peer(path: Path, blocks: int, tmp: Path) -> tuple[dict | None, str | None]:
    exe = shutil.which("rs274")
    if exe is None:
        return None, ("LinuxCNC rs274 not installed (Debian: apt-get install linuxcnc-uspace, "
                      "which ships /usr/bin/rs274)")  # fmt: skip
    table = tmp / "tool.tbl"
    if not table.exists():
        table.write_text("".join(f"T{i} P{i} D6.0 Z+0.0 ;bench\n" for i in range(1, 100)))
    out_file = tmp / "rs274.out"
    argv = [exe, "-t", str(table), "-g", str(path), str(out_file)]
    best, proc = float("inf"), None
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        proc = subprocess.run(argv, capture_output=True, text=True, stdin=subprocess.DEVNULL)
        best = min(best, time.perf_counter() - t0)
    assert proc is not None
    text = out_file.read_text(errors="replace") if out_file.exists() else ""
    if proc.returncode != 0 or "PROGRAM_END" not in text:
        said = (proc.stdout + proc.stderr).splitlines()
        why = " / ".join(ln.strip() for ln in said if ln.strip() not in ("", "executing"))[:200]
        return None, f"rs274 does not read it (exit {proc.returncode}): {why}"
    return {"argv": f"rs274 -t tool.tbl -g {path.name} out", "wall_s": round(best, 3),
            "blocks_per_s": round(blocks / best),
            "canon_calls": len(text.splitlines())}, None  # fmt: skip


def rs274_version() -> str | None:
    try:
        out = subprocess.run(["dpkg-query", "-W", "-f", "${Version}", "linuxcnc-uspace"],
                             capture_output=True, text=True)  # fmt: skip
    except OSError:
        return None
    return out.stdout.strip() or None


def main() -> int:
    if not (GCODE_CORPUS / "SOURCES.md").is_file():
        print(json.dumps({"error": MISSING}))
        return 1
    help_check, help_plan = options_of("check"), options_of("plan")
    # what every run pays before reading a block: the interpreter and the CLI's imports
    startup, _ = timed([sys.executable, "-c", "import server.cli, cnc.cli"], ROOT)
    files = []
    with tempfile.TemporaryDirectory(prefix="bench-nc-cli-") as tmp:
        for path, kind in cam_files(GCODE_CORPUS, N_FILES):
            blocks = blocks_of(path)
            entry: dict = {"file": path.name, "kind": kind, "bytes": path.stat().st_size,
                           "blocks": blocks}  # fmt: skip
            entry["check"] = ours("check", path, kind, blocks, help_check)
            entry["plan"] = ours("plan", path, kind, blocks, help_plan)
            peer_fig, why = peer(path, blocks, Path(tmp))
            entry["peer"] = peer_fig
            if peer_fig is None:
                entry["peer_reason"] = why
            else:
                # how many times slower than the C++ interpreter (interpretation only)
                entry["check_vs_peer"] = round(entry["check"]["wall_s"] / peer_fig["wall_s"], 1)
                if entry["plan"]["ok"]:
                    entry["plan_vs_peer"] = round(entry["plan"]["wall_s"] / peer_fig["wall_s"], 1)
            files.append(entry)
    result = {
        "files": files,
        "repeats": REPEATS,
        "startup_s": round(startup, 3),
        "peer_name": "LinuxCNC rs274 (Debian linuxcnc-uspace)",
        "peer_version": rs274_version() if shutil.which("rs274") else None,
        "compiled": any(True for _ in (ROOT / "cnc").rglob("*.so")),  # mypyc extensions
    }
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())

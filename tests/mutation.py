"""Mutation testing of the pure cores with mutmut (`make mutation`, kept out of `make test`).

Each target is one pure-core module and the bounded test selection that is meant to catch
its defects: a mutant the selection does not kill is a defect the tests would not notice.
Every target runs in its own scratch project, <tmp>/fmscell-mutation/<name>/ (or under
$FMSCELL_MUTATION_DIR): a copy of the packages without compiled extensions (a mypyc module
would shadow its mutants), the tests, and a pyproject.toml with the project's pytest settings
and a [tool.mutmut] block for that target. mutmut's mutants/ copy never lands in the
checkout, and each module is measured against its own tests only (the whole suite per
mutant would take days).

mutmut 3 runs pytest inside mutants/ with `--rootdir=.`, so the project's `pythonpath =
["."]` puts the mutated copy first; an editable install of fmscell would still answer for a
package missing there, which is why every package is copied, not only the target's.

    python -m tests.mutation                       # every target present, score table + JSON
    python -m tests.mutation drives/cia402/statemachine.py
    python -m tests.mutation --list
    python -m tests.mutation --min-score 90        # exit 1 when a target scores lower

Add a module by adding a line to TARGETS; a target whose source file does not exist yet is
reported as `absent` and skipped (the allocation state machine is listed before it lands).
The score is killed / (killed + survived + suspicious) over the mutants mutmut generated (a
timeout, a mutant that makes a selected test hang, counts as killed); mutants no selected
test reaches ("no tests") count as survivors, because that is what they are. A mutant that
cannot change behaviour is listed in EQUIVALENT with its reason and left out of the score.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WORK = Path(
    os.environ.get("FMSCELL_MUTATION_DIR") or Path(tempfile.gettempdir()) / "fmscell-mutation"
)
# The packages copied into each scratch project: all of ours, so that nothing a test imports
# falls through to an installed copy of fmscell outside the mutants/ tree.
PACKAGES = ("drives", "plc", "cnc", "dnc", "server", "web_api")

# module -> test files (globs) that form its bounded selection; "-<node id>" deselects a test
TARGETS: dict[str, tuple[str, ...]] = {
    "drives/cia402/statemachine.py": (
        "tests/drives/test_cia402_statemachine*.py",
        "tests/drives/test_cia402_conformance.py",
    ),
    "plc/modbus/pdu.py": (
        "tests/plc/test_modbus_core.py",
        "tests/plc/test_modbus_frames.py",
        "tests/plc/test_modbus_pdu*.py",
        # a server backpressure test, not a PDU one: 40 000 requests through mutmut's
        # instrumented handler outlast the face's stop time-out
        "-tests/plc/test_modbus_frames.py::test_client_that_never_reads_does_not_block_others",
    ),
    "dnc/rules.py": ("tests/dnc/test_rules*.py",),
    # the table of every state x machine event (the cell and model tests run a scheduler on
    # SQLite: minutes per mutant)
    "dnc/allocation.py": ("tests/dnc/test_allocation.py",),
    "cnc/interp/modes.py": (
        "tests/cnc/test_interp_modes.py",
        "tests/cnc/test_interp_offsets.py",
        "tests/cnc/test_interp_codes.py",
        "tests/cnc/test_interp_code_table.py",
        "tests/cnc/test_interp_errors.py",
        "tests/cnc/test_interp_motion.py",
    ),
    "cnc/interp/offsets.py": (
        "tests/cnc/test_interp_offsets.py",
        "tests/cnc/test_interp_modes.py",
        "tests/cnc/test_interp_codes.py",
        "tests/cnc/test_interp_errors.py",
        "tests/cnc/test_interp_motion.py",
        "tests/cnc/test_machine_data.py",
    ),
    "cnc/interp/compensation.py": (
        "tests/cnc/test_interp_compensation.py",
        "tests/cnc/test_interp_codes.py",
        "tests/cnc/test_interp_cutter_comp.py",
        "tests/cnc/test_interp_errors.py",
        "tests/cnc/test_machine_data.py",
    ),
    "cnc/interp/auxiliary.py": (
        "tests/cnc/test_interp_codes.py",
        "tests/cnc/test_interp_modes.py",
        "tests/cnc/test_interp_errors.py",
    ),
    "cnc/interp/motion.py": (
        "tests/cnc/test_interp_motion_group.py",
        "tests/cnc/test_interp_codes.py",
        "tests/cnc/test_interp_motion.py",
        "tests/cnc/test_interp_errors.py",
        "tests/cnc/test_interp_cycles.py",
    ),
}

# Mutants that cannot change what the module does, each with the reason: left out of the
# score (killed / scored) and listed as `equivalent` in the report. Keyed by mutmut's name,
# which stays put while the function's source does; a renamed or re-numbered mutant shows up
# as a survivor again and has to be looked at anew.
EQUIVALENT: dict[str, str] = {
    # plc/modbus/pdu.py: the FC03 fast path falls back to the general path, which answers
    # the same bytes (tests/plc/test_modbus_pdu_edges.py pins both); only these loosen or
    # tighten its entry test without changing an answer
    "plc.modbus.pdu.xǁPduHandlerǁ_read_holding_registers__mutmut_14": (
        "address - count <= end: the slice-length check sends a read past the area to the "
        "general path"
    ),
    # a table has at most two areas (ModbusMap), so a write has at most two pieces
    "plc.modbus.pdu.x__bit_batch__mutmut_13": "off = n equals off += n after the first piece",
    "plc.modbus.pdu.x__word_batch__mutmut_12": "off = n equals off += n after the first piece",
    # ModbusMap refuses an area beyond 65535, so map.resolve() is None for any request past it
    "plc.modbus.pdu.xǁPduHandlerǁ_resolve__mutmut_1": "the map refuses what passes 65536",
    "plc.modbus.pdu.xǁPduHandlerǁ_resolve__mutmut_3": "the map refuses what passes 65536",
    # struct.pack with no values raises struct.error: the fallback packs every int
    # -32768..65535 to the same two bytes
    "plc.modbus.pdu.x__pack_words__mutmut_3": "the unsigned fallback packs the same bytes",
    # the batch takes exactly the mapped count from the unpacked bits
    "plc.modbus.pdu.xǁPduHandlerǁ_write_multiple_coils__mutmut_35": (
        "unpack_bits(..., None) keeps the padding bits, which no piece takes"
    ),
    # codec names are case-insensitive
    "plc.modbus.pdu.xǁDeviceIdentityǁobjects__mutmut_7": "'ASCII' is the same codec",
    # cnc/interp: an error's column is found by cnc.gcode.lexer.find_col, which upper-cases
    # the address letter it looks for (a block's words are case-insensitive), so "g" is "G"
    **{
        f"cnc.interp.{name}": "find_col upper-cases the letter: the same column"
        for name in (
            "modes.x_accuracy__mutmut_20",  # G187 P
            "modes.x_accuracy__mutmut_46",  # G187 E
            "modes.x_lookahead_limit__mutmut_23",  # G103 P
            "modes.x_path_mode__mutmut_33",  # G64 P
            "modes.x_plane__mutmut_19",  # plane change in cutter compensation
            "modes.x_plane__mutmut_32",  # plane change in G68
            "modes.x_speed_word__mutmut_18",  # negative S
            "modes.x_units__mutmut_22",  # unit change after motion
            "offsets.x_select_work_offset__mutmut_23",  # G54.1 P
            "offsets.x_reference_return__mutmut_17",  # G28/G30 in cutter compensation
            "offsets.x_reference_return__mutmut_42",  # G30 P3/P4
            "offsets.x_machine_move__mutmut_22",  # G53 in G91
            "offsets.x_machine_move__mutmut_35",  # G53 in cutter compensation
            "offsets.x_machine_move__mutmut_53",  # G53 with G2/G3
            "motion.x_motion__mutmut_37",  # a motion code beside G4, G28 with a cycle...
        )
    },
    # G53 moves the rotary axes with machine=True, which takes the word as the machine angle
    # before `absolute` is read
    "cnc.interp.offsets.x_machine_move__mutmut_57": "absolute=None: machine=True decides",
    "cnc.interp.offsets.x_machine_move__mutmut_63": "absolute=False: machine=True decides",
    # G28/G30 on a lathe: m[1] is 0 already, from the intermediate move (_line_to puts a
    # lathe's Y at 0) or from the reference point (a lathe has no Y axis: home Y 0)
    "cnc.interp.offsets.x_reference_return__mutmut_106": "a lathe's m[1] is 0 on every path",
    # an H with G43/G44/G49 in the block: the code's handler runs first at the same step
    # (codes before words) and took the H; the word's handler would apply the same again
    "cnc.interp.compensation.x_h_word__mutmut_1": "length_comp already applied this H",
    "cnc.interp.compensation.x_h_word__mutmut_2": "length_comp already applied this H",
    "cnc.interp.compensation.x_apply_length__mutmut_33": "resync=None is as falsy as False",
    # dnc/rules.py: getattr(rule, "setup_aware", False) is only tested for truth; a rule
    # without the attribute gives None instead of False, as falsy
    **{
        f"dnc.rules.{name}": "getattr's default None is as falsy as False"
        for name in (
            "x__plain__mutmut_6",
            "x_rule_named__mutmut_14",
            "x_rule_named__mutmut_24",
            "x_rule_named__mutmut_41",
        )
    },
}

# mutmut's result names (its `exit_code_to_status`) grouped for the score
# A timeout is a kill: the mutant made a selected test hang, which the suite notices.
KILLED = {"killed", "caught by type check", "timeout"}
NOT_KILLED = {"survived", "no tests", "suspicious", "segfault"}


def _slug(module: str) -> str:
    return module.removesuffix(".py").replace("/", ".")


def _selection(globs: tuple[str, ...]) -> list[str]:
    files: list[str] = []
    for pattern in globs:
        if pattern.startswith("-"):
            files += ["--deselect", pattern[1:]]
            continue
        files += sorted(str(p.relative_to(ROOT)) for p in ROOT.glob(pattern))
    return files


def _pyproject(module: str, tests: list[str]) -> str:
    """The scratch project's pyproject: the real pytest settings plus this target's mutmut."""
    real = tomllib.loads((ROOT / "pyproject.toml").read_text())
    pytest_opts = real["tool"]["pytest"]["ini_options"]

    def arr(items) -> str:
        return "[" + ", ".join(json.dumps(str(x)) for x in items) + "]"

    lines = ["[tool.pytest.ini_options]"]
    for key, value in pytest_opts.items():
        if key == "testpaths":
            continue
        lines.append(f"{key} = {arr(value) if isinstance(value, list) else json.dumps(value)}")
    lines += [
        "",
        "[tool.mutmut]",
        f"source_paths = {arr(PACKAGES)}",
        f"only_mutate = {arr([module])}",
        # the scratch copies are thrown away: no pytest cache beside them
        f"pytest_add_cli_args = {arr(['-p', 'no:cacheprovider'])}",
        f"pytest_add_cli_args_test_selection = {arr(tests)}",
        # the tree's files other than .py (EDS, ladder programs) are copied with the packages;
        # the reference material is reached through FMSCELL_SHARED, never copied
        "use_git_change_detection = false",
        # tests that hold the docs against the code (the G-code tables) read docs/ (linked)
        'also_copy = ["docs"]',
        "",
    ]
    return "\n".join(lines)


def _prepare(module: str, tests: list[str]) -> Path:
    work = WORK / _slug(module)
    if work.exists():
        shutil.rmtree(work)  # a stale mutants/ would report yesterday's code
    work.mkdir(parents=True)
    skip = shutil.ignore_patterns("*.so", "*.pyd", "__pycache__", "*.pyc")
    for name in PACKAGES:
        shutil.copytree(ROOT / name, work / name, ignore=skip)
    (work / "tests").symlink_to(ROOT / "tests", target_is_directory=True)
    (work / "docs").symlink_to(ROOT / "docs", target_is_directory=True)
    (work / "pyproject.toml").write_text(_pyproject(module, tests))
    return work


def _env() -> dict[str, str]:
    env = dict(os.environ)
    # the scratch project's own directory is put first by mutmut; the checkout must not be on
    # the path (it would shadow the mutants), the shared reference material must be found
    env.pop("PYTHONPATH", None)
    extra = os.environ.get("FMSCELL_MUTMUT_PATH")  # a mutmut installed with --target
    if extra:
        env["PYTHONPATH"] = extra
    env.setdefault("FMSCELL_SHARED", str(ROOT.parent / "shared"))
    return env


def _results(work: Path, env: dict[str, str]) -> dict[str, str]:
    out = subprocess.run(
        [sys.executable, "-m", "mutmut", "results", "--all", "true"],
        cwd=work,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    status: dict[str, str] = {}
    for line in out.splitlines():
        name, sep, result = line.strip().rpartition(": ")
        if sep and name:
            status[name] = result.strip()
    return status


def run_target(module: str, max_children: int) -> dict:
    tests = _selection(TARGETS[module])
    if not (ROOT / module).exists():
        return {"module": module, "status": "absent"}
    if not tests:
        return {"module": module, "status": "no tests", "selection": list(TARGETS[module])}
    work = _prepare(module, tests)
    env = _env()
    cmd = [sys.executable, "-m", "mutmut", "run", "--max-children", str(max_children)]
    proc = subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.stderr.write(proc.stdout[-4000:] + proc.stderr[-4000:])
        return {"module": module, "status": f"mutmut failed ({proc.returncode})"}
    status = _results(work, env)
    for name in status:
        if name in EQUIVALENT and status[name] in NOT_KILLED:
            status[name] = "equivalent"
    counts: dict[str, int] = {}
    for result in status.values():
        counts[result] = counts.get(result, 0) + 1
    killed = sum(n for r, n in counts.items() if r in KILLED)
    scored = killed + sum(n for r, n in counts.items() if r in NOT_KILLED)
    survivors = sorted(n for n, r in status.items() if r in NOT_KILLED)
    return {
        "module": module,
        "status": "ok",
        "tests": tests,
        "mutants": len(status),
        "counts": counts,
        "score": round(100.0 * killed / scored, 1) if scored else None,
        "survivors": survivors,
        "workdir": str(work),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("modules", nargs="*", help="targets to run (default: all of TARGETS)")
    ap.add_argument("--list", action="store_true", help="print the targets and exit")
    ap.add_argument("--max-children", type=int, default=1, help="parallel mutant runs")
    ap.add_argument("--min-score", type=float, default=None, help="fail below this score (%%)")
    args = ap.parse_args(argv)
    if args.list:
        for module, globs in TARGETS.items():
            present = "" if (ROOT / module).exists() else "  (absent)"
            print(f"{module}{present}: {' '.join(_selection(globs)) or ' '.join(globs)}")
        return 0
    unknown = [m for m in args.modules if m not in TARGETS]
    if unknown:
        ap.error(f"not a mutation target: {', '.join(unknown)} (see --list)")
    reports = []
    for module in args.modules or list(TARGETS):
        rep = run_target(module, args.max_children)
        reports.append(rep)
        score = rep.get("score")
        line = f"{module}: {rep['status']}"
        if rep["status"] == "ok":
            line += f", {rep['mutants']} mutants, score {score} %, {rep['counts']}"
            for name in rep["survivors"]:
                line += f"\n    survived: {name}  (mutmut show {name}, in {rep['workdir']})"
        print(line, flush=True)
    print(
        json.dumps(
            {"mutation": [{k: v for k, v in r.items() if k != "survivors"} for r in reports]}
        )
    )
    if args.min_score is not None:
        low = [r for r in reports if r["status"] == "ok" and (r["score"] or 0.0) < args.min_score]
        failed = [r for r in reports if r["status"].startswith("mutmut failed")]
        if low or failed:
            return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

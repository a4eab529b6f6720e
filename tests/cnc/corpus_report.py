"""The corpus of real part programs as a test: `make corpus`, `make corpus-baseline`.

Every file of `../shared/reference/corpus/gcode` (tests/reference.py GCODE_CORPUS; never
copied into the repository) is checked exactly as a new user would check it:
`fmscell nc check FILE`, or `fmscell nc check --kind lathe FILE` for the files whose
SOURCES.md kind is lathe, with no other flag, so the shipped machines' defaults decide;
unless the baseline gives the file a setup (below), as a setter would make it (the
programs with rotary A words get `--config mill4`, the 4-axis mill); a program that calls
programs of other files (M98 P / G65 P / G66 P) is checked with `--library` its shop's
folder (the corpus files from its SOURCES.md repository), and a file that ends in M99 is
checked by `nc check` in subprogram mode.
The command line runs in this process (typer's runner) to spare 95 interpreter start-ups;
its exit code and output are the ones a shell would see.

The result is compared with the checked-in baseline tests/cnc/corpus_expected.yaml, one
entry per file:

    expect: pass                       the file must keep passing
    expect: fail,    error: "L:C: ..." today's first error (a known gap, part 2's work)
    expect: invalid, reason: "..."     another controller's language (Okuma, Siemens 840D
                                       native, Marlin, ...): excluded from N passed / M failed
    expect: refused-by-controller,     a program of our dialect that the real control refuses
      alarm: "PS0041", reason: "..."   too (the defect and the evidence in reason): it must keep
                                       failing, and its first error must name that alarm

and with any of them `args: [...]` (extra `nc check` options: `--no-soft-limits`,
`--gcode-system B`, `--units inch`, `--g54 X,Y,Z`, `--g65 "A.125 C.625"`, `--subprogram`,
`--config corpus_setups/NAME.yaml`: a machine file beside this module, e.g. with the macro
variables or the M codes of the program's machine, ...) with `setup: "..."`, why the program
needs them (the machine it was written for, the variables a setter presets): a judgement,
kept by the regeneration like an invalid reason.

A problem is a file that passed and now fails (a regression), a file marked fail, invalid or
refused-by-controller that now passes (the baseline must be updated: the report prints the
exact edit), a refused-by-controller file whose first error no longer names its alarm (the
record would rot), and a file present on one side only. A fail file whose first error changed is reported, not a
problem: other work moves first errors all the time.

    python -m tests.cnc.corpus_report            # table + `N passed, M failed`; exit 1 on a problem
    python -m tests.cnc.corpus_report --write    # regenerate the baseline from today's results
                                                 # (invalid entries and their reasons are kept)
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import yaml

from tests.reference import GCODE_CORPUS, MISSING

BASELINE = Path(__file__).with_name("corpus_expected.yaml")
SETUPS = "corpus_setups/"  # an `args` path starting so names a machine file beside this module
REFUSED = "refused-by-controller"
EXPECTS = ("pass", "fail", "invalid", REFUSED)
# A warning line as the checker prints it: `FILE:LINE:COL: warning: ...` (or bare `warning: ...`).
_WARNING = re.compile(r"(^|:\s)warning\b", re.IGNORECASE)


@dataclass(frozen=True)
class Expected:
    expect: str  # pass | fail | invalid | refused-by-controller
    note: str = ""  # the first error (fail), why it is another controller's language (invalid),
    # or why the real control refuses it too, with the evidence (refused-by-controller)
    args: tuple[str, ...] = ()  # extra `nc check` options for this file
    setup: str = ""  # why it needs them
    alarm: str = ""  # refused-by-controller: the alarm the first error must name (PS0041, 3001)


@dataclass(frozen=True)
class Result:
    file: str
    kind: str
    passed: bool
    first_error: str  # "LINE:COL: message" without the path, "" when passed
    errors: int
    warnings: int
    seconds: float


@dataclass(frozen=True)
class Finding:
    file: str
    problem: bool  # True: the test fails
    text: str


def sources_rows(sources_md: Path) -> list[dict[str, str]]:
    """The rows of the SOURCES.md table (`| file | repo | ... | kind | origin | ...`), by column."""
    rows: list[dict[str, str]] = []
    header: list[str] | None = None
    for line in sources_md.read_text(encoding="utf-8").splitlines():
        if not line.startswith("|"):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if header is None:
            header = cells
            continue
        if set(cells[0]) <= {"-", ":", " "}:
            continue
        rows.append(dict(zip(header, cells, strict=False)))
    return rows


def corpus_kinds(sources_md: Path) -> dict[str, str]:
    """file -> kind ('mill' | 'lathe') from the SOURCES.md table."""
    kinds = {row["file"]: row["kind"] for row in sources_rows(sources_md)}
    if not kinds:
        raise ValueError(f"{sources_md}: no table with a file and a kind column")
    return kinds


def check_argv(
    path: Path, kind: str, args: Iterable[str] = (), library: Path | None = None
) -> list[str]:
    """The `nc check` arguments a user gives: `--kind lathe`, the file's setup `args`, and
    `--library FOLDER` for a program that calls programs of other files."""
    lathe = ["--kind", "lathe"] if kind == "lathe" else []
    shop = ["--library", str(library)] if library is not None else []
    here = Path(__file__).parent
    args = [str(here / a) if a.startswith(SETUPS) else a for a in args]
    return ["check", *lathe, *args, *shop, str(path)]


def calls_other_files(path: Path) -> bool:
    """Whether the program calls (M98 P / G65 P / G66 P) a program not in its own file."""
    from cnc.gcode.calls import program_calls

    with open(path, encoding="latin-1") as fh:
        return bool(program_calls(fh).calls)


def shop_folders(corpus: Path, into: Path) -> dict[str, Path]:
    """file -> the folder of its shop's programs: the corpus files from the same repository
    (SOURCES.md `repository`), linked into one folder each under `into`. A shop's subprograms
    are found among its own programs; O numbers repeat across shops (O1002, O9001)."""
    folders: dict[str, Path] = {}
    for row in sources_rows(corpus / "SOURCES.md"):
        name, repo = row.get("file", ""), row.get("repository", "")
        if not (corpus / name).is_file():
            continue
        folder = into / re.sub(r"[^A-Za-z0-9_.-]+", "_", repo or "unknown")
        folder.mkdir(exist_ok=True)
        (folder / name).symlink_to((corpus / name).resolve())
        folders[name] = folder
    return folders


def split_output(text: str) -> tuple[list[str], list[str]]:
    """The checker's output lines as (errors, warnings); a warning says `warning` after its
    location (`FILE:LINE:COL: warning: ...`) or at the start of the line."""
    lines = [ln for ln in text.splitlines() if ln.strip()]
    warnings = [ln for ln in lines if _WARNING.search(ln)]
    return [ln for ln in lines if not _WARNING.search(ln)], warnings


def check_file(
    path: Path, kind: str, args: Iterable[str] = (), library: Path | None = None
) -> Result:
    from typer.testing import CliRunner

    from cnc.cli import nc_app

    start = time.perf_counter()
    out = CliRunner().invoke(nc_app, check_argv(path, kind, args, library))
    seconds = time.perf_counter() - start
    if out.exception is not None and not isinstance(out.exception, SystemExit):
        # A crash of the checker is a failure with its own first error, never a pass.
        exc = out.exception
        return Result(path.name, kind, False, f"0:0: crash: {type(exc).__name__}: {exc}", 1, 0,
                      seconds)  # fmt: skip
    errors, warnings = split_output(out.stdout + out.stderr)
    first = errors[0] if errors else ""
    prefix = f"{path}:"
    if first.startswith(prefix):
        first = first[len(prefix) :]
    elif library is not None and first.startswith(f"{library}/"):
        first = first[len(f"{library}/") :]  # in a called program: `FILE:LINE:COL: ...`
    passed = out.exit_code == 0
    if not passed and not first:
        first = f"0:0: exit code {out.exit_code} without a message"
    return Result(path.name, kind, passed, first if not passed else "", len(errors), len(warnings),
                  seconds)  # fmt: skip


def run_corpus(
    corpus: Path = GCODE_CORPUS, baseline: Mapping[str, Expected] | None = None
) -> list[Result]:
    """Check every corpus file, with the setup `args` its baseline entry gives."""
    kinds = corpus_kinds(corpus / "SOURCES.md")
    files = sorted(p for p in corpus.iterdir() if p.is_file() and p.name != "SOURCES.md")
    unknown = [p.name for p in files if p.name not in kinds]
    if unknown:
        raise ValueError(f"{corpus}/SOURCES.md: no row (kind) for {', '.join(unknown)}")
    setups = baseline or {}
    with tempfile.TemporaryDirectory(prefix="fmscell-corpus-") as tmp:
        shops = shop_folders(corpus, Path(tmp))
        return [
            check_file(
                p,
                kinds[p.name],
                setups.get(p.name, Expected("pass")).args,
                shops[p.name] if calls_other_files(p) else None,
            )
            for p in files
        ]


def load_baseline(path: Path = BASELINE) -> dict[str, Expected]:
    doc = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    files = doc.get("files")
    if not isinstance(files, dict):
        raise ValueError(f"{path}: /files must be a mapping of file name -> expectation")
    out: dict[str, Expected] = {}
    for name, entry in files.items():
        where = f"{path}: /files/{name}"
        if not isinstance(entry, dict) or entry.get("expect") not in EXPECTS:
            raise ValueError(f"{where}/expect must be one of {', '.join(EXPECTS)}")
        expect = entry["expect"]
        key = _NOTE_KEY.get(expect)
        note = entry.get(key) if key else ""
        if key and not (isinstance(note, str) and note):
            raise ValueError(f"{where}/{key} is required for expect: {expect}")
        alarm = entry.get("alarm", "")
        if expect == REFUSED and not (isinstance(alarm, str) and _ALARM.fullmatch(alarm)):
            raise ValueError(f"{where}/alarm is required for expect: {REFUSED}: the alarm number "
                             "the control gives (PS0041, 3001), which the first error must name")  # fmt: skip
        args, setup = entry.get("args", []), entry.get("setup", "")
        if not (isinstance(args, list) and all(isinstance(a, str) and a for a in args)):
            raise ValueError(f"{where}/args must be a list of `nc check` options")
        if args and not (isinstance(setup, str) and setup):
            raise ValueError(f"{where}/setup is required with args (why the file needs them)")
        for a in args:
            if a.startswith(SETUPS) and not (Path(__file__).parent / a).is_file():
                raise ValueError(f"{where}/args: no machine file {a} beside {Path(__file__).name}")
        out[str(name)] = Expected(expect, note or "", tuple(args), setup if args else "",
                                  alarm if expect == REFUSED else "")  # fmt: skip
    return out


# The note each expectation carries, by its key in the YAML.
_NOTE_KEY = {"fail": "error", "invalid": "reason", REFUSED: "reason"}
# An alarm number as the first error names it: PS0041, 3001 (a #3000 macro alarm), ...
_ALARM = re.compile(r"[A-Z]{0,3}\d{1,5}")


def names_alarm(first_error: str, alarm: str) -> bool:
    """Whether the first error names the alarm as a word (`PS0041`, not `PS00410`)."""
    return re.search(rf"(?<![A-Za-z0-9]){re.escape(alarm)}(?![A-Za-z0-9])", first_error) is not None


def _entry(name: str, expected: Expected) -> str:
    fields = [f"expect: {expected.expect}"]
    if expected.expect == REFUSED:
        fields.append(f"alarm: {_quote(expected.alarm)}")
    key = _NOTE_KEY.get(expected.expect)
    if key:
        fields.append(f"{key}: {_quote(expected.note)}")
    if expected.args:
        fields.append(f"args: [{', '.join(_quote(a) for a in expected.args)}]")
        fields.append(f"setup: {_quote(expected.setup)}")
    return f"  {name}: {{{', '.join(fields)}}}"


def _quote(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def compare(results: Iterable[Result], baseline: Mapping[str, Expected]) -> list[Finding]:
    findings: list[Finding] = []
    seen: set[str] = set()
    for r in results:
        seen.add(r.file)
        exp = baseline.get(r.file)
        got = Expected("pass") if r.passed else Expected("fail", r.first_error)
        if exp is not None:
            got = Expected(got.expect, got.note, exp.args, exp.setup)
        now = _entry(r.file, got)
        if exp is None:
            findings.append(Finding(r.file, True, f"not in the baseline: add `{now.strip()}`"))
        elif exp.expect == "pass" and not r.passed:
            findings.append(
                Finding(r.file, True, f"REGRESSION: passed, now fails: {r.first_error}")
            )
        elif exp.expect != "pass" and r.passed:
            what = {"fail": "marked fail", "invalid": f"marked invalid ({exp.note})",
                    REFUSED: f"marked {REFUSED} ({exp.alarm})"}[exp.expect]  # fmt: skip
            findings.append(Finding(r.file, True, f"{what}, now passes: update the baseline to "
                                                  f"`{now.strip()}`"))  # fmt: skip
        elif exp.expect == REFUSED and not names_alarm(r.first_error, exp.alarm):
            findings.append(Finding(r.file, True, f"marked {REFUSED} with alarm {exp.alarm}, but "
                                                  f"the first error is now {r.first_error!r}: "
                                                  "check the record"))  # fmt: skip
        elif exp.expect == "fail" and r.first_error != exp.note:
            findings.append(Finding(r.file, False, f"first error changed: was {exp.note!r}, "
                                                   f"now {r.first_error!r}"))  # fmt: skip
    for name in sorted(set(baseline) - seen):
        findings.append(Finding(name, True, "in the baseline but not in the corpus: remove it"))
    return findings


def summary(results: Iterable[Result], baseline: Mapping[str, Expected]) -> str:
    results = list(results)
    aside = {r.file: baseline[r.file].expect for r in results
             if r.file in baseline and baseline[r.file].expect in ("invalid", REFUSED)}  # fmt: skip
    counted = [r for r in results if r.file not in aside]
    passed = sum(r.passed for r in counted)
    invalid = sum(1 for e in aside.values() if e == "invalid")
    refused = sum(1 for e in aside.values() if e == REFUSED)
    warnings = sum(r.warnings for r in results)
    return (f"{passed} passed, {len(counted) - passed} failed "
            f"({invalid} expected-invalid, {refused} {REFUSED} excluded; "
            f"{warnings} warnings)")  # fmt: skip


def table(results: Iterable[Result], baseline: Mapping[str, Expected]) -> str:
    rows = []
    for r in results:
        exp = baseline.get(r.file)
        got = "pass" if r.passed else "fail"
        detail = r.first_error if not r.passed else ""
        if exp is not None and exp.expect == "invalid":
            got, detail = f"invalid/{got}", exp.note
        elif exp is not None and exp.expect == REFUSED:
            got, detail = f"refused/{got}", f"{exp.alarm}: {r.first_error}"
        rows.append(f"{r.file:34} {r.kind:5} {got:12} {r.errors:5} {r.warnings:4} "
                    f"{r.seconds:6.2f}s  {detail[:110]}")  # fmt: skip
    head = f"{'file':34} {'kind':5} {'result':12} {'errs':>5} {'warn':>4} {'time':>7}  first error / reason"
    return "\n".join([head, *rows])


def write_baseline(results: Iterable[Result], old: Mapping[str, Expected], path: Path) -> None:
    """Regenerate from today's results; invalid and refused-by-controller entries (a
    judgement, not a result) are kept."""
    lines = [
        "# Expected result of `fmscell nc check [--kind lathe] [args] FILE` on every corpus file",
        "# (../shared/reference/corpus/gcode). Checked by tests/cnc/test_corpus.py and",
        "# `make corpus`; regenerate with `make corpus-baseline` after a change that moves",
        "# results. pass | fail (error: today's first error) | invalid (reason: another",
        "# controller's language; kept by the regeneration, edit by hand) |",
        "# refused-by-controller (alarm: the alarm the real control gives too, which the first",
        "# error must name; reason: the defect and the evidence; kept, edit by hand). args:",
        "# extra `nc check` options with setup: why the file needs them (kept, edit by hand).",
        "files:",
    ]
    for r in results:
        exp = old.get(r.file)
        if exp is not None and exp.expect in ("invalid", REFUSED):
            lines.append(_entry(r.file, exp))
        else:
            now = Expected("pass") if r.passed else Expected("fail", r.first_error)
            if exp is not None:
                now = Expected(now.expect, now.note, exp.args, exp.setup)
            lines.append(_entry(r.file, now))
    tmp = path.with_suffix(".tmp")
    tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    tmp.replace(path)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.cnc.corpus_report", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    ap.add_argument("--write", action="store_true", help="regenerate the baseline file")
    ap.add_argument("--baseline", type=Path, default=BASELINE)
    ap.add_argument("--corpus", type=Path, default=GCODE_CORPUS)
    args = ap.parse_args(argv)
    if not (args.corpus / "SOURCES.md").is_file():
        print(MISSING, file=sys.stderr)
        return 2
    old = load_baseline(args.baseline) if args.baseline.is_file() else {}
    results = run_corpus(args.corpus, old)
    if args.write:
        write_baseline(results, old, args.baseline)
        old = load_baseline(args.baseline)
        print(f"wrote {args.baseline}")
    print(table(results, old))
    findings = compare(results, old)
    for f in findings:
        print(f"{'PROBLEM' if f.problem else 'note'}: {f.file}: {f.text}")
    print(summary(results, old))
    return 1 if any(f.problem for f in findings) else 0


if __name__ == "__main__":
    raise SystemExit(main())

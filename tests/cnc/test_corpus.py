"""The corpus of real part programs against its baseline (tests/cnc/corpus_expected.yaml).

The whole-corpus test fails when a file that passed regresses, when a file marked fail or
invalid now passes (the message gives the baseline edit; `make corpus-baseline` regenerates
it), and when the corpus and the baseline disagree on the files. The comparison itself is
tested on a table of made-up results, so it is known to fail when it should.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cnc import corpus_report as cr
from tests.reference import GCODE_CORPUS, MISSING


def _r(name: str, passed: bool, first: str = "") -> cr.Result:
    return cr.Result(name, "mill", passed, "" if passed else first, 0 if passed else 1, 0, 0.0)


E = cr.Expected
# A file the real control refuses too: it must keep failing with its alarm.
R = E(cr.REFUSED, "a groove narrower than the nose", alarm="PS0041")


@pytest.mark.parametrize(
    ("expected", "result", "problem", "says"),
    [
        (E("pass"), _r("a.nc", True), None, ""),
        (E("pass"), _r("a.nc", False, "3:1: boom"), True, "REGRESSION"),
        (E("fail", "3:1: boom"), _r("a.nc", False, "3:1: boom"), None, ""),
        (E("fail", "3:1: boom"), _r("a.nc", False, "4:1: other"), False, "first error changed"),
        (E("fail", "3:1: boom"), _r("a.nc", True), True, "`a.nc: {expect: pass}`"),
        (E("invalid", "Okuma"), _r("a.nc", False, "1:1: $"), None, ""),
        (E("invalid", "Okuma"), _r("a.nc", True), True, "marked invalid (Okuma), now passes"),
        (None, _r("a.nc", False, "1:1: x"), True, 'add `a.nc: {expect: fail, error: "1:1: x"}`'),
        (R, _r("a.nc", False, "27:1: gouge (Fanuc PS0041 interference in CRC)"), None, ""),
        (R, _r("a.nc", False, "30:1: gouge, elsewhere (PS0041)"), None, ""),  # moved: same alarm
        (R, _r("a.nc", True), True, "marked refused-by-controller (PS0041), now passes"),
        (R, _r("a.nc", False, "3:1: PS00410 boom"), True, "check the record"),
        (R, _r("a.nc", False, "3:1: M20 is not an M code"), True, "alarm PS0041, but the first"),
    ],
)
def test_compare_table(expected, result, problem, says):
    baseline = {} if expected is None else {"a.nc": expected}
    findings = cr.compare([result], baseline)
    if problem is None:
        assert findings == []
    else:
        (f,) = findings
        assert f.problem is problem and says in f.text, f


def test_output_splits_into_errors_and_warnings():
    text = (
        "p.nc:1:1: warning: no G20/G21: inch assumed (power-on unit)\n"
        "p.nc:9:4: axis X move to 12.0000 mm is beyond the soft limit\n"
        "\n"
        "Warning: 2 tools unused\n"
        "p.nc: warning: no G20/G21 in the program: read in mm, the power-on unit\n"
        "p.nc:10:1: feed move without F (warning words inside a message do not count)\n"
    )
    errors, warnings = cr.split_output(text)
    assert [e.split(":")[1] for e in errors] == ["9", "10"]
    assert len(warnings) == 3


def test_compare_reports_a_baseline_file_missing_from_the_corpus():
    (f,) = cr.compare([], {"gone.nc": E("pass")})
    assert f.problem and "not in the corpus" in f.text


def test_baseline_round_trips_through_write(tmp_path: Path):
    old = {"b.nc": E("invalid", 'Siemens "840D" native')}
    results = [_r("a.nc", False, '7:3: unsupported: "x"'), _r("b.nc", False, "1:1: %"),
               _r("c.nc", True)]  # fmt: skip
    path = tmp_path / "expected.yaml"
    cr.write_baseline(results, old, path)
    assert cr.load_baseline(path) == {"a.nc": E("fail", '7:3: unsupported: "x"'), "b.nc": old["b.nc"],
                                      "c.nc": E("pass")}  # fmt: skip
    assert cr.compare(results, cr.load_baseline(path)) == []


def test_a_setup_is_kept_by_the_regeneration_and_reaches_the_command_line(tmp_path: Path):
    old = {"a.nc": E("fail", "1:1: x", ("--no-soft-limits",), "a 2 m gantry"),
           "b.nc": E("invalid", "Okuma", ("--units", "inch"), "inch")}  # fmt: skip
    path = tmp_path / "expected.yaml"
    cr.write_baseline([_r("a.nc", True), _r("b.nc", False, "1:1: $")], old, path)
    assert cr.load_baseline(path) == {"a.nc": E("pass", "", ("--no-soft-limits",), "a 2 m gantry"),
                                      "b.nc": old["b.nc"]}  # fmt: skip
    argv = cr.check_argv(Path("l.nc"), "lathe", ("--gcode-system", "B"))
    assert argv == ["check", "--kind", "lathe", "--gcode-system", "B", "l.nc"]
    path.write_text('files:\n  a.nc: {expect: pass, args: ["--units", "inch"]}\n', encoding="utf-8")
    with pytest.raises(ValueError, match=r"/files/a.nc/setup is required with args"):
        cr.load_baseline(path)
    path.write_text("files:\n  a.nc: {expect: pass, args: --units}\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"/files/a.nc/args must be a list"):
        cr.load_baseline(path)


@pytest.mark.parametrize(
    ("entry", "says"),
    [
        ("{expect: fail}", r"/files/a.nc/error is required"),
        ("{expect: refused-by-controller, alarm: PS0041}", r"/files/a.nc/reason is required"),
        ('{expect: refused-by-controller, reason: "x"}', r"/files/a.nc/alarm is required"),
        ('{expect: refused-by-controller, reason: "x", alarm: "an alarm"}', r"/alarm is required"),
        ("{expect: refused}", r"/files/a.nc/expect must be one of"),
        (
            '{expect: pass, args: [--config, corpus_setups/none.yaml], setup: "x"}',
            r"/files/a.nc/args: no machine file corpus_setups/none.yaml",
        ),
    ],
)
def test_bad_baseline_entry_is_refused_with_its_pointer(tmp_path: Path, entry, says):
    path = tmp_path / "expected.yaml"
    path.write_text(f"files:\n  a.nc: {entry}\n", encoding="utf-8")
    with pytest.raises(ValueError, match=says):
        cr.load_baseline(path)


def test_the_corpus_setups_are_machine_files_that_load():
    from cnc.config import load_machine_config

    setups = sorted((Path(cr.__file__).parent / "corpus_setups").glob("*.yaml"))
    assert setups
    for path in setups:
        load_machine_config(path)  # raises ConfigError with the line of a bad key
    argv = cr.check_argv(Path("a.nc"), "mill", ("--config", "corpus_setups/x.yaml"))
    assert argv[2] == str(Path(cr.__file__).parent / "corpus_setups" / "x.yaml")


def test_a_refused_by_controller_entry_round_trips_and_is_counted_apart(tmp_path: Path):
    old = {"a.nc": R, "b.nc": E("fail", "1:1: x")}
    results = [_r("a.nc", False, "27:1: PS0041 gouge"), _r("b.nc", False, "1:1: x"),
               _r("c.nc", True)]  # fmt: skip
    path = tmp_path / "expected.yaml"
    cr.write_baseline(results, old, path)
    assert cr.load_baseline(path) == {**old, "c.nc": E("pass")}  # the judgement is kept
    assert cr.summary(results, old).startswith(
        "1 passed, 1 failed (0 expected-invalid, 1 refused-by-controller excluded;"
    )


def test_sources_md_gives_every_corpus_file_a_kind():
    if not (GCODE_CORPUS / "SOURCES.md").is_file():
        pytest.skip(MISSING)
    kinds = cr.corpus_kinds(GCODE_CORPUS / "SOURCES.md")
    assert kinds["gcw-fanuc0t.nc"] == "lathe" and kinds["cline-rebels5.nc"] == "mill"
    assert set(kinds.values()) == {"mill", "lathe"}


def test_corpus_against_baseline(capsys):
    if not (GCODE_CORPUS / "SOURCES.md").is_file():
        pytest.skip(MISSING)
    baseline = cr.load_baseline()
    results = cr.run_corpus(GCODE_CORPUS, baseline)
    findings = cr.compare(results, baseline)
    line = cr.summary(results, baseline)
    with capsys.disabled():
        print(f"\ncorpus: {line}")
    problems = [f"{f.file}: {f.text}" for f in findings if f.problem]
    notes = [f"{f.file}: {f.text}" for f in findings if not f.problem]
    assert not problems, (
        f"corpus: {line}\n" + "\n".join(problems)
        + ("\n(notes: " + "; ".join(notes) + ")" if notes else "")
        + "\nregenerate with `make corpus-baseline` when the change is intended"
    )  # fmt: skip


def test_a_calling_program_is_checked_with_its_shops_folder_as_library(tmp_path):
    """O numbers repeat across shops (O1002 is a Haas lathe program of one and a subprogram
    of another): a program's calls are looked up among its own repository's files."""
    corpus = tmp_path / "corpus"
    corpus.mkdir()
    (corpus / "SOURCES.md").write_text(
        "| file | repository | kind |\n|---|---|---|\n"
        "| a-main.nc | shop/a | mill |\n| a-sub.nc | shop/a | mill |\n"
        "| b-other.nc | shop/b | mill |\n",
        encoding="utf-8",
    )
    (corpus / "a-main.nc").write_text("%\nO1\nG21 G90 G1 X-1 F100\nM98 P1002\nM30\n%\n")
    (corpus / "a-sub.nc").write_text("%\nO1002\nG91 G1 X-1\nG90\nM99\n%\n")
    (corpus / "b-other.nc").write_text("%\nO1002\nG0 X-1\nG2 X1\nM30\n%\n")
    assert cr.calls_other_files(corpus / "a-main.nc")
    assert not cr.calls_other_files(corpus / "a-sub.nc")
    shops = cr.shop_folders(corpus, tmp_path)
    assert shops["a-main.nc"] == shops["a-sub.nc"] != shops["b-other.nc"]
    assert sorted(p.name for p in shops["a-main.nc"].iterdir()) == ["a-main.nc", "a-sub.nc"]
    assert cr.check_argv(corpus / "a-main.nc", "mill", library=shops["a-main.nc"])[1:3] == [
        "--library",
        str(shops["a-main.nc"]),
    ]
    results = {r.file: r for r in cr.run_corpus(corpus)}
    assert results["a-main.nc"].passed and results["a-sub.nc"].passed  # the sub: M99 ends it
    assert not results["b-other.nc"].passed


def test_the_rotary_corpus_files_run_on_mill4():
    if not (GCODE_CORPUS / "SOURCES.md").is_file():
        pytest.skip(MISSING)
    rotary = ["kiely-mill-engrave.nc", "norn93-demo.nc", "norn93-peck-pockets.nc",
              "z64-stdbc-o0010.nc"]  # fmt: skip
    baseline = cr.load_baseline()
    assert {baseline[f].args for f in rotary} == {("--config", "mill4")}
    for f in rotary:
        # on mill3 each stops at its first A word; on mill4 none does
        on_mill3 = cr.check_file(GCODE_CORPUS / f, "mill")
        assert "axis A is not configured" in on_mill3.first_error
        on_mill4 = cr.check_file(GCODE_CORPUS / f, "mill", ("--config", "mill4"))
        assert "axis A" not in on_mill4.first_error and "rotary" not in on_mill4.first_error

"""Program library: programs, revisions, release workflow, search, import, audit, outbox."""

from __future__ import annotations

import re

import pytest
from sqlalchemy import func, select, text

from dnc import models as m
from dnc.cursor import encode_cursor
from dnc.errors import Conflict, InvalidCursor, InvalidUpload, NotFound, WorkflowError
from dnc.tape import sha256_of

PROG = "%\nO1000 (BRACKET)\nN10 G0 X0 Y0\nN20 G1 X10 F100\nN30 M30\n%\n"


def test_create_program_stores_first_revision_as_draft(library):
    prog, rev = library.create_program(number=1000, name="Bracket", text=PROG, tags=["alu", "op1"])
    assert (prog.number, prog.name, prog.tags) == (1000, "Bracket", ("alu", "op1"))
    assert (rev.seq, rev.status, rev.check_ok, rev.lines) == (1, "draft", True, 6)
    assert rev.sha256 == sha256_of(PROG) and rev.size == len(PROG)
    assert library.revision_text(rev.id) == PROG
    assert library.get_program(prog.id).latest_revision_id == rev.id


def test_same_number_same_kind_is_a_conflict_other_kind_is_not(library):
    library.create_program(number=1000, name="A", text=PROG)
    with pytest.raises(Conflict, match="O1000 already exists for mill"):
        library.create_program(number=1000, name="B", text=PROG)
    prog, _ = library.create_program(number=1000, name="B", text=PROG, machine_kind="lathe")
    assert prog.machine_kind == "lathe"


def test_identical_content_is_stored_once(library, sessions):
    prog, _ = library.create_program(number=1, name="A", text=PROG)
    library.add_revision(prog.id, PROG.replace("\n", "\r\n").encode())  # CR LF from a tape
    library.create_program(number=2, name="B", text=PROG)
    with sessions() as s:
        assert s.scalar(select(func.count()).select_from(m.Content)) == 1
        assert s.scalar(select(func.count()).select_from(m.Revision)) == 3


def test_release_needs_comment_and_passing_check(library):
    prog, rev = library.create_program(number=1, name="A", text=PROG)
    with pytest.raises(WorkflowError, match="approval comment"):
        library.release(rev.id, approver="ann", comment="  ")
    bad = library.add_revision(prog.id, PROG.replace("G1", "BAD G1"))
    assert not bad.check_ok and bad.check_errors[0]["line"] == 4
    with pytest.raises(WorkflowError, match="failed the NC check .* line 4: bad word"):
        library.release(bad.id, approver="ann", comment="ok")
    released = library.release(rev.id, approver="ann", comment="proved on machine 2")
    assert (released.status, released.approved_by) == ("released", "ann")


def test_releasing_a_new_revision_obsoletes_the_old_one(library):
    prog, r1 = library.create_program(number=1, name="A", text=PROG)
    library.release(r1.id, approver="ann", comment="first")
    r2 = library.add_revision(prog.id, PROG.replace("X10", "X12"), comment="longer")
    library.release(r2.id, approver="bob", comment="second")
    old = library.get_revision(r1.id)
    assert old.status == "obsolete" and old.approval_comment == "superseded by rev 2"
    assert library.get_program(prog.id).released_revision_id == r2.id
    assert library.released_revision(1, "mill").id == r2.id
    with pytest.raises(WorkflowError, match="only a draft can be released"):
        library.release(r1.id, approver="ann", comment="again")


def test_obsolete_is_final(library):
    _, rev = library.create_program(number=1, name="A", text=PROG)
    library.obsolete(rev.id, approver="ann", comment="withdrawn")
    with pytest.raises(WorkflowError, match="already obsolete"):
        library.obsolete(rev.id, approver="ann", comment="again")
    with pytest.raises(NotFound, match="no released revision of O0001"):
        library.released_revision(1, "mill")


@pytest.mark.parametrize(
    "payload, message",
    [
        (b"", "empty"),
        (b"%\n\n%\n", "empty"),
        (b"O1\nG0 X1\x00\x01", "binary data .*0x00.* offset 8"),
        (b"O1\nG0 X\xff1\n", "invalid UTF-8 at byte offset 7"),
        (b"O1\n" + b"G0 X1\n" * 20000, "exceeds the upload limit of 65536 bytes"),
    ],
)
def test_bad_uploads_are_refused_and_nothing_is_stored(library, sessions, payload, message):
    with pytest.raises(InvalidUpload, match=message):
        library.create_program(number=5, name="X", text=payload)
    with sessions() as s:
        assert s.scalar(select(func.count()).select_from(m.Program)) == 0
        assert s.scalar(select(func.count()).select_from(m.OutboxEvent)) == 0


def test_xon_xoff_characters_from_a_tape_are_stripped(library):
    _, rev = library.create_program(number=1, name="A", text=b"\x11%\nO1\nG0 X1\n%\n\x13")
    assert library.revision_text(rev.id) == "%\nO1\nG0 X1\n%\n"


def test_diff_between_revisions_with_normalisations(library):
    prog, r1 = library.create_program(number=1, name="A", text=PROG)
    renumbered = PROG.replace("N10", "N100").replace("N20", "N200").replace("(BRACKET)", "")
    r2 = library.add_revision(prog.id, renumbered)
    plain = library.diff(r1.id, r2.id)
    assert "-N10 G0 X0 Y0" in plain and "+N100 G0 X0 Y0" in plain
    assert library.diff(r1.id, r2.id, ignore_numbers=True, ignore_comments=True) == ""


def test_search_by_name_number_tag_and_text_with_cursor(library):
    for n in range(1, 8):
        body = PROG.replace("O1000", f"O{n}") + ("(DRILL)\n" if n % 2 else "")
        library.create_program(number=n, name=f"part {n}", text=body, tags=["odd"] if n % 2 else [])
    assert [p.number for p in library.search(query="part 3").items] == [3]
    assert [p.number for p in library.search(query="O5").items] == [5]
    assert [p.number for p in library.search(tag="odd").items] == [1, 3, 5, 7]
    assert [p.number for p in library.search(text="(DRILL)").items] == [1, 3, 5, 7]
    first = library.search(limit=3)
    second = library.search(limit=3, cursor=first.next_cursor)
    third = library.search(limit=3, cursor=second.next_cursor)
    assert [p.number for p in first.items + second.items + third.items] == list(range(1, 8))
    assert third.next_cursor is None
    with pytest.raises(InvalidCursor, match="is not a cursor this list gave out"):
        library.search(cursor="!!")
    with pytest.raises(InvalidCursor):  # a cursor of another list (jobs)
        library.search(cursor=encode_cursor("j", first.items[-1].id))


def test_search_treats_like_wildcards_literally(library):
    library.create_program(number=1, name="100% part", text=PROG)
    library.create_program(number=2, name="other", text=PROG.replace("O1000", "O2"))
    assert [p.number for p in library.search(query="100%").items] == [1]
    assert [p.number for p in library.search(query="_").items] == []


def test_import_directory_files_new_programs_and_revisions(library, tmp_path):
    (tmp_path / "a.nc").write_text("%\nO2001 (FLANGE)\nG0 X0\nM30\n%\n")
    (tmp_path / "b.ngc").write_text("%\nO2002\nG0 X0\nM30\n%\n")
    (tmp_path / "c.tap").write_bytes(b"%\nO2001 (FLANGE)\nG0 X5\nM30\n%\n")
    (tmp_path / "no_number.txt").write_text("G0 X0\nM30\n")
    (tmp_path / "picture.png").write_bytes(b"\x89PNG")
    results = {p.name: r for p, r in library.import_path(tmp_path)}
    assert set(results) == {"a.nc", "b.ngc", "c.tap", "no_number.txt"}
    assert results["a.nc"].seq == 1 and results["c.tap"].seq == 2
    assert results["a.nc"].program_id == results["c.tap"].program_id
    assert library.get_program(results["a.nc"].program_id).name == "FLANGE"
    assert isinstance(results["no_number.txt"], InvalidUpload)


def test_program_from_machine_is_a_candidate_and_never_overwrites(library):
    library.register_machine("mill1", "mill", dnc_address="127.0.0.1:7001", memory_bytes=65536)
    prog, r1 = library.create_program(number=1000, name="Bracket", text=PROG)
    library.release(r1.id, approver="ann", comment="ok")
    edited = PROG.replace("X10", "X11")
    cand = library.receive_from_machine("mill1", edited.encode())
    assert (cand.program_id, cand.seq, cand.status, cand.source) == (
        prog.id,
        2,
        "draft",
        "machine:mill1",
    )
    assert library.get_revision(r1.id).status == "released"
    assert library.revision_text(r1.id) == PROG
    new = library.receive_from_machine("mill1", b"%\nO4321 (FIXTURE)\nG0 X0\nM30\n%\n")
    assert library.get_program(new.program_id).name == "FIXTURE"
    with pytest.raises(NotFound, match="unknown machine 'mill9'"):
        library.receive_from_machine("mill9", PROG)
    same = library.receive_from_machine("mill1", edited.encode())  # unchanged since
    assert same.id == cand.id and len(library.revisions(prog.id)) == 2


def test_machine_registry_is_idempotent_by_name(library):
    library.register_machine("lathe1", "lathe", memory_bytes=1000)
    assert library.machine("lathe1")["axes"] is None  # not known: judged by its kind alone
    library.register_machine(
        "lathe1", "lathe", memory_bytes=2000, dnc_profile={"parity": True}, axes=("X", "Z")
    )
    assert library.machines() == [
        dict(
            name="lathe1",
            kind="lathe",
            dnc_address="",
            modbus_address="",
            status_address="",
            memory_bytes=2000,
            dnc_profile={"parity": True},
            axes=["X", "Z"],
        )
    ]
    with pytest.raises(NotFound):
        library.machine("nope")


def test_tools_fixtures_and_material_link_to_programs(library):
    prog, _ = library.create_program(number=1, name="A", text=PROG)
    t1 = library.add_resource("tool", "T1", description="D10 end mill", data={"radius": 5.0})
    fx = library.add_resource("fixture", "VISE-125")
    library.link_resource(prog.id, t1)
    library.link_resource(prog.id, fx)
    library.link_resource(prog.id, t1)  # idempotent
    assert [(r["kind"], r["code"]) for r in library.resources(prog.id)] == [
        ("fixture", "VISE-125"),
        ("tool", "T1"),
    ]
    with pytest.raises(InvalidUpload, match="tool, fixture or material"):
        library.add_resource("robot", "R1")


def test_every_change_is_audited_and_the_audit_log_is_append_only(library, engine):
    prog, rev = library.create_program(number=1, name="A", text=PROG, author="ann")
    library.release(rev.id, approver="bob", comment="ok")
    actions = [a["action"] for a in library.audit()]
    assert actions == ["revision.create", "program.create", "revision.release"]
    with pytest.raises(Exception, match="append-only"), engine.begin() as conn:
        conn.execute(text("UPDATE audit_log SET actor = 'mallory'"))
    with pytest.raises(Exception, match="append-only"), engine.begin() as conn:
        conn.execute(text("DELETE FROM audit_log"))
    assert [a["actor"] for a in library.audit()] == ["ann", "ann", "bob"]


def test_outbox_event_per_change_in_the_same_transaction(library, sessions):
    library.create_program(number=1, name="A", text=PROG)
    with pytest.raises(Conflict):
        library.create_program(number=1, name="dup", text=PROG)
    with sessions() as s:
        topics = s.scalars(select(m.OutboxEvent.topic).order_by(m.OutboxEvent.id)).all()
    assert topics == ["fmscell/revision/create", "fmscell/program/create"]


def test_not_found_errors_name_the_id(library):
    with pytest.raises(NotFound, match="no program with id 42"):
        library.get_program(42)
    with pytest.raises(NotFound, match="no revision with id 7"):
        library.revision_text(7)


def test_program_number_and_name_are_validated(library):
    with pytest.raises(InvalidUpload, match=r"1\.\.99999999 \(O number\), got 0"):
        library.create_program(number=0, name="A", text=PROG)
    with pytest.raises(InvalidUpload, match=r"1\.\.99999999 \(O number\), got 100000000"):
        library.create_program(number=100_000_000, name="A", text=PROG)
    assert library.create_program(number=80000001, name="A", text=PROG)[0].number == 80000001
    with pytest.raises(InvalidUpload, match="name must not be empty"):
        library.create_program(number=1, name=" ", text=PROG)


def test_parity_tape_upload_gets_a_hint():
    from dnc.tape import decode_program

    def with_parity(ch: int) -> int:
        return ch | 0x80 if bin(ch).count("1") % 2 else ch

    tape = bytes(with_parity(c) for c in b"%\nO1\nG0 X1\n%\n")
    with pytest.raises(InvalidUpload, match="parity bit set"):
        decode_program(tape, limit=1000)


@pytest.mark.parametrize(
    "needle, found", [("X1", [1]), ("G1 X10", [1]), ("100%", [2]), ("_", []), ("Z", [])]
)
def test_text_search_finds_substrings_of_any_length(library, needle, found):
    library.create_program(number=1, name="a", text=PROG.replace("O1000", "O1"))
    library.create_program(number=2, name="b", text="%\nO2 (100% FEED)\nG0 X0\n%\n")
    assert [p.number for p in library.search(text=needle).items] == found


def test_text_search_ignores_case_on_every_backend(library):
    library.create_program(number=1, name="a", text=PROG.replace("O1000", "O1"))
    assert [p.number for p in library.search(text="(bracket)").items] == [1]
    assert [p.number for p in library.search(text="n20 g1").items] == [1]


@pytest.mark.parametrize("drive", ["auto", "index", "programs"])
def test_text_search_pages_alike_whether_from_the_index_or_by_walking_programs(library, drive):
    """A text search walks the index's hits in program order, or checks program after
    program against the index (with a number or name to match, or under 3 characters).
    Both give the same pages, old revisions included."""
    library.text_search_from = drive
    for n in range(1, 10):
        prog, _ = library.create_program(
            number=n, name=f"p{n}", text=f"%\nO{n} (OP{n % 3})\nG0 X{n}\n%\n"
        )
        # The tool call lives only in an older revision of every third program.
        library.add_revision(prog.id, f"%\nO{n} (OP{n % 3})\nT{n % 3} M6\nG0 X{n}\n%\n")
        library.add_revision(prog.id, f"%\nO{n} (OP{n % 3} NEW)\nG0 X{n}\n%\n")

    def pages(**kw) -> list[list[int]]:
        out, cursor = [], None
        while True:
            page = library.search(limit=2, cursor=cursor, **kw)
            out.append([p.number for p in page.items])
            if not (cursor := page.next_cursor):
                return out

    assert pages(text="T0 M6") == [[3, 6], [9]]
    assert pages(text="(op1") == [[1, 4], [7]]
    assert pages(text="G0 X") == [[1, 2], [3, 4], [5, 6], [7, 8], [9]]
    assert pages(text="X") == pages(text="G0 X")
    assert pages(text="T0 M6", tag="none") == [[]]
    assert pages(text='"') == [[]]
    assert pages(text="G0 X", query="p") == pages(text="G0 X")
    assert pages(text="(OP0", number=6) == [[6]]
    assert pages(text="(OP0", machine_kind="lathe") == [[]]


def test_name_search_ignores_case_on_every_backend(library):
    library.create_program(number=1, name="Bracket LEFT", text=PROG.replace("O1000", "O1"))
    assert [p.number for p in library.search(query="bracket left").items] == [1]
    assert [p.number for p in library.search(query="BRACKET l").items] == [1]


@pytest.mark.parametrize(
    ("text", "says", "where"),
    [
        ("%\nO1\n(CAF\u00c9)\nM30\n%\n", "character '\u00c9' (U+00C9, bytes C3 89)", (9, 3, 5)),
        ("O1\nG0 X1\u00b0\n", "character '\u00b0' (U+00B0, bytes C2 B0)", (8, 2, 6)),
        ("O1\nG0 X1\n(\u2013)\n", "(U+2013, bytes E2 80 93)", (10, 3, 2)),
        ("O1\nG0 X1\x01\n", "control character 0x01", (8, 2, 6)),
        ("O1\nG0 X1\x7f\n", "control character 0x7F", (8, 2, 6)),
    ],
)
def test_program_text_is_held_to_the_iso_6983_character_set(library, text, says, where):
    """A non-ASCII character passed the NC check and the release, then wedged the dispatch
    (issue 14, item 9): refused at upload with the byte offset, line and column."""
    with pytest.raises(InvalidUpload, match=re.escape(says)) as info:
        library.create_program(number=1, name="a", text=text)
    d = info.value.detail
    assert (d["offset"], d["line"], d["column"]) == where
    assert f"line {where[1]}" in str(info.value) and f"column {where[2]}" in str(info.value)
    assert library.search().items == []


def test_dnc_import_refuses_a_file_outside_the_character_set(library, tmp_path):
    (tmp_path / "O0007.nc").write_bytes("%\nO0007\nG0 X1 (\u00d8 10)\nM30\n%\n".encode())
    (tmp_path / "O0008.nc").write_bytes(b"%\nO0008\nG0 X1\nM30\n%\n")
    results = {p.name: r for p, r in library.import_path(tmp_path)}
    assert isinstance(results["O0007.nc"], InvalidUpload)
    assert "U+00D8" in str(results["O0007.nc"]) and "line 3, column 8" in str(results["O0007.nc"])
    assert not isinstance(results["O0008.nc"], Exception)

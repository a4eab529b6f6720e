"""ISO tape code: even parity, program framing and the incremental decoder."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cnc.faces.tape import (
    XOFF,
    TapeDecoder,
    add_parity,
    encode_program,
    parity_error_at,
    strip_parity,
)


@pytest.mark.parametrize(
    "char, on_tape",
    [
        ("%", 0xA5),  # 0x25 has 3 ones -> parity bit set
        ("0", 0x30),  # 2 ones -> unchanged
        ("G", 0x47),  # 4 ones
        ("X", 0xD8),  # 0x58 has 3 ones
        ("\n", 0x0A),  # LF: 2 ones
        (" ", 0xA0),
    ],
)
def test_even_parity_table(char, on_tape):
    assert add_parity(char.encode()) == bytes([on_tape])
    assert strip_parity(bytes([on_tape])) == char.encode()


def test_parity_error_is_located():
    tape = bytearray(add_parity(b"%\nG0 X1\n%\n"))
    assert parity_error_at(bytes(tape)) is None
    tape[5] ^= 0x04
    assert parity_error_at(bytes(tape)) == 5


def test_parity_refuses_8_bit_text():
    with pytest.raises(ValueError, match="7-bit"):
        add_parity("Ä".encode())


@pytest.mark.parametrize(
    "text, tape",
    [
        ("O1\nG0 X1", b"%\nO1\nG0 X1\n%\n"),
        ("%\nO1\nM30\n%\n", b"%\nO1\nM30\n%\n"),
        ("O1\r\nM30\r\n\r\n", b"%\nO1\nM30\n%\n"),
        ("%\n%\n", b"%\n%\n"),
        ("%\nO1\n\nM30\n%\n\n", b"%\nO1\n\nM30\n%\n"),
        (" %\nO1\n%\n", b" %\nO1\n%\n"),
    ],
)
def test_encode_program_frames_once(text, tape):
    assert encode_program(text) == tape
    assert encode_program(text, leader=2) == b"\0\0" + tape


def events(decoder, data):
    return [(e.kind, e.text) for e in decoder.feed(data)]


def test_decoder_skips_leader_cr_and_reports_controls():
    data = b"\0\0\n%\r\nO1\r\nG0\x13 X1\n%\nTRAILER"
    assert events(TapeDecoder(), data) == [
        ("start", ""),
        ("line", "O1"),
        ("control", ""),
        ("line", "G0 X1"),
        ("end", ""),
    ]


def test_decoder_stops_at_the_first_parity_error():
    tape = bytearray(add_parity(b"%\nO1\nG0 X1\n%\n"))
    tape[6] ^= 0x01
    d = TapeDecoder(parity=True)
    assert events(d, bytes(tape))[-1] == ("parity_error", "")
    assert d.failed and not d.ended


def test_overlong_block_is_refused():
    d = TapeDecoder(max_block=8)
    assert events(d, b"%\n123456789\n")[-1] == ("overlong", "")


@given(
    st.lists(st.from_regex(r"[A-Z0-9 .\-()]{0,20}", fullmatch=True), max_size=10),
    st.lists(st.integers(1, 7), min_size=1, max_size=40),
    st.booleans(),
)
def test_any_chunking_decodes_the_same(blocks, cuts, parity):
    blocks = [b for b in blocks if b.strip() != "%" and "%" not in b]
    tape = encode_program("\n".join(["O1", *blocks]), parity=parity)
    whole = events(TapeDecoder(parity=parity), tape)
    d, out, i = TapeDecoder(parity=parity), [], 0
    for n in cuts * (len(tape) // len(cuts) + 1):
        if i >= len(tape):
            break
        out += events(d, tape[i : i + n])
        i += n
    out += events(d, tape[i:])
    assert out == whole
    expected = ["O1", *blocks]
    while not expected[-1].strip():  # trailing blank blocks are not put on tape
        expected.pop()
    assert [t for k, t in whole if k == "line"] == expected


def test_xoff_inside_a_block_does_not_split_it():
    assert events(TapeDecoder(), b"%\nG0" + bytes([XOFF]) + b"X1\n")[1:] == [
        ("control", ""),
        ("line", "G0X1"),
    ]


class BlockByBlock(TapeDecoder):
    """The decoder without its runs of blocks: the reference they must agree with."""

    def _run_of_blocks(self, data, i, events, runs):
        return i


def runs(decoder, data):
    out = []
    for e in decoder.feed_runs(data):
        out += [("line", t) for t in e.lines] if e.kind == "lines" else [(e.kind, e.text)]
    return out


def detailed(decoder, data):
    return [(e.kind, e.text, e.offset, e.code) for e in decoder.feed(data)]


@given(
    st.lists(st.from_regex(r"[A-Z0-9 .\-()%\r\x13]{0,12}", fullmatch=True), max_size=12),
    st.lists(st.integers(1, 40), min_size=1, max_size=10),
    st.booleans(),
)
def test_runs_of_blocks_decode_as_block_by_block(blocks, cuts, parity):
    tape = encode_program("\n".join(["O1", *blocks]), parity=parity)
    if not parity:
        tape = tape[:4] + b"\xff" + tape[4:]  # a stray 8-bit byte in the first block
    elif blocks:
        tape = tape[:-3] + bytes([tape[-3] ^ 1]) + tape[-2:]  # a parity error near the end
    reference = detailed(BlockByBlock(parity=parity, max_block=10), tape)
    assert detailed(TapeDecoder(parity=parity, max_block=10), tape) == reference
    d, out, i = TapeDecoder(parity=parity, max_block=10), [], 0
    for n in cuts * (len(tape) // len(cuts) + 1):
        if i >= len(tape):
            break
        out += runs(d, tape[i : i + n])
        i += n
    out += runs(d, tape[i:])
    assert out == [(k, t) for k, t, *_ in reference]


def test_line_offsets_are_those_of_the_block_ends():
    data = b"%\nO1\nG0 X1\nG1 Y2\n%\n"
    lf = [i for i, b in enumerate(data) if b == 0x0A]
    lines = [e.offset for e in TapeDecoder().feed(data) if e.kind == "line"]
    assert lines == lf[1:4]
    d = TapeDecoder()
    d.feed(data[:7])  # "G0" carried into the next feed
    assert [e.offset for e in d.feed(data[7:]) if e.kind == "line"] == lf[2:4]

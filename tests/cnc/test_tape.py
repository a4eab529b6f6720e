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

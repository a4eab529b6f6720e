"""Bit-exact CAN frame lengths against hand-worked frames and the anchor note's figures."""

import random
import statistics

import pytest

from drives.bus.frame import (
    TRAILER_BITS,
    crc15,
    data_frame_bits,
    frame_bits,
    nominal_bits,
    stuff_bit_count,
    stuffed_bitstream,
    unstuffed_bits,
    worst_case_bits,
)


def _bits_of(text: str) -> list[int]:
    return [int(c) for c in text.replace(" ", "")]


def test_crc15_check_value_of_the_standard_string():
    # CRC-15/CAN catalogue check value over the bytes "123456789".
    bits = [(byte >> (7 - i)) & 1 for byte in b"123456789" for i in range(8)]
    assert crc15(bits) == 0x059E


def test_sync_frame_hand_worked():
    # SYNC 0x080, DLC 0. SOF 0 | ID 000 1000 0000 | RTR 0 IDE 0 r0 0 | DLC 0000 | CRC-15.
    head = "0" + "00010000000" + "000" + "0000"
    bits = unstuffed_bits(0x080, b"")
    assert bits[:19] == _bits_of(head)
    crc = crc15(_bits_of(head))
    assert bits[19:] == [(crc >> (14 - i)) & 1 for i in range(15)]
    # Runs: "0000" + "1" then "0000000000000000" (7 id zeros + 3 ctl + 4 dlc +...) stuff.
    assert stuffed_bitstream(_bits_of("000001"))[:7] == _bits_of("0000011")
    assert frame_bits(0x080, b"") == 51  # anchor note, measured with an independent builder


def test_stuff_bits_count_stuff_bits_in_the_next_run():
    # 10 zeros: 00000 [1] 00000 [1] -> 2 stuff bits; the stuff bit starts a new run.
    assert stuff_bit_count([0] * 10) == 2
    # 0000 1111 1: after "0000" comes "1" (run of 1s: 11111) -> one stuff bit after five 1s.
    assert stuff_bit_count(_bits_of("000011111")) == 1
    # Five zeros, stuffed 1, then four 1s: the stuffed 1 + 1111 = five 1s -> another stuff bit.
    assert stuffed_bitstream(_bits_of("000001111")) == _bits_of("00000 1 1111 0")


@pytest.mark.parametrize(
    ("can_id", "data", "bits"),
    [
        (0x080, b"", 51),  # SYNC
        (0x181, bytes(8), 126),  # all-zero payload stuffs heavily
        (0x085, bytes([0x11, 0x86, 0x80, 0, 0, 0, 0, 0]), 121),  # EMCY 0x8611
    ],
)
def test_anchor_note_measured_frames(can_id, data, bits):
    assert frame_bits(can_id, data) == bits


@pytest.mark.parametrize("dlc", range(9))
def test_nominal_and_worst_case_formulae(dlc):
    assert nominal_bits(dlc) == 47 + 8 * dlc
    assert worst_case_bits(dlc) == 47 + 8 * dlc + (34 + 8 * dlc - 1) // 4
    assert nominal_bits(dlc, extended=True) == 67 + 8 * dlc


def test_worst_case_table_of_the_anchor_note():
    assert [worst_case_bits(n) for n in (0, 1, 2, 6, 8)] == [55, 65, 75, 115, 135]
    assert [nominal_bits(n) for n in (0, 1, 2, 6, 8)] == [47, 55, 63, 95, 111]


def test_every_frame_lies_between_nominal_and_worst_case():
    rng = random.Random(7)
    for _ in range(2000):
        extended = rng.random() < 0.3
        can_id = rng.randrange(1 << (29 if extended else 11))
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(9)))
        bits = frame_bits(can_id, data, extended)
        assert nominal_bits(len(data), extended=extended) <= bits
        assert bits <= worst_case_bits(len(data), extended=extended)


def test_random_payload_mean_is_about_114_bits():
    rng = random.Random(1)
    mean = statistics.mean(
        frame_bits(0x181, bytes(rng.randrange(256) for _ in range(8))) for _ in range(5000)
    )
    assert 113.0 <= mean <= 115.5


def test_extended_identifier_layout():
    bits = unstuffed_bits(0x1ABCDEF0 & 0x1FFFFFFF, b"\x01", extended=True)
    assert bits[0] == 0
    assert bits[12:14] == [1, 1]  # SRR, IDE recessive
    base = 0x1ABCDEF0 >> 18
    assert bits[1:12] == [(base >> (10 - i)) & 1 for i in range(11)]
    assert len(bits) == 1 + 11 + 2 + 18 + 3 + 4 + 8 + 15


def test_remote_frame_has_no_data_field_but_keeps_dlc():
    bits = unstuffed_bits(0x701, b"", remote=True, dlc=1)
    assert bits[12] == 1  # RTR recessive
    assert len(bits) == 1 + 11 + 3 + 4 + 15


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"can_id": 0x800, "data": b""}, "11-bit"),
        ({"can_id": 1 << 29, "data": b"", "extended": True}, "29-bit"),
        ({"can_id": 1, "data": bytes(9)}, "max 8"),
    ],
)
def test_bad_frames_are_refused_with_the_reason(kwargs, message):
    with pytest.raises(ValueError, match=message):
        unstuffed_bits(**kwargs)


def test_table_driven_length_equals_the_bit_by_bit_reference():
    rng = random.Random(11)
    patterns = (0x00, 0xFF, 0xF0, 0x0F, 0x1F, 0xF8, 0x83)
    for _ in range(5000):
        extended = rng.random() < 0.3
        remote = rng.random() < 0.1
        can_id = rng.randrange(1 << (29 if extended else 11))
        if rng.random() < 0.1:
            can_id = rng.choice([0, (1 << (29 if extended else 11)) - 1])
        data = bytes(
            rng.choice(patterns) if rng.random() < 0.6 else rng.randrange(256)
            for _ in range(rng.randrange(9))
        )
        dlc = rng.randrange(9) if remote else None
        bits = unstuffed_bits(can_id, data, extended=extended, remote=remote, dlc=dlc)
        reference = len(bits) + stuff_bit_count(bits) + TRAILER_BITS
        assert frame_bits.__wrapped__(can_id, data, extended, remote, dlc) == reference
        if not remote:  # the bus's uncached path for data frames
            assert data_frame_bits(can_id, bytearray(data), extended) == reference

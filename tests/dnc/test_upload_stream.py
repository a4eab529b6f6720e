"""The streamed upload (dnc/upload.py) stores exactly what the in-memory path stores, and
refuses exactly where it refuses, whatever the chunking."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dnc.errors import InvalidUpload
from dnc.tape import count_lines, decode_program, sha256_of
from dnc.upload import ProgramUpload

LIMIT = 1 << 20

texts = st.lists(
    st.sampled_from(
        ["%", "O1234 (A)", "G1 X1", "\r", "\n", "\r\n", "\x11", "\x13", " ", "\t", "M30", "%\n"]
    ),
    max_size=30,
).map("".join)
bad_texts = st.tuples(texts, st.sampled_from(["\u00e9", "\x01", "\x7f", "\u2013", "\x00"]), texts)


def streamed(data: bytes, cuts: list[int]) -> ProgramUpload:
    up = ProgramUpload(limit=LIMIT)
    start = 0
    for cut in sorted({c % (len(data) + 1) for c in cuts}) + [len(data)]:
        up.feed(data[start:cut])
        start = cut
    return up.finish()


def outcome(fn):
    try:
        return ("ok", fn())
    except InvalidUpload as exc:
        d = exc.detail
        return ("refused", d.get("offset"), d.get("line"), d.get("column"))


@settings(max_examples=300, deadline=None)
@given(texts, st.lists(st.integers(0, 400), max_size=6))
def test_streamed_equals_in_memory(text, cuts):
    data = text.encode()

    def memory():
        t = decode_program(data, limit=LIMIT)
        return t, sha256_of(t), count_lines(t)

    def stream():
        with streamed(data, cuts) as up:
            return up.text(), up.sha256, up.lines

    assert outcome(stream) == outcome(memory)


@settings(max_examples=300, deadline=None)
@given(bad_texts, st.lists(st.integers(0, 400), max_size=6))
def test_streamed_refuses_where_in_memory_refuses(parts, cuts):
    data = "".join(parts).encode()
    expected = outcome(lambda: decode_program(data, limit=LIMIT))
    assert expected[0] == "refused"
    assert outcome(lambda: streamed(data, cuts)) == expected


def test_too_large_is_refused_as_soon_as_the_limit_is_passed():
    up = ProgramUpload(limit=10)
    up.feed(b"O1\nG1 X1\n")
    with pytest.raises(InvalidUpload) as info:
        up.feed(b"G1 X2\n")
    assert info.value.detail["limit"] == 10 and info.value.detail["size"] == 15
    up.close()


def test_line_file_feeds_the_nc_check_lazily():
    from dnc.checker import nc_checker

    text = "%\nO1000\nG21 G90 G17\nG0 X0 Y0\nM98 P2000\nM30\nO2000\nG1 X10 F100\nM99\n%\n"
    with ProgramUpload(limit=LIMIT) as up:
        up.feed(text.encode())
        up.finish()
        with up.line_file() as f:
            assert nc_checker(f, "mill") == nc_checker(text, "mill") == []
        bad = text.replace("G1 X10 F100", "G1 X10 F100 G2")
    with ProgramUpload(limit=LIMIT) as up:
        up.feed(bad.encode())
        up.finish()
        with up.line_file() as f:
            assert nc_checker(f, "mill") == nc_checker(bad, "mill") != []


def _counting_checker(text, kind):
    for _ in text.splitlines() if isinstance(text, str) else text:
        pass
    return []


_counting_checker.reads_files = True  # type: ignore[attr-defined]


def test_memory_of_a_streamed_upload_stays_near_one_copy_of_the_program(sessions):
    """Issue 14, item 11 (four 15 MB uploads took the host to 947 MB): a streamed upload of
    6 MB, checked and stored, allocates at most about two copies of its text at any moment
    (reading the stored form back: its bytes and its str), where the in-memory path held
    five. Loose bound: 2.5x."""
    import tracemalloc

    from dnc.library import Library

    lib = Library(sessions, checker=_counting_checker, upload_limit=64 << 20)
    moves = "".join(f"G1 X{i % 50}.{i % 10} Y{i % 7} F300\n" for i in range(20000))
    data = ("%\nO1234 (BIG)\n" + moves * 18 + "M30\n%\n").encode()
    assert len(data) > 6_000_000
    tracemalloc.start()
    try:
        with ProgramUpload(limit=64 << 20, name="big.nc") as up:
            for i in range(0, len(data), 1 << 20):
                up.feed(data[i : i + (1 << 20)])
            _, rev = lib.create_program(number=1234, name="big", text=up)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert rev.size == len(data) and rev.sha256 == sha256_of(data.decode())
    assert peak < 2.5 * len(data), f"peak {peak / 1e6:.1f} MB for {len(data) / 1e6:.1f} MB"


@pytest.mark.parametrize("cut", [1, 2, 3])
def test_a_character_split_between_chunks_is_named_whole(cut):
    data = "O1\nG0 X1 (\u20ac)\n".encode()  # the euro sign: 3 bytes
    i = data.index("\u20ac".encode())
    up = ProgramUpload(limit=LIMIT)
    with pytest.raises(InvalidUpload) as info:
        up.feed(data[: i + cut] if cut < 3 else data[:i] + data[i : i + 1])
        up.feed(data[i + cut :] if cut < 3 else data[i + 1 :])
        up.finish()
    up.close()
    assert "U+20AC" in str(info.value)
    assert (info.value.detail["offset"], info.value.detail["line"]) == (i, 2)
    assert info.value.detail["column"] == 8


def test_large_uploads_are_stored_in_turn_on_one_thread():
    """Every upload over HEAVY_BYTES runs on the one large-upload worker, one after the
    other: stored on several threads, each thread's malloc arena kept its own peak."""
    import asyncio
    import threading
    import time

    from web_api.routers import programs

    seen: list[tuple[int, float, float]] = []

    def work():
        start = time.perf_counter()
        time.sleep(0.02)
        seen.append((threading.get_ident(), start, time.perf_counter()))
        return len(seen)

    big, small = "x" * programs.HEAVY_BYTES, "x"

    async def main():
        return await asyncio.gather(*(programs._heavy(big, work) for _ in range(3)))

    assert sorted(asyncio.run(main())) == [1, 2, 3]
    assert len({ident for ident, _, _ in seen}) == 1
    ordered = sorted(seen, key=lambda s: s[1])
    assert all(a[2] <= b[1] for a, b in zip(ordered, ordered[1:], strict=False))
    assert asyncio.run(programs._heavy(small, lambda: threading.get_ident())) != seen[0][0]

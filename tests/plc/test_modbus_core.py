"""Property tests of the pure cores: arbitrary bytes never crash the framer or the PDU handler."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from plc.image import ImageSize, ProcessImage, Write
from plc.modbus import AllowList, ModbusMap, PduHandler
from plc.modbus.frame import FrameViolation, MbapDecoder
from plc.modbus.pdu import PduSizeError, pack_bits, unpack_bits

SIZE = ImageSize(ix=64, qx=64, mx=64, iw=32, qw=32, mw=32)
MAP = ModbusMap(SIZE)
HANDLER = PduHandler(MAP, AllowList.parse("coil:0-31,hr:0-15").resolve(MAP))
SNAP = ProcessImage(SIZE).snapshot(0)

pdus = st.one_of(
    st.binary(min_size=1, max_size=253),
    st.tuples(
        st.sampled_from([1, 2, 3, 4, 5, 6, 15, 16, 23, 43]), st.binary(min_size=0, max_size=20)
    ).map(lambda t: bytes([t[0]]) + t[1]),
)


@settings(max_examples=400, deadline=None)
@given(pdus)
def test_handler_answers_or_flags_size(pdu):
    try:
        response, batch = HANDLER.handle(pdu, SNAP)
    except PduSizeError:
        return
    assert 1 <= len(response) <= 253
    assert response[0] in (pdu[0], pdu[0] | 0x80)
    if response[0] & 0x80:
        assert len(response) == 2 and response[1] in (1, 2, 3, 4) and batch is None
    if batch is not None:
        for w in batch:
            assert isinstance(w, Write)
            image = ProcessImage(SIZE)
            image.apply(w)  # every queued write fits the image
            if w.area in ("QW", "MW"):
                assert all(-32768 <= v <= 32767 for v in w.values)
            else:
                assert w.area in ("QX", "MX") and set(w.values) <= {0, 1}
                assert w.index + len(w.values) <= 32 or w.area == "MX"


@settings(max_examples=300, deadline=None)
@given(st.lists(st.binary(max_size=40), max_size=20))
def test_decoder_on_arbitrary_chunks(chunks):
    d = MbapDecoder()
    try:
        for c in chunks:
            for tid, unit, pdu in d.feed(c):
                assert 0 <= tid <= 0xFFFF and 0 <= unit <= 255 and 1 <= len(pdu) <= 253
            assert d.pending < 260
    except FrameViolation:
        pass


@given(st.binary(max_size=250))
def test_decoder_is_split_invariant(payload):
    """Frames come out the same however the stream is cut."""
    stream = b"".join(
        bytes([0, i, 0, 0, 0, 1 + len(p), 1]) + p
        for i, p in enumerate([payload[:5] or b"\x03", payload[5:] or b"\x04"])
    )
    whole = MbapDecoder().feed(stream)
    d = MbapDecoder()
    pieces = []
    for k in range(0, len(stream), 3):
        pieces += d.feed(stream[k : k + 3])
    assert pieces == whole and d.pending == 0


@given(st.binary(max_size=2000))
def test_bit_packing_round_trip(raw):
    bits = bytes(b & 1 for b in raw)
    packed = pack_bits(bits)
    assert len(packed) == (len(bits) + 7) // 8
    assert unpack_bits(packed, len(bits)) == bits
    for k, b in enumerate(bits):
        assert (packed[k // 8] >> (k % 8)) & 1 == b

"""SDO server protocol table: every request shape and its exact answer (node 5, raw frames)."""

import pytest

from drives.cia301.sdo_server import MAX_TRANSFER


@pytest.mark.parametrize(
    ("title", "requests", "answer"),
    [
        # ---- expedited
        ("upload U32", ["605#4000100000000000"], ["585#4300100092010200"]),
        ("upload U8 error register", ["605#4001100000000000"], ["585#4F01100000000000"]),
        ("upload U16 heartbeat", ["605#4017100000000000"], ["585#4B17100000000000"]),
        ("upload record sub0", ["605#4018100000000000"], ["585#4F18100004000000"]),
        ("download U16 with size", ["605#2B17100010000000"], ["585#6017100000000000"]),
        ("download U16 without size", ["605#2217100010000000"], ["585#6017100000000000"]),
        ("download U32 cycle period", ["605#23061000E8030000"], ["585#6006100000000000"]),
        # ---- refused
        ("object does not exist", ["605#4004100000000000"], ["585#8004100000000206"]),
        ("sub-index of VAR", ["605#4000100100000000"], ["585#8000100111000906"]),
        ("sub-index of ARRAY", ["605#4016100900000000"], ["585#8016100911000906"]),
        ("sub-index of RECORD", ["605#4018100500000000"], ["585#8018100511000906"]),
        ("write read-only", ["605#2300100001000000"], ["585#8000100002000106"]),
        ("write const", ["605#2F08100041000000"], ["585#8008100002000106"]),
        ("length too high", ["605#2317100001000000"], ["585#8017100012000706"]),
        ("length too low", ["605#2F06100001000000"], ["585#8006100013000706"]),
        ("value too high", ["605#2B5A600009000000"], ["585#805A600031000906"]),
        ("value too low", ["605#2383600000000000"], ["585#8083600032000906"]),
        ("value too low (int8)", ["605#2FC26002F9000000"], ["585#80C2600232000906"]),
        ("1003:00 non-zero", ["605#2F03100002000000"], ["585#8003100030000906"]),
        ("1016:00 is read-only", ["605#2F16100001000000"], ["585#8016100002000106"]),
        ("application refuses", ["605#2B40600000010000"], ["585#8040600030000906"]),
        ("application read-only", ["605#2B41600000000000"], ["585#8041600002000106"]),
        ("application read abort", ["605#4000600000000000"], ["585#8000600000000206"]),
        # ---- protocol errors
        ("unknown command specifier", ["605#E000100000000000"], ["585#8000100001000405"]),
        ("frame shorter than 8 bytes", ["605#400010"], ["585#8000100001000405"]),
        ("segment without transfer", ["605#6000000000000000"], ["585#8000000001000405"]),
        (
            "upload toggle not alternated",
            ["605#4008100000000000", "605#6000000000000000", "605#6000000000000000"],
            ["585#8008100000000305"],
        ),
        (
            "download toggle not alternated",
            ["605#2100210005000000", "605#1061626364650000"],
            ["585#8000210000000305"],
        ),
        (
            "segmented size mismatch for a fixed type",
            ["605#2117100004000000"],
            ["585#8017100012000706"],
        ),
        (
            "segmented data longer than announced",
            ["605#2100210002000000", "605#0061626364656667"],
            ["585#8000210012000706"],
        ),
        (
            "segmented data shorter than announced",
            ["605#2100210009000000", "605#0B61626364000000"],
            ["585#8000210010000706"],
        ),
        (
            "segmented download too large",
            [f"605#21002100{(MAX_TRANSFER + 1).to_bytes(4, 'little').hex().upper()}"],
            ["585#8000210005000405"],
        ),
        ("client abort ends the transfer", ["605#4008100000000000", "605#8008100000000000"], []),
        ("block upload bad block size", ["605#A400210100000000"], ["585#8000210102000405"]),
        ("block download write read-only", ["605#C600100004000000"], ["585#8000100002000106"]),
    ],
)
def test_sdo_table(cell, slave, title, requests, answer):
    replies = []
    for request in requests:
        replies = cell.send(request)
    assert replies == answer, title


def test_segmented_upload_of_an_empty_string(cell, app, slave):
    assert cell.send("605#2100210000000000") == ["585#6000210000000000"]  # 0 bytes follow
    assert cell.send("605#0F00000000000000") == ["585#2000000000000000"]
    assert slave.od.get(0x2100, 0) == ""
    assert cell.send("605#4000210000000000") == ["585#4100210000000000"]
    assert cell.send("605#6000000000000000") == ["585#0F00000000000000"]


def test_block_download_out_of_sequence_segment_is_acked_for_resend(cell, slave):
    assert cell.send("605#C201210010000000") == ["585#A00121007F000000"]
    cell.send("605#0100010203040506")  # seq 1
    ack = cell.send("605#8300000000000000")  # seq 3, last: seq 2 missing
    assert ack == ["585#A2017F0000000000"]


def test_block_download_bad_crc_aborts(cell, slave):
    assert cell.send("605#C601210003000000") == ["585#A40121007F000000"]  # CRC, 3 bytes
    assert cell.send("605#8141424300000000") == ["585#A2017F0000000000"]
    assert cell.send("605#D1FFFF0000000000") == ["585#8001210004000405"]


def test_block_sequence_number_zero_aborts(cell, slave):
    cell.send("605#C201210003000000")
    assert cell.send("605#0041424300000000") == ["585#8001210003000405"]


def test_sdo_server_holds_no_transfer_after_an_abort(cell, slave):
    cell.send("605#4008100000000000")
    cell.send("605#7000000000000000")  # wrong toggle -> abort
    assert slave.sdo.transfer is None
    assert cell.send("605#4000100000000000") == ["585#4300100092010200"]


class _Broken:
    """An application with bugs: wrong types, exceptions."""

    def owns(self, index):
        return 0x6000 <= index <= 0x67FF

    def read_object(self, index, subindex):
        if index == 0x6064:
            return 12.0  # float for INTEGER32: tolerated
        if index == 0x6041:
            return 70000  # does not fit UNSIGNED16
        raise RuntimeError("bug")

    def write_object(self, index, subindex, value):
        raise RuntimeError("bug")

    def on_sync(self):
        raise RuntimeError("bug")

    def advance(self, dt_s):
        pass

    def on_nmt_state(self, state):
        pass

    def on_communication_fault(self, error_code):
        pass

    def take_emcy(self):
        return []


def test_application_bugs_become_aborts_not_crashes(cell):
    from drives.cia301 import CanopenSlave

    slave = CanopenSlave(5, cell.hub.endpoint(), _Broken())
    assert cell.send("605#4064600000000000") == ["585#436460000C000000"]
    assert cell.send("605#4041600000000000") == ["585#8041600000000008"]
    assert cell.send("605#4060600000000000") == ["585#8060600000000008"]
    assert cell.send("605#2B40600006000000") == ["585#8040600000000008"]
    cell.send("000#0105")
    assert cell.send("080#") == []  # on_sync raised: counted, the bus goes on
    assert slave.handler_errors == 1
    assert cell.send("605#4000100000000000") == ["585#4300100092010200"]

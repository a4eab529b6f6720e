"""Process image: snapshots are immutable copies, writes wrap to IEC INT, bounds are checked."""

import pytest

from plc.image import ImageSize, ProcessImage, Write, WriteQueue


def test_snapshot_is_a_copy_taken_at_the_scan():
    img = ProcessImage(ImageSize(ix=8, qx=8, mx=8, iw=2, qw=2, mw=2))
    img.qx[3] = True
    img.mw[1] = -5
    snap = img.snapshot(scan=7)
    img.qx[3] = False
    img.mw[1] = 0
    assert snap.scan == 7 and snap.qx[3] == 1 and snap.mw[1] == -5


@pytest.mark.parametrize(
    "register, expected", [(0, 0), (32767, 32767), (0x8000, -32768), (0xFFFF, -1)]
)
def test_word_writes_wrap_to_int(register, expected):
    img = ProcessImage()
    img.apply(Write("MW", 0, (register,)))
    assert img.mw[0] == expected


def test_write_outside_the_image_is_refused():
    img = ProcessImage(ImageSize(mw=4))
    with pytest.raises(IndexError, match="MW3..4"):
        img.apply(Write("MW", 3, (1, 2)))


def test_queue_drains_batches_in_order():
    q = WriteQueue()
    q.put([Write("QX", 0, (1,))])
    q.put([Write("QX", 1, (1,)), Write("QX", 2, (1,))])
    assert [len(b) for b in q.drain()] == [1, 2]
    assert q.drain() == []

"""The runtime behind its real Modbus TCP face (plc.modbus) and a stock pymodbus client,
stepped in lockstep: a remote-panel write is seen by the logic in the next scan and goes
through the same interlocks; every read comes from one published scan."""

from __future__ import annotations

import pytest
from pymodbus.client import ModbusTcpClient

from plc.ladder import compile_text
from plc.modbus import ModbusFace
from plc.runtime import Runtime

PANEL = """
TAG DoorClosed : BOOL AT %IX0.0     // door switch
TAG RemoteStart: BOOL AT %MX0.0     // remote operator panel coil (host writes it)
TAG RemoteStop : BOOL AT %MX0.1
TAG CycleOn    : BOOL AT %QX0.0
TAG Override   : INT  AT %MW0       // feed override from the host, %
TAG FeedOvr    : INT  AT %QW0       // override handed to the NC, limited 0..120
TAG Cycles     : COUNTER
// no cycle start with the door open, whoever asks
BST XIC RemoteStart NXB XIC CycleOn BND XIC DoorClosed XIO RemoteStop OTE CycleOn
XIC RemoteStart OTU RemoteStart
XIC CycleOn CTU Cycles 1000
LIM 0 Override 120 MOV Override FeedOvr
GRT Override 120 MOV 120 FeedOvr
XIC CycleOn MOV Cycles.ACC %MW10
"""


@pytest.fixture()
def plc():
    rt = Runtime(compile_text(PANEL, "panel.ld"))
    face = ModbusFace(
        lambda: rt.snapshot, rt.writes, rt.image.size, port=0, writable="%MX0.0-%MX0.7,%MW0"
    )
    face.start_in_thread()
    client = ModbusTcpClient("127.0.0.1", port=face.bound_port, timeout=3)
    assert client.connect()
    yield rt, client
    client.close()
    face.stop_thread()


def test_remote_start_passes_the_door_interlock(plc):
    rt, client = plc
    rt.scan(0)
    assert not client.write_coil(8192, True).isError()  # %MX0.0 RemoteStart
    rt.scan(10)
    assert client.read_coils(0, count=1).bits[0] is False  # door open: refused
    assert client.read_coils(8192, count=1).bits[0] is False  # request consumed
    rt.image.ix[0] = True  # door closed (field input)
    client.write_coil(8192, True)
    rt.scan(20)
    assert client.read_coils(0, count=1).bits[0] is True
    client.write_coil(8193, True)  # RemoteStop
    rt.scan(30)
    assert client.read_coils(0, count=1).bits[0] is False


def test_override_register_is_limited_by_the_logic(plc):
    rt, client = plc
    assert not client.write_register(1024, 150).isError()  # %MW0
    rt.scan(0)
    assert client.read_holding_registers(0, count=1).registers == [120]  # %QW0
    client.write_register(1024, 80)
    rt.scan(10)
    assert client.read_holding_registers(0, count=1).registers == [80]
    # outputs are not writable from Modbus
    assert client.write_register(0, 5).isError() and client.write_coil(0, True).isError()
    rt.scan(20)
    assert client.read_coils(0, count=1).bits[0] is False


def test_reads_come_from_the_last_published_scan(plc):
    rt, client = plc
    rt.image.ix[0] = True
    client.write_coil(8192, True)
    rt.scan(0)
    rt.image.mw[10] = 999  # changed behind the scan's back: not published yet
    assert client.read_holding_registers(1034, count=1).registers == [1]
    rt.scan(10)
    assert client.read_holding_registers(1034, count=1).registers == [1]
    assert rt.read("Cycles.ACC") == 1

"""The shipped EDS: loads in canopen, describes every object, and matches the slave."""

import configparser

import canopen
import pytest
from canopen import objectdictionary as odt

from drives import EDS_PATH

REQUIRED_301 = [0x1000, 0x1001, 0x1003, 0x1005, 0x1006, 0x1008, 0x1009, 0x100A, 0x100C]
REQUIRED_301 += [0x100D, 0x1010, 0x1011, 0x1014]
REQUIRED_301 += [0x1016, 0x1017, 0x1018]
REQUIRED_301 += [base + k for base in (0x1400, 0x1600, 0x1800, 0x1A00) for k in range(4)]
REQUIRED_402 = [
    0x603F, 0x6007, 0x6040, 0x6041, 0x605A, 0x605B, 0x605C, 0x605D, 0x605E, 0x6060, 0x6061,
    0x6064, 0x6065, 0x6066, 0x606C, 0x6071, 0x6077, 0x607A, 0x607C, 0x607D, 0x607F, 0x6080,
    0x6081, 0x6083, 0x6084, 0x6085, 0x6098, 0x6099, 0x609A, 0x60C2, 0x60F4, 0x60FF, 0x6502,
]  # fmt: skip


@pytest.fixture(scope="module")
def od():
    return canopen.import_od(EDS_PATH, 5)


def test_every_required_object_is_described(od):
    missing = [hex(i) for i in REQUIRED_301 + REQUIRED_402 if i not in od]
    assert missing == []


@pytest.mark.parametrize(
    ("index", "sub", "data_type", "access", "mappable"),
    [
        (0x1000, 0, odt.UNSIGNED32, "ro", False),
        (0x6040, 0, odt.UNSIGNED16, "rww", True),
        (0x6041, 0, odt.UNSIGNED16, "ro", True),
        (0x6060, 0, odt.INTEGER8, "rww", True),
        (0x6061, 0, odt.INTEGER8, "ro", True),
        (0x6064, 0, odt.INTEGER32, "ro", True),
        (0x607A, 0, odt.INTEGER32, "rww", True),
        (0x605A, 0, odt.INTEGER16, "rw", False),
        (0x6007, 0, odt.INTEGER16, "rw", False),
        (0x6065, 0, odt.UNSIGNED32, "rw", False),
        (0x6066, 0, odt.UNSIGNED16, "rw", False),
        (0x607D, 1, odt.INTEGER32, "rw", False),
        (0x6099, 2, odt.UNSIGNED32, "rw", False),
        (0x60C2, 1, odt.UNSIGNED8, "rw", False),
        (0x60C2, 2, odt.INTEGER8, "rw", False),
        (0x6502, 0, odt.UNSIGNED32, "ro", False),
    ],
)
def test_types_access_and_mapping(od, index, sub, data_type, access, mappable):
    obj = od[index]
    var = obj if isinstance(obj, odt.ODVariable) else obj[sub]
    assert (var.data_type, var.access_type, var.pdo_mappable) == (data_type, access, mappable)


def test_profile_values(od):
    assert od[0x1000].default == 0x00020192  # CiA 402 servo drive
    assert od[0x6502].default & 0x1A5 == 0x1A5  # PP, PV, HM, CSP, CSV
    assert (od[0x605A].min, od[0x605A].max, od[0x605A].default) == (0, 8, 2)
    assert (od[0x605E].min, od[0x605E].max) == (0, 4)
    assert (od[0x6007].min, od[0x6007].max) == (0, 3)
    assert (od[0x60C2][1].default, od[0x60C2][2].default) == (2, -3)  # 2 ms IPO cycle


def test_node_id_relative_cob_ids(od):
    assert od[0x1014].default == 0x85
    assert [od[0x1400 + k][1].default & 0x7FF for k in range(4)] == [0x205, 0x305, 0x405, 0x505]
    assert [od[0x1800 + k][1].default & 0x7FF for k in range(4)] == [0x185, 0x285, 0x385, 0x485]


def test_default_mappings_fit_classic_can_and_point_at_mappable_objects(od):
    for base, direction in ((0x1600, "r"), (0x1A00, "t")):
        for k in range(4):
            record = od[base + k]
            entries = [record[s].default for s in range(1, record[0].default + 1)]
            assert sum(e & 0xFF for e in entries) <= 64
            for entry in entries:
                var = od.get_variable(entry >> 16, (entry >> 8) & 0xFF)
                assert var.pdo_mappable and len(var) == entry & 0xFF
                assert var.writable if direction == "r" else var.readable


def test_object_lists_match_the_sections():
    eds = configparser.ConfigParser()
    eds.optionxform = str
    eds.read(EDS_PATH)
    listed = set()
    for section in ("MandatoryObjects", "OptionalObjects", "ManufacturerObjects"):
        count = int(eds[section]["SupportedObjects"])
        listed |= {int(eds[section][str(i)], 0) for i in range(1, count + 1)}
    described = {int(s, 16) for s in eds.sections() if len(s) == 4 and s.isalnum()}
    assert listed == described
    for section in eds.sections():
        if "ObjectType" in eds[section] and int(eds[section]["ObjectType"], 0) in (8, 9):
            subs = [s for s in eds.sections() if s.startswith(f"{section}sub")]
            assert int(eds[section]["SubNumber"], 0) == len(subs), section


def test_stock_master_classes_accept_the_eds():
    network = canopen.Network()
    node = canopen.BaseNode402(5, EDS_PATH)
    network.add_node(node)
    assert len(node.tpdo) == 4 and len(node.rpdo) == 4
    node.tpdo.read(from_od=True)
    assert [v.index for v in node.tpdo[1].map] == [0x6041, 0x6064]
    out = network.add_node(7, EDS_PATH)
    out.rpdo.read(from_od=True)
    assert out.rpdo[1].cob_id == 0x207


def test_export_round_trip(tmp_path, od):
    path = tmp_path / "node5.dcf"
    canopen.export_od(od, str(path))
    again = canopen.import_od(str(path), 5)
    assert set(again) == set(od)


def test_importing_drives_stays_light():
    import subprocess
    import sys

    code = "import sys, drives; print('canopen' in sys.modules, 'can' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]
    from drives import CanHub, CanopenSlave

    assert CanHub.__name__ == "CanHub" and CanopenSlave.__name__ == "CanopenSlave"


def test_profile_section_matches_the_cia402_application(od):
    """CTT "OD 02/08": every object the application owns is in the EDS with its type,
    access, limits, and the value a freshly powered drive reports as DefaultValue."""
    from drives.cia402.application import Drive402
    from drives.cia402.objects import OBJECTS

    types = {"i8": odt.INTEGER8, "u8": odt.UNSIGNED8, "i16": odt.INTEGER16}
    types |= {"u16": odt.UNSIGNED16, "i32": odt.INTEGER32, "u32": odt.UNSIGNED32}
    drive = Drive402()
    mismatches = []
    for index, subs in OBJECTS.items():
        for sub, spec in subs.items():
            obj = od[index]
            var = obj if isinstance(obj, odt.ODVariable) else obj[sub]
            expected = (types[spec.dtype], spec.writable, spec.low, spec.high)
            expected += (drive.read_object(index, sub),)
            got = (var.data_type, var.writable, var.min, var.max, var.default)
            if got != expected:
                mismatches.append((hex(index), sub, got, expected))
    assert mismatches == []


def test_shipped_eds_is_what_the_generator_writes(monkeypatch):
    import importlib.util
    import sys
    from pathlib import Path

    path = Path(EDS_PATH).parent / "generate.py"
    spec = importlib.util.spec_from_file_location("fmscell_eds_generate", path)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, module)  # dataclasses look the module up
    spec.loader.exec_module(module)
    assert Path(EDS_PATH).read_text() == module.generate(), "run drives/eds/generate.py"

"""Regenerate `fmscell_servo.eds`: `.venv/bin/python drives/eds/generate.py [--check]`.

The communication section (0x1000-0x1FFF) and the PDO defaults are declared here; the
profile section (0x6000-0x9FFF) is derived from `drives.cia402.objects` with the values a
freshly powered `Drive402` reports, so the EDS cannot drift from the drive (CTT "OD 02/08").
`--check` exits 1 if the shipped file differs from what would be generated.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
EDS_FILE = HERE / "fmscell_servo.eds"

BOOL, I8, I16, I32, U8, U16, U32, VS, DOM = 0x1, 0x2, 0x3, 0x4, 0x5, 0x6, 0x7, 0x9, 0xF
VAR, ARRAY, RECORD = 0x7, 0x8, 0x9


@dataclass
class Var:
    name: str
    data_type: int
    access: str
    default: str
    pdo: bool = False
    low: str | None = None
    high: str | None = None


@dataclass
class Obj:
    index: int
    name: str
    kind: int
    subs: dict[int, Var] = field(default_factory=dict)


def communication_objects() -> list[Obj]:
    objs: list[Obj] = []

    def var(index: int, name: str, *args, **kwargs) -> None:
        objs.append(Obj(index, name, VAR, {0: Var(name, *args, **kwargs)}))

    def array(index: int, name: str, subs: dict[int, Var], kind: int = ARRAY) -> None:
        objs.append(Obj(index, name, kind, subs))

    def count(n: int, name: str = "Highest sub-index supported") -> Var:
        return Var(name, U8, "ro", str(n))

    var(0x1000, "Device type", U32, "ro", "0x00020192")
    var(0x1001, "Error register", U8, "ro", "0x00", pdo=True)
    array(
        0x1003,
        "Pre-defined error field",
        {0: Var("Number of errors", U8, "rw", "0", low="0", high="8")}
        | {i: Var(f"Standard error field {i}", U32, "ro", "0x00000000") for i in range(1, 9)},
    )
    var(0x1005, "COB-ID SYNC", U32, "rw", "0x00000080")
    var(0x1006, "Communication cycle period", U32, "rw", "0")
    var(0x1008, "Manufacturer device name", VS, "const", "fmscell virtual servo drive")
    var(0x1009, "Manufacturer hardware version", VS, "const", "sim-1")
    var(0x100A, "Manufacturer software version", VS, "const", "fmscell 0.1")
    var(0x100C, "Guard time", U16, "rw", "0")
    var(0x100D, "Life time factor", U8, "rw", "0")
    for index, verb, groups in (
        (0x1010, "Save", ("all", "communication", "application")),
        (0x1011, "Restore", ("all default", "communication default", "application default")),
    ):
        name = "Store parameters" if index == 0x1010 else "Restore default parameters"
        subs = {0: count(3)} | {
            i: Var(f"{verb} {group} parameters", U32, "rw", "0x00000001")
            for i, group in enumerate(groups, 1)
        }
        array(index, name, subs)
    var(0x1014, "COB-ID EMCY", U32, "rw", "$NODEID+0x80")
    var(0x1015, "Inhibit time EMCY", U16, "rw", "0")
    array(
        0x1016,
        "Consumer heartbeat time",
        {0: count(4, "Number of entries")}
        | {i: Var(f"Consumer heartbeat time {i}", U32, "rw", "0x00000000") for i in range(1, 5)},
    )
    var(0x1017, "Producer heartbeat time", U16, "rw", "0")
    array(
        0x1018,
        "Identity object",
        {
            0: count(4, "Number of entries"),
            1: Var("Vendor-ID", U32, "ro", "0x464D5343"),
            2: Var("Product code", U32, "ro", "0x00000402"),
            3: Var("Revision number", U32, "ro", "0x00010000"),
            4: Var("Serial number", U32, "ro", "$NODEID+0x0"),
        },
        RECORD,
    )
    var(0x1019, "Synchronous counter overflow value", U8, "rw", "0")
    array(
        0x1200,
        "SDO server parameter",
        {
            0: count(2),
            1: Var("COB-ID client to server", U32, "ro", "$NODEID+0x600"),
            2: Var("COB-ID server to client", U32, "ro", "$NODEID+0x580"),
        },
        RECORD,
    )
    # (COB-ID base, valid, transmission type, mapping): type 255 so that canopen.BaseNode402
    # works without SYNC; a cyclic master remaps to type 1. Each RPDO carries one object: a
    # master that transmits a PDO to change one object (BaseNode402's controlword and op_mode
    # setters do) must never send a stale copy of another with it. CiA 402's suggested
    # layouts repeat the controlword in RPDO2-4, so `op_mode = ...` sent controlword 0
    # (Disable voltage) and a controlword change sent target position 0.
    rpdos = [
        (0x200, True, 255, ["0x60400010"]),
        (0x300, True, 255, ["0x60600008"]),
        (0x400, True, 255, ["0x607A0020"]),
        (0x500, True, 255, ["0x60FF0020"]),
    ]
    tpdos = [
        (0x180, True, 255, ["0x60410010", "0x60640020"]),
        (0x280, True, 255, ["0x60410010", "0x60610008"]),
        (0x380, False, 1, ["0x60410010", "0x606C0020"]),
        (0x480, False, 1, ["0x60F40020", "0x60770010"]),
    ]
    for base_index, kind, table in ((0x1400, "RPDO", rpdos), (0x1800, "TPDO", tpdos)):
        for k, (cob, valid, trans_type, _) in enumerate(table):
            cob_text = f"$NODEID+0x{cob if valid else cob | 0x80000000:X}"
            subs = {
                0: count(6 if kind == "TPDO" else 5),
                1: Var(f"COB-ID used by {kind}", U32, "rw", cob_text),
                2: Var("Transmission type", U8, "rw", str(trans_type)),
                3: Var("Inhibit time", U16, "rw", "0"),
                5: Var("Event timer", U16, "rw", "0"),
            }
            if kind == "TPDO":
                subs[6] = Var("SYNC start value", U8, "rw", "0")
            array(base_index + k, f"{kind} communication parameter {k + 1}", subs, RECORD)
        for k, (_, _, _, mapping) in enumerate(table):
            subs = {
                0: Var(
                    "Number of mapped application objects in PDO",
                    U8,
                    "rw",
                    str(len(mapping)),
                    low="0",
                    high="8",
                )
            }
            for i in range(1, 9):
                default = mapping[i - 1] if i <= len(mapping) else "0x00000000"
                subs[i] = Var(f"Application object {i}", U32, "rw", default)
            array(base_index + 0x200 + k, f"{kind} mapping parameter {k + 1}", subs, RECORD)
    var(0x2100, "Axis name", VS, "rw", "axis")
    var(0x2101, "Trace buffer", DOM, "rw", "")
    return objs


RPDO_MAPPABLE = {0x6040, 0x6060, 0x607A, 0x60FF, 0x6071, 0x6081, 0x6083, 0x6084}
TPDO_MAPPABLE = {0x603F, 0x6041, 0x6061, 0x6062, 0x6063, 0x6064, 0x606B, 0x606C}
TPDO_MAPPABLE |= {0x6077, 0x6078, 0x60F4, 0x60FD}
RECORD_NAMES = {
    0x607D: "Software position limit",
    0x608F: "Position encoder resolution",
    0x6091: "Gear ratio",
    0x6092: "Feed constant",
    0x6099: "Homing speeds",
    0x60C2: "Interpolation time period",
}


def profile_objects() -> list[Obj]:
    sys.path.insert(0, str(HERE.parent.parent))
    # deferred: run as a script, the project root must be on sys.path first
    from drives.cia402.application import Drive402
    from drives.cia402.objects import OBJECTS

    types = {"i8": I8, "u8": U8, "i16": I16, "u16": U16, "i32": I32, "u32": U32}
    drive = Drive402()
    objs = []
    for index, specs in OBJECTS.items():
        subs = {}
        for sub, spec in specs.items():
            access = ("rww" if index in RPDO_MAPPABLE else "rw") if spec.writable else "ro"
            subs[sub] = Var(
                spec.name[0].upper() + spec.name[1:],
                types[spec.dtype],
                access,
                str(drive.read_object(index, sub)),
                pdo=sub == 0 and index in RPDO_MAPPABLE | TPDO_MAPPABLE,
                low=None if spec.low is None else str(spec.low),
                high=None if spec.high is None else str(spec.high),
            )
        if len(subs) == 1:
            objs.append(Obj(index, subs[0].name, VAR, subs))
        else:
            same_type = len({v.data_type for s, v in subs.items() if s}) == 1
            name = RECORD_NAMES.get(index, f"Object {index:04X}")
            objs.append(Obj(index, name, ARRAY if same_type else RECORD, subs))
    if all(o.index != 0x6071 for o in objs):
        # Listed by the profile, not modelled by the application: the slave stores it.
        objs.append(
            Obj(0x6071, "Target torque", VAR, {0: Var("Target torque", I16, "rww", "0", True)})
        )
    return objs


def render(objs: list[Obj]) -> str:
    objs = sorted(objs, key=lambda o: o.index)
    mandatory = [0x1000, 0x1001, 0x1018]
    lists = {
        "MandatoryObjects": mandatory,
        "OptionalObjects": [
            o.index for o in objs if o.index not in mandatory and not 0x2000 <= o.index < 0x6000
        ],
        "ManufacturerObjects": [o.index for o in objs if 0x2000 <= o.index < 0x6000],
    }
    out = [
        "; fmscell virtual CiA 402 servo drive: electronic data sheet (CiA 306).",
        "; Generated by drives/eds/generate.py: edit that script, not this file.",
        "; Position user unit = 1 um by default (0x6092 feed 10000 per screw revolution of a",
        "; 10 mm lead), velocities um/s, accelerations um/s^2, 0x6080 rpm, torque/current per",
        "; mille of rated, times in ms unless the object says otherwise.",
        "",
        "[FileInfo]",
        "FileName=fmscell_servo.eds",
        "FileVersion=1",
        "FileRevision=0",
        "EDSVersion=4.0",
        "Description=fmscell virtual CiA 402 servo drive",
        "CreatedBy=fmscell",
        "",
        "[DeviceInfo]",
        "VendorName=fmscell",
        "VendorNumber=0x464D5343",
        "ProductName=fmscell virtual servo drive",
        "ProductNumber=0x00000402",
        "RevisionNumber=0x00010000",
        "OrderCode=FMS-SERVO-400",
        *[f"BaudRate_{b}=1" for b in (10, 20, 50, 125, 250, 500, 800, 1000)],
        "SimpleBootUpMaster=0",
        "SimpleBootUpSlave=1",
        "Granularity=8",
        "DynamicChannelsSupported=0",
        "GroupMessaging=0",
        "NrOfRXPDO=4",
        "NrOfTXPDO=4",
        "LSS_Supported=0",
        "",
        "[DummyUsage]",
        *[f"Dummy000{d}={0 if d == 1 else 1}" for d in range(1, 8)],
        "",
    ]
    for title, indices in lists.items():
        out += [f"[{title}]", f"SupportedObjects={len(indices)}"]
        out += [f"{i}=0x{index:04X}" for i, index in enumerate(indices, 1)] + [""]

    def variable(section: str, v: Var, kind: int = VAR) -> None:
        out.extend(
            [
                f"[{section}]",
                f"ParameterName={v.name}",
                f"ObjectType=0x{kind:X}",
                f"DataType=0x{v.data_type:04X}",
                f"AccessType={v.access}",
            ]
        )
        if v.low is not None:
            out.append(f"LowLimit={v.low}")
        if v.high is not None:
            out.append(f"HighLimit={v.high}")
        out.extend([f"DefaultValue={v.default}", f"PDOMapping={int(v.pdo)}", ""])

    for obj in objs:
        if obj.kind == VAR:
            variable(f"{obj.index:04X}", obj.subs[0])
            continue
        out += [
            f"[{obj.index:04X}]",
            f"ParameterName={obj.name}",
            f"ObjectType=0x{obj.kind:X}",
            f"SubNumber={len(obj.subs)}",
            "",
        ]
        for sub, v in sorted(obj.subs.items()):
            variable(f"{obj.index:04X}sub{sub:X}", v)
    return "\n".join(out)


def generate() -> str:
    return render(communication_objects() + profile_objects())


def main(argv: list[str]) -> int:
    text = generate()
    if "--check" in argv:
        if EDS_FILE.read_text() != text:
            print(f"{EDS_FILE} is out of date: run drives/eds/generate.py", file=sys.stderr)
            return 1
        return 0
    EDS_FILE.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""PLCopen import of the IEC 61131-3 standard functions (MOVE, comparison, arithmetic,
selection), externalVars/globalVars scopes and data-flow variables, checked by running the
imported program against values worked out by hand; and the real OpenPLC Editor / Beremiz
files of the shared corpus, each with the outcome it must have."""

from __future__ import annotations

import itertools

import pytest

from plc.ladder import check_file, compile_program, format_program, import_plcopen, load_file
from plc.runtime import Runtime
from tests.reference import MISSING, PLCOPEN_CORPUS

HEAD = """<?xml version="1.0" encoding="utf-8"?>
<project xmlns="http://www.plcopen.org/xml/tc6_0201">
<types><pous><pou name="fns" pouType="program">
<interface>
<localVars>
{locals}
</localVars>
<externalVars>
<variable name="Shared"><type><INT/></type></variable>
</externalVars>
</interface>
<body><LD>
<leftPowerRail localId="1"><position x="0" y="0"/><connectionPointOut formalParameter=""/></leftPowerRail>
"""
TAIL = """</LD></body></pou></pous></types>
<instances><configurations><configuration name="c">
<globalVars><variable name="Shared"><type><INT/></type>
<initialValue><simpleValue value="42"/></initialValue></variable></globalVars>
<resource name="r"><task name="t" priority="0" interval="T#10ms">
<pouInstance name="i" typeName="fns"/></task></resource>
</configuration></configurations></instances></project>
"""


class Ld:
    """Builds an LD body: every element gets a localId and a drawing position (y orders rungs)."""

    def __init__(self) -> None:
        self.parts: list[str] = []
        self.lid = 100
        self.vars: dict[str, str] = {}

    def _next(self) -> int:
        self.lid += 1
        return self.lid

    @staticmethod
    def _conn(src) -> str:
        lid, formal = src if isinstance(src, tuple) else (src, "")
        attr = f' formalParameter="{formal}"' if formal else ""
        return f'<connectionPointIn><connection refLocalId="{lid}"{attr}/></connectionPointIn>'

    def var(self, name: str, type_: str = "INT") -> None:
        self.vars[name] = type_

    def const(self, expr: str | int) -> int:
        lid = self._next()
        self.parts.append(
            f'<inVariable localId="{lid}"><position x="0" y="0"/>'
            f"<connectionPointOut/><expression>{expr}</expression></inVariable>"
        )
        return lid

    def contact(self, name: str, src=1) -> int:
        lid = self._next()
        self.parts.append(
            f'<contact localId="{lid}"><position x="0" y="0"/>{self._conn(src)}'
            f"<variable>{name}</variable></contact>"
        )
        return lid

    def block(self, type_name: str, y: int, en=None, **inputs) -> int:
        lid = self._next()
        ins = []
        if en is not None:
            ins.append(f'<variable formalParameter="EN">{self._conn(en)}</variable>')
        for formal, src in inputs.items():
            ins.append(f'<variable formalParameter="{formal}">{self._conn(src)}</variable>')
        self.parts.append(
            f'<block localId="{lid}" typeName="{type_name}"><position x="100" y="{y}"/>'
            f"<inputVariables>{''.join(ins)}</inputVariables><inOutVariables/>"
            '<outputVariables><variable formalParameter="ENO"><connectionPointOut/></variable>'
            '<variable formalParameter="OUT"><connectionPointOut/></variable></outputVariables>'
            "</block>"
        )
        return lid

    def out(self, name: str, src, y: int) -> None:
        self.parts.append(
            f'<outVariable localId="{self._next()}"><position x="300" y="{y}"/>'
            f"{self._conn(src)}<expression>{name}</expression></outVariable>"
        )

    def coil(self, name: str, src, y: int) -> None:
        self.parts.append(
            f'<coil localId="{self._next()}"><position x="300" y="{y}"/>'
            f"{self._conn(src)}<variable>{name}</variable></coil>"
        )

    def xml(self) -> str:
        locals_ = "\n".join(
            f'<variable name="{n}"><type><{t}/></type></variable>' for n, t in self.vars.items()
        )
        return HEAD.format(locals=locals_) + "\n".join(self.parts) + TAIL


def standard_functions_program() -> str:
    ld = Ld()
    for name in ("A", "B", "C", "K", "Mv", "Add", "Mul", "Sub", "Div", "Mod", "Sel", "Max"):
        ld.var(name)
    for name in ("Min", "Lim", "Mux", "Chain", "Copy"):
        ld.var(name)
    for name in ("En", "Gt", "Ne", "Le"):
        ld.var(name, "BOOL")
    a, b, c, k = (ld.const(n) for n in "ABCK")
    en = ld.contact("En")
    ld.out("Mv", (ld.block("MOVE", 10, en=en, IN=a), "OUT"), 10)
    ld.coil("Gt", (ld.block("GT", 20, en=1, IN1=a, IN2=b, IN3=c), "OUT"), 20)
    ld.coil("Ne", (ld.block("NE", 30, en=1, IN1=a, IN2=b), "OUT"), 30)
    ld.coil("Le", (ld.block("LE", 35, IN1=c, IN2=b, IN3=a), "OUT"), 35)  # EN not wired: FBD
    ld.out("Add", (ld.block("ADD", 40, en=1, IN1=a, IN2=b, IN3=c), "OUT"), 40)
    ld.out("Mul", (ld.block("MUL", 50, en=1, IN1=a, IN2=b, IN3=c), "OUT"), 50)
    ld.out("Sub", (ld.block("SUB", 60, en=1, IN1=a, IN2=b), "OUT"), 60)
    ld.out("Div", (ld.block("DIV", 70, en=1, IN1=a, IN2=b), "OUT"), 70)
    ld.out("Mod", (ld.block("MOD", 80, en=1, IN1=a, IN2=b), "OUT"), 80)
    ld.out("Sel", (ld.block("SEL", 90, en=1, G=ld.contact("En"), IN0=a, IN1=b), "OUT"), 90)
    ld.out("Max", (ld.block("MAX", 100, en=1, IN1=c, IN2=a, IN3=b), "OUT"), 100)
    ld.out("Min", (ld.block("MIN", 110, en=1, IN1=b, IN2=c, IN3=a), "OUT"), 110)
    two, four = ld.const(2), ld.const(4)
    ld.out("Lim", (ld.block("LIMIT", 120, en=1, MN=two, IN=a, MX=four), "OUT"), 120)
    ld.out("Mux", (ld.block("MUX", 130, en=1, K=k, IN0=a, IN1=b, IN2=c), "OUT"), 130)
    # Chain = ADD(MUL(A, B), C), with the ADD drawn above the MUL it reads: the import runs
    # the MUL first, so the chain holds in the same scan.
    mul_lid = ld.lid + 3  # after the ADD and its outVariable: the MUL below
    ld.out("Chain", (ld.block("ADD", 140, en=1, IN1=(mul_lid, "OUT"), IN2=c), "OUT"), 140)
    assert ld.block("MUL", 150, en=1, IN1=a, IN2=b) == mul_lid
    ld.out("Copy", (ld.block("MOVE", 160, en=1, IN=ld.const("Shared")), "OUT"), 160)
    return ld.xml()


@pytest.fixture
def functions_rt(tmp_path):
    path = tmp_path / "fns.xml"
    path.write_text(standard_functions_program())
    return Runtime(load_file(str(path)))


def run(rt: Runtime, t: int, **inputs) -> None:
    for name, value in inputs.items():
        rt.write_once(name, value)
    rt.scan(t)


@pytest.mark.parametrize(
    "a, b, c, k, expect",
    [
        # A B C K -> hand-computed results (IEC: DIV truncates toward zero, MOD has A's sign)
        (
            5,
            3,
            1,
            2,
            dict(Gt=True, Ne=True, Le=True, Add=9, Mul=15, Sub=2, Div=1, Mod=2, Max=5, Min=1)
            | dict(Lim=4, Mux=1, Chain=16),
        ),
        (
            -7,
            2,
            2,
            0,
            dict(Gt=False, Ne=True, Le=False, Add=-3, Mul=-28, Sub=-9, Div=-3, Mod=-1, Max=2)
            | dict(Min=-7, Lim=2, Mux=-7, Chain=-12),
        ),
        (
            3,
            3,
            3,
            1,
            dict(Gt=False, Ne=False, Le=True, Add=9, Mul=27, Sub=0, Div=1, Mod=0, Max=3, Min=3)
            | dict(Lim=3, Mux=3, Chain=12),
        ),
    ],
)
def test_standard_functions_compute_as_iec(functions_rt, a, b, c, k, expect):
    run(functions_rt, 0, A=a, B=b, C=c, K=k, En=False)
    got = {name: functions_rt.read(name) for name in expect}
    assert got == expect
    assert functions_rt.read("Sel") == a  # G false: IN0


def test_en_gates_a_function_and_sel_follows_g(functions_rt):
    run(functions_rt, 0, A=11, B=22, En=False)
    assert functions_rt.read("Mv") == 0  # MOVE not called: its variable keeps its value
    assert functions_rt.read("Sel") == 11
    run(functions_rt, 10, En=True)
    assert functions_rt.read("Mv") == 11 and functions_rt.read("Sel") == 22
    run(functions_rt, 20, A=5, En=False)
    assert functions_rt.read("Mv") == 11  # kept while EN is off
    assert functions_rt.read("Sel") == 5


def test_mux_with_k_out_of_range_keeps_its_output(functions_rt):
    run(functions_rt, 0, A=1, B=2, C=3, K=1)
    assert functions_rt.read("Mux") == 2
    run(functions_rt, 10, K=7)
    assert functions_rt.read("Mux") == 2


def test_external_variable_is_the_global_with_its_initial_value(functions_rt):
    run(functions_rt, 0)
    assert functions_rt.read("Copy") == 42 and functions_rt.read("Shared") == 42


def test_generated_rungs_read_as_ladder(tmp_path):
    program, sink = import_plcopen(standard_functions_program(), "fns.xml")
    assert not [d for d in sink.items if d.severity == "error"], [str(d) for d in sink.items]
    text = format_program(program)
    lines = text.splitlines()
    # the MUL feeding the chain runs before the ADD that reads it, though drawn below it
    chain = next(t for t in lines if t.startswith("MOV _F") and t.endswith(" Chain")).split()[1]
    chain_add = next(i for i, t in enumerate(lines) if t.startswith("ADD _F") and chain in t)
    product = lines[chain_add].split()[1]
    assert lines.index(f"MUL A B {product}") < chain_add
    assert "XIC En MOV A _F" in text  # MOVE under its EN
    assert "GRT A B GRT B C OTE Gt" in text  # extensible comparison: IN1>IN2 AND IN2>IN3


@pytest.mark.parametrize(
    "inputs, message",
    [
        ({"IN1": "a"}, "input IN2 of SUB is not connected"),
        ({"IN1": "a", "IN2": "coil"}, "input IN2 must come from a variable"),
    ],
)
def test_function_input_errors_name_the_block(tmp_path, inputs, message):
    ld = Ld()
    ld.var("A")
    ld.var("R")
    ld.var("Q", "BOOL")
    refs = {"a": ld.const("A"), "coil": ld.contact("Q")}
    lid = ld.block("SUB", 10, en=1, **{f: refs[v] for f, v in inputs.items()})
    ld.out("R", (lid, "OUT"), 10)
    path = tmp_path / "bad.xml"
    path.write_text(ld.xml())
    diags = check_file(str(path))
    assert any(message in d.message and d.severity == "error" for d in diags), [
        str(d) for d in diags
    ]


# --- the real files ---------------------------------------------------------------------


def corpus(name: str) -> str:
    path = PLCOPEN_CORPUS / name
    if not path.exists():
        pytest.skip(MISSING)
    return str(path)


def errors(path: str) -> list[str]:
    return [f"{d.line}: {d.message}" for d in check_file(path) if d.severity == "error"]


def test_openplc_blink_imports():
    assert errors(corpus("openplc_Blink.xml")) == []


def test_openplc_7_segments_external_counter_counts_to_ten_and_restarts():
    path = corpus("openplc_Arduino_7_Segments.xml")
    assert errors(path) == []
    rt = Runtime(load_file(path))
    seen = []
    for t in range(0, 10000, 10):  # square wave: 200 ms on, 200 ms off
        rt.scan(t)
        seen.append(rt.read("current_count"))
    # CTU counts rising edges of the 400 ms square wave and resets itself at PV=10
    # IEC CTU: one count per 400 ms period; at PV=10 Q resets it through R (priority over
    # CU) to 0, and the next rising edge of CU counts 1
    values = [k for k, _ in itertools.groupby(seen)]
    assert values == [0, *range(1, 11), *range(0, 11), *range(0, len(values) - 22)]


def test_openplc_serial_print_is_refused_for_its_string_not_its_externals():
    path = corpus("openplc_Arduino_Serial_Print.xml")
    found = errors(path)
    assert any("374:" in e and "needs a STRING" in e for e in found), found
    assert any("381:" in e and "'SerialMSG' is a STRING variable" in e for e in found), found
    assert not any("PrintMSG" in e for e in found), found  # a BOOL external: declared
    assert not any("MOVE" in e for e in found), found


def test_openplc_p1am_is_refused_for_its_vendor_blocks_only():
    found = errors(corpus("openplc_Blink_P1AM.xml"))
    assert any("187:" in e and "unsupported block 'P1AM_INIT'" in e for e in found), found
    assert any("261:" in e and "unsupported block 'P1_16CDR'" in e for e in found), found
    assert not any("'GT'" in e for e in found), found


def test_beremiz_first_steps_names_the_languages_and_its_ld_block_runs():
    path = corpus("beremiz_first_steps.xml")
    (only,) = errors(path)
    assert "program 'plc_prg': FBD" in only and "functionBlock 'CounterLD': LD" in only
    program, sink = import_plcopen(path, pou="CounterLD")
    assert not sink.items, [str(d) for d in sink.items]
    rungs = format_program(program).splitlines()
    # Cnt := SEL(Reset, ADD(1, Cnt), ResetCounterValue); Out := Cnt: in data-flow order, the
    # ADD reading the last scan's Cnt (the feedback variable)
    order = [
        next(i for i, r in enumerate(rungs) if r.startswith(p))
        for p in ("ADD 1 Cnt", "XIC Reset MOV ResetCounterValue", "MOV _F7 Cnt", "MOV Cnt Out")
    ]
    assert order == sorted(order)
    rt = Runtime(compile_program(program))
    for t in range(3):
        rt.scan(t * 100)
    assert rt.read("Out") == 3 and rt.read("Cnt") == 3
    run(rt, 300, Reset=True)
    assert rt.read("Out") == 17  # the global constant ResetCounterValue
    run(rt, 400, Reset=False)
    assert rt.read("Out") == 18

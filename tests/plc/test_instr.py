"""Every instruction, table-driven in lockstep: set inputs, scan at a virtual time, check.

Each case is (tags, rungs, steps); a step is (now_ms, values written once before the scan,
values expected after it). Timers use exact ms edges: a timer that starts timing at t
reaches its preset at exactly t + PRE.
"""

from __future__ import annotations

import pytest

from plc.ladder import compile_text
from plc.runtime import ALARM_DIV_ZERO, Runtime

TAGS = """
TAG A : BOOL AT %IX0.0
TAG B : BOOL AT %IX0.1
TAG C : BOOL AT %IX0.2
TAG Q : BOOL AT %QX0.0
TAG Q2 : BOOL AT %QX0.1
TAG M : BOOL
TAG S : BOOL
TAG X : INT AT %IW0
TAG Y : INT AT %IW1
TAG Z : INT AT %IW2
TAG R : INT AT %QW0
TAG T : TIMER
TAG K : COUNTER
"""


def run_steps(rungs: str, steps, tags: str = TAGS) -> Runtime:
    rt = Runtime(compile_text(tags + rungs, "case.ld"))
    for i, (now, writes, expect) in enumerate(steps):
        for name, value in writes.items():
            rt.write_once(name, value)
        rt.scan(now)
        got = {name: rt.read(name) for name in expect}
        assert got == expect, f"step {i} at t={now}: {got} != {expect}"
    return rt


def ticks(start: int, stop: int, step: int = 10):
    return range(start, stop + 1, step)


BIT_CASES = {
    "XIC": ("XIC A OTE Q", [(0, {"A": 1}, {"Q": True}), (10, {"A": 0}, {"Q": False})]),
    "XIO": ("XIO A OTE Q", [(0, {"A": 1}, {"Q": False}), (10, {"A": 0}, {"Q": True})]),
    "OTE series": (
        "XIC A XIO B OTE Q",
        [
            (0, {"A": 1, "B": 0}, {"Q": True}),
            (10, {"B": 1}, {"Q": False}),
            (20, {"A": 0, "B": 0}, {"Q": False}),
        ],
    ),
    "OTL/OTU": (
        "XIC A OTL Q\nXIC B OTU Q",
        [
            (0, {"A": 1}, {"Q": True}),
            (10, {"A": 0}, {"Q": True}),
            (20, {"B": 1}, {"Q": False}),
            (30, {"B": 0}, {"Q": False}),
        ],
    ),
    "OTN": ("XIC A OTN Q", [(0, {"A": 1}, {"Q": False}), (10, {"A": 0}, {"Q": True})]),
    "branch OR": (
        "BST XIC A NXB XIC B BND OTE Q",
        [(0, {}, {"Q": False}), (10, {"A": 1}, {"Q": True}), (20, {"A": 0, "B": 1}, {"Q": True})],
    ),
    "nested branch": (
        "XIC A BST XIC B NXB BST XIC C NXB XIC M BND BND OTE Q",
        [(0, {"A": 1}, {"Q": False}), (10, {"C": 1}, {"Q": True}), (20, {"A": 0}, {"Q": False})],
    ),
    "outputs inside legs": (
        "XIC A BST OTE Q NXB XIO B OTE Q2 BND",
        [(0, {"A": 1}, {"Q": True, "Q2": True}), (10, {"B": 1}, {"Q": True, "Q2": False})],
    ),
    "seal-in": (
        "BST XIC A NXB XIC Q BND XIO B OTE Q",
        [
            (0, {"A": 1}, {"Q": True}),
            (10, {"A": 0}, {"Q": True}),
            (20, {"B": 1}, {"Q": False}),
            (30, {"B": 0}, {"Q": False}),
        ],
    ),
    "power read before an output changes it": (
        "XIC M OTU M OTE Q",
        [(0, {"M": 1}, {"M": False, "Q": True}), (10, {}, {"Q": False})],
    ),
    "ONS": (
        "XIC A ONS S OTE Q",
        [
            (0, {"A": 1}, {"Q": True}),
            (10, {}, {"Q": False}),
            (20, {"A": 0}, {"Q": False}),
            (30, {"A": 1}, {"Q": True}),
        ],
    ),
    "OSR": (
        "XIC A OSR S Q",
        [
            (0, {"A": 1}, {"Q": True}),
            (10, {}, {"Q": False}),
            (20, {"A": 0}, {"Q": False}),
            (30, {"A": 1}, {"Q": True}),
        ],
    ),
    "OSF": (
        "XIC A OSF S Q",
        [(0, {"A": 1}, {"Q": False}), (10, {"A": 0}, {"Q": True}), (20, {}, {"Q": False})],
    ),
}


@pytest.mark.parametrize("name", list(BIT_CASES))
def test_bit_instructions(name):
    rungs, steps = BIT_CASES[name]
    run_steps(rungs, steps)


def test_ton_exact_edges():
    steps = [(0, {"A": 1}, {"T.DN": False, "T.TT": True, "T.EN": True, "T.ACC": 0, "T.PRE": 100})]
    steps += [(t, {}, {"T.DN": False, "T.ACC": t}) for t in ticks(10, 90)]
    steps += [(100, {}, {"T.DN": True, "T.TT": False, "T.ACC": 100, "Q": True})]
    steps += [(110, {}, {"T.DN": True, "T.ACC": 100})]
    steps += [(120, {"A": 0}, {"T.DN": False, "T.EN": False, "T.ACC": 0, "Q": False})]
    run_steps("XIC A TON T 100\nXIC T.DN OTE Q", steps)


def test_ton_uneven_scans_and_time_literal():
    steps = [
        (1000, {"A": 1}, {"T.ACC": 0}),
        (1030, {}, {"T.ACC": 30}),
        (1249, {}, {"T.DN": False}),
        (1250, {}, {"T.DN": True, "T.ACC": 250}),
        (1999, {}, {"T.ACC": 250}),
    ]
    run_steps("XIC A TON T T#250ms", steps)


def test_ton_zero_preset_is_done_at_once():
    run_steps("XIC A TON T 0", [(0, {"A": 1}, {"T.DN": True}), (10, {"A": 0}, {"T.DN": False})])


def test_ton_preset_from_a_word():
    run_steps(
        "XIC A TON T X",
        [
            (0, {"A": 1, "X": 30}, {"T.PRE": 30}),
            (20, {}, {"T.DN": False}),
            (30, {}, {"T.DN": True}),
        ],
    )


def test_tof_exact_edges():
    steps = [
        (0, {}, {"T.DN": False, "T.TT": False}),
        (10, {"A": 1}, {"T.DN": True, "T.EN": True}),
        (50, {"A": 0}, {"T.DN": True, "T.TT": True, "T.ACC": 0}),
    ]
    steps += [(t, {}, {"T.DN": True, "T.ACC": t - 50}) for t in ticks(60, 140)]
    steps += [
        (150, {}, {"T.DN": False, "T.TT": False, "T.ACC": 100}),
        (160, {"A": 1}, {"T.DN": True, "T.ACC": 0}),
        (170, {"A": 0}, {"T.TT": True}),
        (200, {"A": 1}, {"T.DN": True, "T.TT": False}),
    ]
    run_steps("XIC A TOF T 100", steps)


def test_rto_keeps_time_and_res_clears():
    steps = [
        (0, {"A": 1}, {"T.ACC": 0}),
        (50, {}, {"T.ACC": 50}),
        (60, {"A": 0}, {"T.ACC": 50, "T.DN": False, "T.EN": False}),
        (500, {"A": 1}, {"T.ACC": 50}),
        (510, {}, {"T.ACC": 60}),
        (550, {}, {"T.ACC": 100, "T.DN": True}),
        (560, {"A": 0}, {"T.DN": True}),
        (570, {"B": 1}, {"T.ACC": 0, "T.DN": False}),
    ]
    run_steps("XIC A RTO T 100\nXIC B RES T", steps)


def test_ctu_ctd_res():
    steps = [
        (0, {"A": 1}, {"K.ACC": 1, "K.CU": True}),
        (10, {}, {"K.ACC": 1}),
        (20, {"A": 0}, {"K.ACC": 1, "K.CU": False}),
        (30, {"A": 1}, {"K.ACC": 2}),
        (40, {"A": 0}, {}),
        (50, {"A": 1}, {"K.ACC": 3, "K.DN": True, "K.Q": True}),
        (60, {"B": 1}, {"K.ACC": 2, "K.DN": False, "K.CD": True}),
        (70, {"B": 0, "C": 1}, {"K.ACC": 0, "K.DN": False, "K.CU": False}),
    ]
    # after RES the CU bit is clear, so a still-true CTU rung counts again (Rockwell rule)
    steps += [(80, {"C": 0}, {"K.ACC": 1})]
    run_steps("XIC A CTU K 3\nXIC B CTD K 3\nXIC C RES K", steps)


def test_ctu_overflow_and_ctd_underflow_wrap_with_flags():
    rt = run_steps("XIC A CTU K 5\nXIC B CTD K 5", [(0, {"K.ACC": 32767}, {})])
    rt.write_once("A", 1)
    rt.scan(10)
    assert rt.read("K.ACC") == -32768 and rt.read("K.OV") is True
    rt = run_steps("XIC A CTU K 5\nXIC B CTD K 5", [(0, {"K.ACC": -32768}, {})])
    rt.write_once("B", 1)
    rt.scan(10)
    assert rt.read("K.ACC") == 32767 and rt.read("K.UN") is True


COMPARE = [
    ("EQU", 3, 3, True),
    ("EQU", 3, 4, False),
    ("NEQ", 3, 4, True),
    ("NEQ", -1, -1, False),
    ("LES", -5, 2, True),
    ("LES", 2, 2, False),
    ("LEQ", 2, 2, True),
    ("LEQ", 3, 2, False),
    ("GRT", 3, 2, True),
    ("GRT", 2, 2, False),
    ("GEQ", 2, 2, True),
    ("GEQ", -3, 2, False),
]


@pytest.mark.parametrize("mnemonic, x, y, result", COMPARE)
def test_compare(mnemonic, x, y, result):
    run_steps(f"{mnemonic} X Y OTE Q", [(0, {"X": x, "Y": y}, {"Q": result})])


@pytest.mark.parametrize(
    "low, test, high, result",
    [
        (0, 5, 10, True),
        (0, 0, 10, True),
        (0, 10, 10, True),
        (0, 11, 10, False),
        (0, -1, 10, False),
        # low > high: true outside the open range (high, low)
        (10, 5, 0, False),
        (10, 10, 0, True),
        (10, 0, 0, True),
        (10, 11, 0, True),
        (10, -7, 0, True),
    ],
)
def test_lim_with_words_and_literals(low, test, high, result):
    run_steps("LIM X Y Z OTE Q", [(0, {"X": low, "Y": test, "Z": high}, {"Q": result})])
    run_steps(f"LIM {low} Y {high} OTE Q", [(0, {"Y": test}, {"Q": result})])


MATH = [
    ("ADD", 2, 3, 5, False),
    ("ADD", 32767, 1, -32768, True),
    ("SUB", 2, 5, -3, False),
    ("SUB", -32768, 1, 32767, True),
    ("MUL", -4, 6, -24, False),
    ("MUL", 300, 300, 24464, True),
    ("DIV", 7, 2, 3, False),
    ("DIV", -7, 2, -3, False),
    ("DIV", 7, -2, -3, False),
    ("DIV", -32768, -1, -32768, True),
    ("MOD", 7, 3, 1, False),
    ("MOD", -7, 3, -1, False),
    ("MOD", 7, -3, 1, False),
]


@pytest.mark.parametrize("mnemonic, a, b, result, overflow", MATH)
def test_math_int_semantics(mnemonic, a, b, result, overflow):
    run_steps(
        f"XIC A {mnemonic} X Y R",
        [(0, {"X": a, "Y": b}, {"R": 0}), (10, {"A": 1}, {"R": result, "S_OVERFLOW": overflow})],
    )


@pytest.mark.parametrize("mnemonic", ["DIV", "MOD"])
def test_division_by_zero_leaves_dest_sets_flag_and_alarm(mnemonic):
    rt = run_steps(
        f"XIC A MOV 9 R\nXIC B {mnemonic} X Y R\nXIC S_DIV_ZERO OTE Q",
        [
            (0, {"A": 1}, {"R": 9}),
            (
                10,
                {"A": 0, "B": 1, "X": 5, "Y": 0},
                {"R": 9, "S_DIV_ZERO": True, "S_FAULT_RUNG": 1, "Q": True},
            ),
        ],
    )
    assert ALARM_DIV_ZERO in rt.alarms and str(rt.mode) == "RUN"
    rt.write_once("Y", 2)
    rt.scan(20)
    assert rt.read("S_DIV_ZERO") is False and rt.read("R") == (2 if mnemonic == "DIV" else 1)


def test_mov_and_timer_acc_to_word():
    run_steps(
        "XIC A MOV -12 R\nXIC B TON T 50\nXIC B MOV T.ACC %MW3",
        [(0, {"A": 1}, {"R": -12}), (10, {"B": 1}, {}), (40, {}, {"%MW3": 30})],
    )


def test_jmp_skips_rungs_and_their_timers():
    rungs = "XIC A JMP over\nXIC B OTE Q\nXIC B TON T 100\nLBL over XIC B OTE Q2"
    steps = [
        (0, {"B": 1}, {"Q": True, "Q2": True, "T.EN": True}),
        # skipped rungs keep their outputs and their timers do not run
        (10, {"A": 1, "B": 0}, {"Q": True, "Q2": False, "T.EN": True, "T.ACC": 0}),
        (50, {"B": 1}, {"Q": True, "T.ACC": 0}),
        (55, {"B": 0}, {}),
        (60, {"A": 0}, {"Q": False, "T.EN": False}),
    ]
    run_steps(rungs, steps)


def test_overlapping_jumps():
    rungs = "XIC A JMP l1\nXIC B JMP l2\nXIC C OTE Q\nLBL l1 XIC C OTE Q2\nLBL l2 XIC C OTE %QX0.2"
    rt = run_steps(rungs, [(0, {"C": 1}, {"Q": True, "Q2": True, "%QX0.2": True})])
    rt.write_once("A", 1)
    rt.write_once("C", 0)
    rt.scan(10)
    assert rt.read("Q") is True and rt.read("Q2") is False  # rung 2 skipped by l1
    rt.write_once("A", 0)
    rt.write_once("B", 1)
    rt.write_once("C", 1)
    rt.scan(20)
    assert rt.read("Q") is True and rt.read("Q2") is False  # rungs 2 and 3 skipped by l2
    assert rt.read("%QX0.2") is True


def test_first_scan_flag():
    rt = run_steps(
        "XIC S_FIRST_SCAN OTL M",
        [
            (0, {}, {"M": True, "S_FIRST_SCAN": True}),
            (10, {"M": 0}, {"M": False, "S_FIRST_SCAN": False}),
        ],
    )
    rt.stop()
    rt.run()
    rt.scan(20)
    assert rt.read("M") is True


def test_iec_addresses_without_tags():
    text = "XIC %IX1.7 BST OTE %QX2.0 NXB MOV %IW3 %MW4 BND\nXIC %MX0.1 OTE %MX0.2\n"
    rt = Runtime(compile_text(text, "a.ld"))
    rt.image.ix[15] = True
    rt.image.iw[3] = -77
    rt.image.mx[1] = True
    rt.scan(0)
    assert rt.snapshot.qx[16] == 1 and rt.snapshot.mw[4] == -77 and rt.snapshot.mx[2] == 1


def test_initial_values_and_internal_int():
    text = "TAG N : INT := 40\nTAG On : BOOL := 1\nXIC On ADD N 2 N\n"
    rt = Runtime(compile_text(text, "i.ld"))
    rt.scan(0)
    assert rt.read("N") == 42

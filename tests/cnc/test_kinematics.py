"""Kinematics: Cartesian mill, lathe and the 5-axis B45/C seam (002_postprocessor.md)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cnc.errors import NcError
from cnc.kinematics import (
    CartesianMill,
    Kinematics,
    Lathe,
    TableTableBC45,
    bc45_forward,
    bc45_inverse,
    bc45_rotary,
    kinematics_for,
    register_kinematics,
)
from cnc.params import AxisParams, MachineParams

coord = st.floats(-2000, 2000, allow_nan=False, allow_infinity=False)


@given(x=coord, y=coord, z=coord)
def test_mill_round_trip(x, y, z):
    kin = CartesianMill()
    assert kin.to_joints((x, y, z)) == (x, y, z)
    assert kin.to_pose(kin.to_joints((x, y, z))) == (x, y, z)


@given(x=coord, z=coord)
def test_lathe_round_trip_holds_y_at_zero(x, z):
    kin = Lathe()
    assert kin.to_joints((x, 0.0, z)) == (x, z)
    assert kin.to_pose(kin.to_joints((x, 0.0, z))) == (x, 0.0, z)


def test_axis_names():
    assert CartesianMill().axis_names == ("X", "Y", "Z")
    assert Lathe().axis_names == ("X", "Z")
    assert TableTableBC45().axis_names == ("X", "Y", "Z", "B", "C")
    for kin in (CartesianMill(), Lathe(), TableTableBC45()):
        assert isinstance(kin, Kinematics)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: Lathe().to_joints((10.0, 0.5, -3.0)), "lathe has no Y axis: Y must be 0, got 0.5"),
        (lambda: Lathe().to_joints((10.0, -3.0)), "lathe pose needs 3 values"),
        (lambda: Lathe().to_pose((1.0, 2.0, 3.0)), "lathe joints needs 2 values"),
        (lambda: CartesianMill().to_joints((1.0, 2.0)), "mill pose needs 3 values"),
        (lambda: CartesianMill().to_pose((1.0, 2.0, 3.0, 4.0)), "mill joints needs 3 values"),
        (lambda: TableTableBC45().to_joints((1.0, 2.0, 3.0)), "B45/C pose needs 6 values"),
        (lambda: TableTableBC45().to_pose((1.0, 2.0, 3.0)), "B45/C joints needs 5 values"),
    ],
)
def test_wrong_shapes_are_refused(call, message):
    with pytest.raises(NcError, match=message):
        call()


# --- selection by machine kind ----------------------------------------------------------


def _axes(*names):
    return tuple(AxisParams(n, -100.0, 0.0, 10000.0, 1000.0, 10000.0) for n in names)


def test_kinematics_for_kinds():
    assert isinstance(kinematics_for(MachineParams()), CartesianMill)
    assert isinstance(kinematics_for(MachineParams(kind="lathe", axes=_axes("X", "Z"))), Lathe)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        (MachineParams(kind="lathe"), "machine kind 'lathe' has axes X Z, configured X Y Z"),
        (MachineParams(kind="mill", axes=_axes("X", "Z")), "has axes X Y Z, configured X Z"),
        (MachineParams(kind="router", axes=_axes("X")), "no kinematics for machine kind 'router'"),
    ],
)
def test_kinematics_for_refuses_mismatches(params, message):
    with pytest.raises(NcError, match=message):
        kinematics_for(params)


def test_register_kinematics_adds_a_kind():
    register_kinematics("bc45_test", lambda p: TableTableBC45(d=12.5))
    kin = kinematics_for(MachineParams(kind="bc45_test", axes=_axes("X", "Y", "Z", "B", "C")))
    assert kin == TableTableBC45(d=12.5)


# --- B45/C inverse kinematics: 002 test vectors -----------------------------------------

ROTARY_VECTORS = [
    ((-0.70710678, -0.5, 0.5), 90.0, 0.0),
    ((0.0, -1.0, 0.0), 180.0, 0.0),
    ((1.0, 0.0, 0.0), 180.0, -90.0),
    ((0.0, 1.0, 0.0), 180.0, 180.0),
    ((-1.0, 0.0, 0.0), 180.0, 90.0),
    ((0.6327447124, 0.465569252, 0.6187742456), 76.2582, 172.6859),  # Table 1 P1
    ((0.628284235, 0.461387437, 0.62640867), 75.3560, 172.3460),  # P2
    ((0.623829809, 0.457180279, 0.634039219), 74.4570, 172.0119),  # P3, |v| = 1.00009
    ((0.618938519, 0.452948814, 0.6416794216), 73.5392, 171.6547),  # P4
]


@pytest.mark.parametrize(("v", "b", "c"), ROTARY_VECTORS)
def test_bc45_rotary_vectors(v, b, c):
    got_b, got_c, singular = bc45_rotary(v)
    assert got_b == pytest.approx(b, abs=1e-4)
    assert got_c == pytest.approx(c, abs=1e-4)
    assert not singular


@pytest.mark.parametrize(
    ("d", "expected"),
    [(0.0, (35.3553, -12.0711, -2.0711)), (100.0, (106.0660, -62.0711, -52.0711))],
)
def test_bc45_linear_axes_vector(d, expected):
    j = bc45_inverse((10.0, 20.0, 30.0), (-0.70710678, -0.5, 0.5), d)
    assert (j.x, j.y, j.z) == pytest.approx(expected, abs=1e-4)
    assert (j.b, j.c) == pytest.approx((90.0, 0.0), abs=1e-6)


TABLE_1_XYZ = [
    ((20, 0, -155), (0.6327447124, 0.465569252, 0.6187742456), (-109.428, 74.291, -83.255)),
    ((100, 0, -150), (0.628284235, 0.461387437, 0.62640867), (-118.564, 132.186, -31.133)),
    ((200, 0, -146), (0.623829809, 0.457180279, 0.634039219), (-133.600, 205.987, 32.193)),
    ((300, 0, -139), (0.618938519, 0.452948814, 0.6416794216), (-148.840, 279.030, 96.488)),
]


@pytest.mark.parametrize(("tip", "v", "xyz"), TABLE_1_XYZ)
def test_bc45_table_1_machine_coordinates(tip, v, xyz):
    j = bc45_inverse(tip, v, 0.0)
    assert (j.x, j.y, j.z) == pytest.approx(xyz, abs=1e-3)


def test_bc45_tool_length_and_frame_offset_shift_z_only():
    base = bc45_inverse((10.0, 20.0, 30.0), (-0.70710678, -0.5, 0.5), 100.0)
    shifted = bc45_inverse(
        (10.0, 20.0, 30.0), (-0.70710678, -0.5, 0.5), 100.0, tool_length=80.0, z_offset=15.0
    )
    assert (shifted.x, shifted.y) == (base.x, base.y)
    assert shifted.z == pytest.approx(base.z - 15.0 + 80.0)


def test_bc45_singular_keeps_previous_c_and_is_a_pure_c_rotation():
    j = bc45_inverse((10.0, 20.0, 30.0), (0.0, 0.0, 1.0), 50.0, previous_c=30.0)
    assert j.singular
    assert (j.b, j.c) == (0.0, 30.0)
    c = math.radians(30.0)
    assert j.x == pytest.approx(10.0 * math.cos(c) - 20.0 * math.sin(c))
    assert j.y == pytest.approx(10.0 * math.sin(c) + 20.0 * math.cos(c))
    assert j.z == pytest.approx(30.0)
    assert bc45_rotary((0.0, 0.0, 1.0)) == (0.0, 0.0, True)  # program start: C = 0


def test_bc45_unwraps_c_to_the_previous_turn():
    _, c, _ = bc45_rotary((0.0, 1.0, 0.0), previous_c=-170.0)
    assert c == pytest.approx(-180.0)
    _, c, _ = bc45_rotary((1.0, 0.0, 0.0), previous_c=700.0)
    assert c == pytest.approx(630.0)


@pytest.mark.parametrize(
    ("v", "message"),
    [
        ((0.0, 0.0, -1.0), "unreachable"),
        ((0.6, 0.0, -0.8), "unreachable"),
        ((0.0, 0.0, 0.0), "not a unit vector"),
        ((0.5, 0.5, 0.5), "not a unit vector"),
        ((1.0, 0.0), "3 direction cosines"),
        ((math.nan, 0.0, 1.0), "not a unit vector"),
    ],
)
def test_bc45_bad_orientations(v, message):
    with pytest.raises(NcError, match=message):
        bc45_rotary(v)


unit_reachable = st.tuples(
    st.floats(0.01, 0.99), st.floats(-math.pi, math.pi)
).map(lambda kc: (math.sqrt(1 - kc[0] ** 2) * math.cos(kc[1]),
                  math.sqrt(1 - kc[0] ** 2) * math.sin(kc[1]), kc[0]))  # fmt: skip


@settings(max_examples=200)
@given(
    tip=st.tuples(coord, coord, coord),
    v=unit_reachable,
    d=st.floats(0, 500),
    tool=st.floats(0, 300),
    zo=st.floats(-200, 200),
)
def test_bc45_forward_of_inverse_is_identity(tip, v, d, tool, zo):
    kin = TableTableBC45(d=d, tool_length=tool, z_offset=zo)
    pose = (*tip, *v)
    back = kin.to_pose(kin.to_joints(pose))
    assert back == pytest.approx(pose, abs=1e-9 * (1 + max(abs(t) for t in tip) + d + tool))


@settings(max_examples=100)
@given(
    xyz=st.tuples(coord, coord, coord),
    b=st.floats(1.0, 179.0),
    c=st.floats(-179.0, 179.0),
    d=st.floats(0, 500),
)
def test_bc45_inverse_of_forward_recovers_joints(xyz, b, c, d):
    tip, axis = bc45_forward((*xyz, b, c), d)
    j = bc45_inverse(tip, axis, d)
    assert (j.x, j.y, j.z) == pytest.approx(xyz, abs=1e-8 * (1 + max(map(abs, xyz)) + d))
    assert j.b == pytest.approx(b, abs=1e-6)
    assert j.c == pytest.approx(c, abs=1e-6)


def test_bc45_previous_joints_feed_the_unwrap():
    kin = TableTableBC45()
    joints = kin.to_joints((0.0, 0.0, 0.0, 0.0, 1.0, 0.0), previous=(0, 0, 0, 180.0, -170.0))
    assert joints[4] == pytest.approx(-180.0)

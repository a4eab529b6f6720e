"""Drive402: the CiA 402 device profile application of one virtual servo axis.

It implements `drives.application.DriveApplication`: the CiA 301 slave forwards every access
to 0x6000-0x67FF here, calls `on_sync()` at each SYNC (after synchronous RPDOs were written)
and `advance(dt)` to integrate the plant. Time moves only through `advance`; nothing here
reads a clock, sleeps or does I/O.

Timing contract (lockstep): RPDO writes → `on_sync()` → TPDOs sampled → `advance(T)`. A
controlword takes effect in `write_object`, so the new state is visible in the TPDO of the
SYNC that applied it; stops that need standstill (quick stop ramp, fault reaction, 0x605B/C
ramps) complete inside a later `advance`.
"""

from __future__ import annotations

import math
import struct
from dataclasses import replace
from typing import Final

from drives.application import (
    ABORT_DEVICE_STATE,
    ABORT_NOT_EXIST,
    ABORT_READ_ONLY,
    ABORT_SUBINDEX,
    ABORT_VALUE_HIGH,
    ABORT_VALUE_LOW,
    ABORT_VALUE_RANGE,
    EmcyRequest,
    ObjectAccessError,
)
from drives.cia402 import faults as F
from drives.cia402 import homing as HM
from drives.cia402.objects import NEEDS_POWER_OFF, OBJECTS, TYPE_RANGE, TYPE_SIZE, Entry
from drives.cia402.profile import Demand, ramp_velocity, stop_step, trapezoid_step
from drives.cia402.statemachine import (
    CW_CHANGE_SET_IMMEDIATELY,
    CW_HALT,
    CW_NEW_SET_POINT,
    CW_RELATIVE,
    STATE_BITS,
    STATE_NAMES,
    SW_INTERNAL_LIMIT,
    SW_OMS12,
    SW_OMS13,
    SW_REMOTE,
    SW_TARGET_REACHED,
    SW_VOLTAGE_ENABLED,
    SW_WARNING,
    Conditions,
    Options,
    PowerState,
    State,
    Stop,
)
from drives.cia402.statemachine import step as sm_step
from drives.fault_registry import DRIVE_FAULTS, FaultKind
from drives.plant import OFF, POSITION, VELOCITY, Plant, PlantParams
from drives.plant.plant import FOLLOWING_ERROR

PP, PV, HOMING, CSP, CSV = 1, 3, 6, 8, 9
# the power states read every SYNC and sub-step, as constants (compiled: C statics, not a
# class attribute lookup on the enum each time)
_OPERATION_ENABLED: Final = State.OPERATION_ENABLED
_QUICK_STOP_ACTIVE: Final = State.QUICK_STOP_ACTIVE
_NOT_READY_TO_SWITCH_ON: Final = State.NOT_READY_TO_SWITCH_ON
# not Final: mypyc can leave a Final tuple constant unset (as cnc/planner/geometry.py notes)
_ENERGIZED = (_OPERATION_ENABLED, _QUICK_STOP_ACTIVE, State.FAULT_REACTION_ACTIVE)
# the drive's own hardware monitors (`_monitor_device`)
DEVICE_TAU_S: Final = 5.0  # heat-sink sensor lag behind the cabinet air
DEVICE_WARNING_C: Final = 75.0  # statusword bit 7; a 0x4210 fault resets below it
DEVICE_TRIP_C: Final = 85.0  # -> 0x4210 excess temperature device
CHOPPER_CHECK_S: Final = 0.1  # brake check period: an open chopper faults 0x7111 within it
_STRUCT: Final = {
    ("i8", 1): "<b",
    ("u8", 1): "<B",
    ("i16", 2): "<h",
    ("u16", 2): "<H",
    ("i32", 4): "<i",
    ("u32", 4): "<I",
}


_KEYS: Final = frozenset((index, sub) for index, subs in OBJECTS.items() for sub in subs)


def _plain_write_limits() -> dict[tuple[int, int], tuple[int, int, frozenset[int] | None]]:
    """(lo, hi, allowed) of the writable objects whose write needs no special handling."""
    out = {}
    for index, subs in OBJECTS.items():
        if index in NEEDS_POWER_OFF or index in (0x6080, 0x6092):
            continue
        for sub, entry in subs.items():
            if entry.writable:
                lo, hi = TYPE_RANGE[entry.dtype]
                if entry.low is not None:
                    lo = max(lo, entry.low)
                if entry.high is not None:
                    hi = min(hi, entry.high)
                out[(index, sub)] = (lo, hi, entry.allowed)
    return out


_PLAIN_WRITES: Final = _plain_write_limits()


class Drive402:
    """A virtual CiA 402 servo drive (profile application + physical plant).

    Parameters
    ----------
    params:
        Plant parameters (`drives.plant.PlantParams`); defaults describe a 400 W servo on a
        10 mm lead ball screw.
    objects:
        Initial values for writable 402 objects, `{index: value}` or `{(index, sub): value}`
        (e.g. `{0x6060: 8, 0x6065: 5000}`); validated like an SDO write.
    """

    def __init__(
        self,
        params: PlantParams | None = None,
        objects: dict[int | tuple[int, int], int] | None = None,
    ) -> None:
        self.params = params or PlantParams()
        self.plant = Plant(self.params)
        # parameters read every cycle, as plain floats (the parameter set is immutable)
        p = self.params
        self._max_substep = p.loops.substep
        self._rated_current = p.motor.rated_current
        self._voltage_present = p.dc_link.voltage_present
        self._warning_temp = p.thermal.warning
        self._i2t_warning_fraction = p.thermal.i2t_warning_fraction
        self._initial_objects = dict(objects or {})
        self._emcy: list[EmcyRequest] = []
        self.nmt_state = "PRE-OPERATIONAL"
        self.time = 0.0
        self._reset_application()

    # ------------------------------------------------------------------ lifecycle
    def _reset_application(self) -> None:
        self._od: dict[tuple[int, int], int] = {
            (i, s): e.default for i, subs in OBJECTS.items() for s, e in subs.items()
        }
        enc = self.params.encoder
        gear = self.params.screw.gear_ratio
        self._od[(0x608F, 1)] = enc.counts_per_rev
        self._od[(0x6091, 1)] = round(gear * 1000)
        self._od[(0x6091, 2)] = 1000
        m = self.params.motor
        self._od[(0x6075, 0)] = round(m.rated_current * 1000)
        self._od[(0x6076, 0)] = round(m.rated_torque * 1000)
        self._od[(0x6080, 0)] = round(m.max_speed_rpm)
        self._update_factor()
        for key, value in self._initial_objects.items():
            index, sub = key if isinstance(key, tuple) else (key, 0)
            self._store(index, sub, value)
        self._update_factor()
        self.plant.speed_limit = self._od[(0x6080, 0)] * 2.0 * math.pi / 60.0
        self._set_power(PowerState())
        self._mode = self._od[(0x6060, 0)]
        self._dem = Demand(self.plant.theta_meas, 0.0)
        self._zero = 0.0  # measured angle (rad) of user position 0
        self.homed = False
        self._fault_code = 0
        self._fault_emcy_sent = False
        self._fe_timer = 0.0
        self._fe_latched = False
        self._split_dt, self._split = -1.0, (1, 0.0)  # advance(): last tick, its sub-steps
        #: False runs every CSP sub-step through the generic `_substep` (the reference the
        #: fast path is tested against; a compiled class cannot be monkeypatched)
        self.csp_fast_path = True
        self._limit_active = False
        self._inputs = self.plant.switch_inputs()
        self._last_sync: float | None = None
        self._seg_to = self._seg_v = self._seg_t = 0.0
        self._seg_T = 0.0
        self._csv_vel = 0.0
        self._pp_target = self._dem.pos
        self._pp_target_user = 0
        self._pp_moving = False
        self._pp_next: float | None = None
        self._pp_ack = False
        self._window_timer = 0.0
        self._hm: HM.HomingRun | None = None
        self._hm_status = HM.HomingStatus.NOT_STARTED
        self._halt_stopped = False
        self.device_temp = self.plant.ambient  # heat-sink sensor, degC
        self._chopper_open_s = 0.0  # time since the brake check found the chopper open

    def power_on_reset(self) -> None:
        """NMT reset node / power cycle: objects back to defaults, incremental position lost."""
        self.plant.power_on_reset()
        self._reset_application()

    # ------------------------------------------------------------------ unit scaling
    @property
    def rad_per_unit(self) -> float:
        """Motor radians per position user unit (factor group 0x6091/0x6092)."""
        return self._rpu

    def _update_factor(self) -> None:
        feed = self._od[(0x6092, 1)]
        revs = self._od[(0x6092, 2)]
        self._rpu = 2.0 * math.pi * self.params.screw.gear_ratio * revs / feed

    def _to_user(self, rad: float) -> int:
        return round((rad - self._zero) / self.rad_per_unit)

    def _from_user(self, units: float) -> float:
        return self._zero + units * self.rad_per_unit

    # ------------------------------------------------------------------ DriveApplication
    def owns(self, index: int) -> bool:
        return index in OBJECTS

    def object_reader(self, index: int, subindex: int):
        """A direct zero-argument reader for the objects TPDOs sample every cycle, else None
        (the PDO service then goes through `read_object`). Same values as `read_object`."""
        if subindex == 0:
            if index == 0x6041:
                return self._statusword
            if index == 0x6064:
                return self._position_actual_value
        return None

    def _position_actual_value(self) -> int:
        # `_i32(self._to_user(p.theta_meas))` inlined: every TPDO1 carries it
        p = self.plant
        v = round((p.counts * p._rad_per_count - self._zero) / self._rpu)
        return v if -0x80000000 <= v <= 0x7FFFFFFF else _i32(v)

    def read_object(self, index: int, subindex: int) -> int:
        if (index, subindex) not in _KEYS:
            self._entry(index, subindex)  # raises the abort saying what is missing
        return self._value(index, subindex)

    def write_object(self, index: int, subindex: int, value: object) -> None:
        # Fast path for what RPDOs write every cycle (controlword, targets): a plain int
        # inside the object's limits needs none of the decoding and checking below.
        limits = _PLAIN_WRITES.get((index, subindex))
        if limits is not None and type(value) is int:
            lo, hi, allowed = limits
            if lo <= value <= hi and (allowed is None or value in allowed):
                self._od[(index, subindex)] = value
                if index == 0x6040:
                    self._on_controlword(value)
                elif index == 0x6060:
                    self._set_mode(value)
                return
        entry = self._entry(index, subindex)
        if not entry.writable:
            raise ObjectAccessError(ABORT_READ_ONLY, f"0x{index:04X}:{subindex} is read-only")
        value = self._decode(entry, value, index, subindex)
        if index in NEEDS_POWER_OFF and self._power.state in _ENERGIZED:
            raise ObjectAccessError(
                ABORT_DEVICE_STATE, f"0x{index:04X} cannot change while the drive is enabled"
            )
        self._check(entry, value, index, subindex)
        if index == 0x6080 and value > self.params.motor.max_speed_rpm:
            raise ObjectAccessError(
                ABORT_VALUE_HIGH, f"0x6080 = {value} rpm above the motor's maximum speed"
            )
        self._od[(index, subindex)] = value
        if index == 0x6040:
            self._on_controlword(value)
        elif index == 0x6060:
            self._set_mode(value)
        elif index == 0x6092:
            self._update_factor()
        elif index == 0x6080:
            self.plant.speed_limit = value * 2.0 * math.pi / 60.0
        elif index == 0x60FF and self._mode == PV:
            pass  # PV follows 0x60FF continuously

    def on_sync(self) -> None:
        od = self._od
        period = od[(0x60C2, 1)] * 10.0 ** od[(0x60C2, 2)]  # `interpolation_period`
        if period <= 0.0:
            period = (self.time - self._last_sync) if self._last_sync is not None else 0.002
        self._last_sync = self.time
        if not self._following:
            return
        if self._mode == CSP:
            tgt = self._clamp_position(od[(0x607A, 0)])
            to = self._zero + tgt * self._rpu  # `_from_user`
            self._seg_to = to
            self._seg_T = seg_T = max(period, 1e-6)
            self._seg_v = (to - self._dem.pos) / seg_T
            self._seg_t = 0.0
        elif self._mode == CSV:
            self._csv_vel = self._od[(0x60FF, 0)] * self.rad_per_unit

    def advance(self, dt_s: float) -> None:
        if dt_s <= 0.0:
            return
        if self._power_state == _NOT_READY_TO_SWITCH_ON:
            self._sm(None)  # transition 1: self-test passed
        if dt_s == self._split_dt:  # the same tick length every cycle: split it once
            n, h = self._split
        else:
            n = max(1, math.ceil(dt_s / self._max_substep - 1e-9))
            h = dt_s / n
            self._split_dt, self._split = dt_s, (n, h)
        # objects that cannot change inside advance(): convert them once per call
        od = self._od
        window = od[(0x6065, 0)]
        self._fe_window = None if window == 0xFFFFFFFF else window * self._rpu
        self._fe_timeout = od[(0x6066, 0)] * 1e-3
        self._ilim = od[(0x6072, 0)] * 1e-3 * self._rated_current  # 6072h in per mille of rated
        done = self._csp_substeps(h, n) if self._mode == CSP and self.csp_fast_path else 0
        for _ in range(n - done):
            self._substep(h)
        self.time += dt_s
        self._monitor_device(dt_s)

    def _monitor_device(self, dt_s: float) -> None:
        """The drive's monitors of its own hardware, once per tick (not per plant sub-step):

        * device temperature: the heat-sink sensor follows the cabinet air with a first-order
          lag (DEVICE_TAU_S; the power stage's own losses are not modelled): warning bit 7
          above DEVICE_WARNING_C, fault 0x4210 above DEVICE_TRIP_C;
        * brake check (as a Danfoss drive's "brake check"): the chopper circuit is tested
          every CHOPPER_CHECK_S; an open chopper or resistor faults 0x7111 at the next test
          instead of waiting for braking energy to trip the link at 420 V.
        """
        p = self.plant
        self.device_temp += (p.ambient - self.device_temp) * (1.0 - math.exp(-dt_s / DEVICE_TAU_S))
        fault = 0
        if self.device_temp > DEVICE_TRIP_C:
            fault = 0x4210
        if p.chopper_failed:
            self._chopper_open_s += dt_s
            if self._chopper_open_s >= CHOPPER_CHECK_S - 1e-9:
                fault = fault or 0x7111
        else:
            self._chopper_open_s = 0.0
        if fault and self._power_state not in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            self._raise_fault(fault)

    def _csp_substeps(self, h: float, n: int) -> int:
        """`_substep` specialised for plain CSP following in OPERATION ENABLED; returns how
        many of the n sub-steps it ran (the rest go through `_substep`).

        It computes exactly what `_substep` computes there, without the per-sub-step mode
        dispatch: no stop, no halt (CSP ignores it), no homing, no PP/PV windows. The plant
        runs the sub-steps in one call (`Plant.follow_ramp`: the demand ramp, the loops, the
        following-error and switch monitors) and hands over as soon as a sub-step ends with
        a fault or a changed switch input.
        """
        if not self._following or self._hm is not None:
            return 0
        d = self._dem
        inputs = self._inputs
        self._halt_stopped = False
        done, fault, new_inputs, pos, vel, seg_t, fe_timer = self.plant.follow_ramp(
            h,
            n,
            d.pos,
            self._seg_t,
            self._seg_T,
            self._seg_to,
            self._seg_v,
            self._ilim,
            bool(inputs & 1),
            bool(inputs & 2),
            self._fe_window,
            self._fe_timer,
            self._fe_timeout,
            inputs,
        )
        if not done:
            return 0
        d.pos, d.vel = pos, vel
        self._seg_t = seg_t
        self._fe_timer = fe_timer
        if fault == FOLLOWING_ERROR:
            self._fe_latched = True
        if fault or new_inputs != inputs:
            self._inputs = new_inputs
            if new_inputs & ~inputs & 3 and not fault:
                fault = 0x8612
            if fault:
                self._raise_fault(fault)
        return done

    def on_nmt_state(self, state: str) -> None:
        self.nmt_state = state

    def on_nmt_reset(self, scope: str) -> None:
        """Optional hook of the CiA 301 slave: 'node' reboots the drive (`power_on_reset`),
        'communication' leaves the profile application untouched."""
        if scope == "node":
            self.power_on_reset()

    def on_communication_fault(self, error_code: int) -> None:
        """Apply the abort connection option code 0x6007 (CiA 402): 0 no action, 1 fault
        (0x603F = error_code, no EMCY of ours: the 301 layer already sent it), 2 disable
        voltage, 3 quick stop."""
        option = self._od[(0x6007, 0)]
        if option == 1:
            self._raise_fault(error_code, emcy=False)
        elif option == 2:
            self._sm(0x0000, internal=True)
        elif option == 3:
            self._sm(0x0002, internal=True)

    def take_emcy(self) -> list[EmcyRequest]:
        out, self._emcy = self._emcy, []
        return out

    # ------------------------------------------------------------------ fault injection
    def inject(self, kind: str, **params: float) -> None:
        """Inject a physical fault: a row of `drives.fault_registry` whose target is "drive"
        (ValueError names an unknown kind or a bad parameter)."""
        row = self._fault_kind(kind)
        handler = row.on_plant
        assert handler is not None  # every drive row has one (checked by the registry)
        handler(self.plant, row.values(params))

    def clear_injection(self, kind: str) -> None:
        """Remove an injected fault (the drive still needs a fault reset if it tripped)."""
        handler = self._fault_kind(kind).off_plant
        assert handler is not None
        handler(self.plant)

    @staticmethod
    def _fault_kind(kind: str) -> FaultKind:
        row = DRIVE_FAULTS.get(kind)
        if row is None:
            raise ValueError(f"unknown fault kind {kind!r}; known: {', '.join(DRIVE_FAULTS)}")
        return row

    # ------------------------------------------------------------------ observation
    @property
    def state(self) -> State:
        return self._power.state

    @property
    def state_name(self) -> str:
        return STATE_NAMES[self._power.state]

    @property
    def statusword(self) -> int:
        return self._statusword()

    @property
    def error_code(self) -> int:
        return self._fault_code

    @property
    def error_register(self) -> int:
        """0x1001 contribution of the application (0 when no fault is latched)."""
        return F.spec(self._fault_code).register if self._fault_code else 0

    @property
    def mode_display(self) -> int:
        return self._mode

    @property
    def interpolation_period(self) -> float:
        return self._od[(0x60C2, 1)] * 10.0 ** self._od[(0x60C2, 2)]

    @property
    def position_actual(self) -> int:
        return self._to_user(self.plant.theta_meas)

    @property
    def following_error(self) -> int:
        return round((self._dem.pos - self.plant.theta_meas) / self.rad_per_unit)

    # ------------------------------------------------------------------ internals: objects
    def _entry(self, index: int, subindex: int) -> Entry:
        subs = OBJECTS.get(index)
        if subs is None:
            raise ObjectAccessError(ABORT_NOT_EXIST, f"0x{index:04X} does not exist")
        entry = subs.get(subindex)
        if entry is None:
            raise ObjectAccessError(ABORT_SUBINDEX, f"0x{index:04X} has no sub-index {subindex}")
        return entry

    @staticmethod
    def _decode(entry: Entry, value, index: int, subindex: int) -> int:
        if isinstance(value, bytes | bytearray):
            size = TYPE_SIZE[entry.dtype]
            if len(value) != size:
                raise ObjectAccessError(
                    0x06070010, f"0x{index:04X}:{subindex} needs {size} bytes, got {len(value)}"
                )
            return struct.unpack(_STRUCT[(entry.dtype, size)], bytes(value))[0]
        if isinstance(value, float):
            if not value.is_integer():
                raise ObjectAccessError(0x06070010, f"0x{index:04X}:{subindex} is an integer")
            return int(value)
        if not isinstance(value, int):
            raise ObjectAccessError(
                0x06070010, f"0x{index:04X}:{subindex} takes an integer, not {type(value).__name__}"
            )
        return int(value)

    @staticmethod
    def _check(entry: Entry, value: int, index: int, subindex: int) -> None:
        lo, hi = TYPE_RANGE[entry.dtype]
        if entry.low is not None:
            lo = max(lo, entry.low)
        if entry.high is not None:
            hi = min(hi, entry.high)
        where = f"0x{index:04X}:{subindex} = {value}"
        if value > hi:
            raise ObjectAccessError(ABORT_VALUE_HIGH, f"{where} above {hi}")
        if value < lo:
            raise ObjectAccessError(ABORT_VALUE_LOW, f"{where} below {lo}")
        if entry.allowed is not None and value not in entry.allowed:
            raise ObjectAccessError(ABORT_VALUE_RANGE, f"{where} not supported")

    def _store(self, index: int, subindex: int, value: int) -> None:
        entry = self._entry(index, subindex)
        if not entry.writable:
            raise ObjectAccessError(ABORT_READ_ONLY, f"0x{index:04X}:{subindex} is read-only")
        value = self._decode(entry, value, index, subindex)
        self._check(entry, value, index, subindex)
        self._od[(index, subindex)] = value
        if index == 0x6060:
            self._mode = value

    def _value(self, index: int, subindex: int) -> int:
        p = self.plant
        rpu = self.rad_per_unit
        if index == 0x6041:
            return self._statusword()
        if index == 0x6061:
            return self._mode
        if index == 0x603F:
            return self._fault_code
        if index == 0x6064:  # every TPDO: `_i32(self._to_user(p.theta_meas))` inlined
            v = round((p.counts * p._rad_per_count - self._zero) / self._rpu)
            return v if -0x80000000 <= v <= 0x7FFFFFFF else _i32(v)
        if index == 0x6063:
            return _i32(p.counts)
        if index == 0x6062:
            return _i32(self._to_user(self._dem.pos))
        if index == 0x60F4:
            return _i32(round((self._dem.pos - p.theta_meas) / rpu))
        if index == 0x606C:
            return _i32(round(p.vel_meas / rpu))
        if index == 0x606B:
            return _i32(round(self._dem.vel / rpu))
        if index == 0x6077:
            return _i16(round(1000.0 * p.torque / self.params.motor.rated_torque))
        if index == 0x6078:
            return _i16(round(1000.0 * p.current / self.params.motor.rated_current))
        if index == 0x60FD:
            return p.switch_inputs()
        return self._od[(index, subindex)]

    # ------------------------------------------------------------------ state machine
    def _options(self) -> Options:
        od = self._od
        return Options(od[(0x605A, 0)], od[(0x605B, 0)], od[(0x605C, 0)], od[(0x605E, 0)])

    def _fault_present(self) -> bool:
        code, p, d = self._fault_code, self.plant, self.params
        if p.encoder_broken or p.inverter_fault:
            return True  # hardware faults block any reset, whichever fault was latched first
        if code == 0x2310:
            return p.inverter_fault
        if code == 0x7305:
            return p.encoder_broken or p.encoder_noise > 0.0
        if code == 0x3130:
            return not p.supply_on
        if code == 0x3220:
            return not p.voltage_present
        if code == 0x3210:
            return p.vdc > d.dc_link.chopper_on
        if code == 0x4310:
            return p.winding_temp > d.thermal.warning
        if code == 0x4210:
            return self.device_temp > DEVICE_WARNING_C
        if code == 0x7111:
            return p.chopper_failed
        if code == 0x2350:
            return p.i2t > d.thermal.i2t_warning_fraction * p.i2t_limit
        return False

    def _sm(
        self,
        controlword: int | None,
        *,
        fault: bool = False,
        stopped: bool = False,
        forced_coast: bool = False,
        internal: bool = False,
    ) -> None:
        """Run the pure state machine and carry out the actions of the transitions taken."""
        before = self._power
        if internal:
            # A command from inside the drive (0x6007): decode it without disturbing the
            # fault-reset edge detector of the master's controlword.
            res = sm_step(
                before,
                controlword,
                Conditions(voltage_present=self.plant.voltage_present, stopped=stopped),
                self._options(),
            )
            power = replace(res.power, last_controlword=before.last_controlword)
        else:
            cond = Conditions(
                fault=fault,
                fault_present=self._fault_present(),
                stopped=stopped,
                voltage_present=self.plant.voltage_present,
                forced_coast=forced_coast,
            )
            res = sm_step(before, controlword, cond, self._options())
            power = res.power
        self._set_power(power)
        for t in res.transitions:
            if t == 4:
                self._on_enable()
            elif t == 15:
                self._fault_code = 0
                self._fe_latched = False
                self._emcy.append(EmcyRequest(0x0000, 0))
        entered = before.state != _OPERATION_ENABLED == power.state
        if entered and 4 not in res.transitions:
            self._on_enable(keep=True)

    def _on_enable(self, keep: bool = False) -> None:
        """Drive function enabled: internal set-points start from the actual position."""
        p = self.plant
        if not keep:
            self._dem.pos = p.theta_meas
            self._dem.vel = 0.0
            p.vel_integral = 0.0
        self._fe_timer = 0.0
        self._start_mode()

    def _set_mode(self, mode: int) -> None:
        if mode == self._mode:
            return
        self._mode = mode
        if self._power.state == _OPERATION_ENABLED:
            self._start_mode()

    def _start_mode(self) -> None:
        d = self._dem
        if self._mode in (PV, CSV):
            d.vel = self.plant.vel_meas
        self._seg_to, self._seg_v, self._seg_t, self._seg_T = d.pos, 0.0, 0.0, 0.0
        self._csv_vel = 0.0
        self._pp_target = d.pos
        self._pp_target_user = self._to_user(d.pos)
        self._pp_moving = False
        self._pp_next = None
        self._hm = None
        self._hm_status = HM.HomingStatus.NOT_STARTED
        self._window_timer = math.inf  # standing on its own position: target reached

    def _raise_fault(self, code: int, emcy: bool = True) -> None:
        if self._power.state == _NOT_READY_TO_SWITCH_ON:
            self._sm(None)  # the self-test finishes before a fault can be reported
        if self._power.state == State.FAULT_REACTION_ACTIVE:
            if F.spec(code).forced_coast and self._power.stop != Stop.COAST:
                self._set_power(replace(self._power, pending=None, stop=Stop.COAST))
                self._sm(None, stopped=True)  # coasting: the reaction is over at once
            return
        if self._power.state == State.FAULT:
            return
        self._fault_code = code
        if self._hm is not None and self._hm_status == HM.HomingStatus.IN_PROGRESS:
            self._hm_status = HM.HomingStatus.ERROR
        if emcy:
            self._emcy.append(EmcyRequest(code, F.spec(code).register))
        self._sm(None, fault=True, forced_coast=F.spec(code).forced_coast)

    def _set_power(self, power: PowerState) -> None:
        """The one place the power state changes; it keeps the plain copies the per-cycle
        paths read (compiled, they are read without attribute lookups on the immutable
        `PowerState`, an ordinary Python object)."""
        self._power = power
        self._power_state = power.state
        self._last_cw = power.last_controlword
        #: OPERATION ENABLED with no stop running: the drive follows its demand
        self._following = power.state == _OPERATION_ENABLED and power.stop is None

    def _on_controlword(self, cw: int) -> None:
        prev = self._last_cw
        if cw == prev and self._power_state == _OPERATION_ENABLED:
            return  # the same word in every RPDO while enabled: no edge, nothing to do
        # (other states re-evaluate a repeated word: e.g. Switch on succeeds once the DC
        # link is charged)
        self._sm(cw)
        if not self._following:
            return
        rising = cw & ~prev
        falling = prev & ~cw
        if self._mode == PP:
            if rising & CW_NEW_SET_POINT:
                self._pp_new_set_point(cw)
            elif falling & CW_NEW_SET_POINT:
                self._pp_ack = False
        elif self._mode == HOMING:
            if rising & CW_NEW_SET_POINT:
                self._start_homing()
            elif falling & CW_NEW_SET_POINT and self._hm_status == HM.HomingStatus.IN_PROGRESS:
                self._hm_status = HM.HomingStatus.INTERRUPTED
                self._hm = None
        if rising & CW_HALT:
            self._halt_stopped = False

    # ------------------------------------------------------------------ profile position
    def _pp_new_set_point(self, cw: int) -> None:
        target = self._od[(0x607A, 0)]
        if cw & CW_RELATIVE:
            target += self._pp_target_user
        target = self._clamp_position(target)
        rad = self._from_user(target)
        if not self._pp_moving or cw & CW_CHANGE_SET_IMMEDIATELY:
            self._pp_target, self._pp_moving, self._pp_next = rad, True, None
        elif self._pp_next is None:
            self._pp_next = rad
        else:
            return  # buffer full: no acknowledge
        self._pp_target_user = target
        self._pp_ack = True
        self._window_timer = 0.0

    # ------------------------------------------------------------------ homing
    def _start_homing(self) -> None:
        method = self._od[(0x6098, 0)]
        segs = HM.plan(method, self.plant.switch_inputs())
        if segs is None:
            self._hm_status = HM.HomingStatus.ERROR_STOPPED
            return
        rpu = self.rad_per_unit
        travel = 1.2 * self.params.screw.length / self.params.metres_per_motor_rad
        self._hm = HM.HomingRun(
            segs,
            self._od[(0x6099, 1)] * rpu,
            self._od[(0x6099, 2)] * rpu,
            self._od[(0x609A, 0)] * rpu,
            travel,
            self._dem.pos,
        )
        self._hm_status = HM.HomingStatus.IN_PROGRESS
        if not segs:
            self._hm.latched = self.plant.theta_meas
            self._set_home(self.plant.theta_meas)

    def _set_home(self, measured: float) -> None:
        self._zero = measured - self._od[(0x607C, 0)] * self.rad_per_unit
        self.homed = True
        self._hm_status = HM.HomingStatus.ATTAINED

    # ------------------------------------------------------------------ software limits
    def _clamp_position(self, target: int) -> int:
        lo, hi = self._od[(0x607D, 1)], self._od[(0x607D, 2)]
        self._limit_active = False
        if lo < hi:
            if target < lo:
                target, self._limit_active = lo, True
            elif target > hi:
                target, self._limit_active = hi, True
        return target

    # ------------------------------------------------------------------ one sub-step
    def _stop_control(self, kind: Stop, h: float, velocity_mode: bool):
        """Control for a running stop: (loop mode, stopped).

        With `velocity_mode` the ramp is the velocity loop's command, so the motor itself
        decelerates along it and is at standstill a few velocity-loop time constants after
        the ramp reaches zero. Otherwise (halt in a position mode) the ramp moves the
        position demand and the motor follows it with the Kv lag.
        """
        d, p = self._dem, self.plant
        thr = self.params.loops.standstill_velocity
        if kind == Stop.COAST:
            d.pos, d.vel = p.theta_meas, 0.0
            return OFF, True
        if kind in (Stop.CURRENT_LIMIT, Stop.VOLTAGE_LIMIT):
            d.vel = 0.0
            d.pos = p.theta_meas
            return VELOCITY, abs(p.vel_meas) < thr
        rate = self._od[(0x6084 if kind == Stop.SLOW_DOWN else 0x6085, 0)] * self.rad_per_unit
        stop_step(d, rate, h)
        if velocity_mode:
            return VELOCITY, d.vel == 0.0 and abs(p.vel_meas) < thr
        return POSITION, d.vel == 0.0 and abs(p.vel_meas) < thr

    def _substep(self, h: float) -> None:
        power = self._power
        st = power.state
        d, p = self._dem, self.plant
        mode = self._mode
        ctl = OFF
        vel_mode = mode in (PV, CSV)
        stopped = False
        block_neg = block_pos = False
        inputs = self._inputs
        # The position loop compares the demand and the encoder at the same instant: the
        # start of the sub-step (the generators below move the demand to its end).
        pos_now = d.pos
        if st in _ENERGIZED:
            if power.stop is not None:
                # Quick stop, fault reaction and disable operation ramp the motor's speed
                # (CiA 402: decelerate on the ramp, then the transition follows at
                # standstill). A ramp of the position demand would leave the motor to run
                # out its v/Kv following error for ~4/Kv (250 ms at Kv 16.7) after the ramp.
                ctl, stopped = self._stop_control(power.stop, h, True)
            elif st == _OPERATION_ENABLED:
                ctl = self._mode_step(h)
            else:
                ctl = VELOCITY if vel_mode else POSITION  # QSA 5..8 after standstill: hold
                d.vel = 0.0
            if inputs & 1 and not self._homing_uses(1):
                block_neg = True
            if inputs & 2 and not self._homing_uses(2):
                block_pos = True
        else:
            d.pos, d.vel = p.theta_meas, 0.0
        th_prev = p.theta_meas
        x_prev = p.table_x
        fault = p.step(h, ctl, pos_now, d.vel, d.vel, self._ilim, block_neg, block_pos)
        if ctl == VELOCITY:
            d.pos = p.theta_meas
        # following error monitor (position control in OPERATION ENABLED)
        if ctl == POSITION and st == _OPERATION_ENABLED and power.stop is None:
            window = self._fe_window
            if window is not None and abs(d.pos - p.theta_meas) > window:
                self._fe_timer += h
                if self._fe_timer > self._fe_timeout and not fault:
                    self._fe_latched = True
                    fault = 0x8611
            else:
                self._fe_timer = 0.0
        if mode == PP and st == _OPERATION_ENABLED and not self._pp_moving:
            near = abs(p.theta_meas - self._pp_target) <= self._od[(0x6067, 0)] * self.rad_per_unit
            self._window_timer = self._window_timer + h if near else 0.0
        elif mode == PV and st == _OPERATION_ENABLED:
            near = abs(p.vel_meas - self._pv_target()) <= self._od[(0x606D, 0)] * self._rpu
            self._window_timer = self._window_timer + h if near else 0.0
        # switches
        new_inputs = p.switch_inputs()
        rising = new_inputs & ~inputs
        self._inputs = new_inputs
        if self._hm is not None and st == _OPERATION_ENABLED:
            self._observe_homing(inputs, new_inputs, th_prev, x_prev)
        if rising & 3 and st in _ENERGIZED and not fault:
            hm_bits = (1 if self._homing_uses(1) else 0) | (2 if self._homing_uses(2) else 0)
            if rising & 3 & ~hm_bits:
                if self._hm is not None:
                    self._hm.error = True
                    self._hm_status = HM.HomingStatus.ERROR
                else:
                    fault = 0x8612
        if fault:
            self._raise_fault(fault)
        # `stopped` belongs to the stop that was running: a fault that just ended OPERATION
        # ENABLED starts a new one, a fault repeated during FAULT REACTION ACTIVE does not.
        if stopped and not (fault and st == _OPERATION_ENABLED) and self._power.stop is not None:
            self._sm(None, stopped=True)

    def _homing_uses(self, bit: int) -> bool:
        if self._hm is None or self._mode != HOMING:
            return False
        return any(s.until[0] == "sw" and s.until[1] == bit for s in self._hm.segments)

    def _observe_homing(self, inputs: int, new_inputs: int, th_prev: float, x_prev: float) -> None:
        hm, p = self._hm, self.plant
        if hm is None:
            return
        changed = inputs ^ new_inputs
        edges: dict[int, float] = {}
        if changed:
            sw = self.params.switches
            where = {1: sw.negative_limit, 2: sw.positive_limit, 4: sw.home_switch}
            dx = p.table_x - x_prev
            for bit, edge in where.items():
                if changed & bit and edge is not None:
                    frac = (edge - x_prev) / dx if dx else 1.0
                    frac = min(1.0, max(0.0, frac))
                    edges[bit] = th_prev + frac * (p.theta_meas - th_prev)
        index_at = p.index_crossing(th_prev, p.theta_meas)
        was_latched = hm.latched
        hm.observe(new_inputs, edges, index_at)
        if hm.latched is not None and was_latched is None:
            shift = hm.latched
            self._set_home(shift)

    def _mode_step(self, h: float) -> int:
        d, od = self._dem, self._od
        mode = self._mode
        rpu = self.rad_per_unit
        cw = self._power.last_controlword
        halt = bool(cw & CW_HALT) and mode in (PP, PV, HOMING)
        if halt:
            kind = Stop(self._od[(0x605D, 0)])
            ctl, self._halt_stopped = self._stop_control(kind, h, mode == PV)
            if mode == HOMING and self._hm is not None:
                self._hm = None
                self._hm_status = HM.HomingStatus.INTERRUPTED
            return ctl
        self._halt_stopped = False
        if mode == CSP:
            if self._seg_t < self._seg_T:
                self._seg_t += h
                if self._seg_t >= self._seg_T:
                    d.pos, d.vel = self._seg_to, self._seg_v
                else:
                    d.pos += self._seg_v * h
                    d.vel = self._seg_v
            else:
                d.vel = 0.0
            return POSITION
        if mode == CSV:
            d.vel = self._csv_vel
            return VELOCITY
        if mode == PP:
            if self._pp_moving:
                vmax = min(od[(0x6081, 0)], od[(0x607F, 0)]) * rpu
                if trapezoid_step(
                    d, self._pp_target, vmax, od[(0x6083, 0)] * rpu, od[(0x6084, 0)] * rpu, h
                ):
                    if self._pp_next is not None:
                        self._pp_target, self._pp_next = self._pp_next, None
                    else:
                        self._pp_moving = False
            return POSITION
        if mode == PV:
            target = od[(0x60FF, 0)] * rpu
            vmax = od[(0x607F, 0)] * rpu
            target = max(-vmax, min(vmax, target))
            ramp_velocity(d, target, od[(0x6083, 0)] * rpu, od[(0x6084, 0)] * rpu, h)
            return VELOCITY
        if mode == HOMING:
            hm = self._hm
            if hm is not None:
                hm.standstill = abs(self.plant.vel_meas) < self.params.loops.standstill_velocity
                done = hm.drive(d, h)
                if hm.error:
                    self._hm_status = (
                        HM.HomingStatus.ERROR_STOPPED if done else HM.HomingStatus.ERROR
                    )
                elif done and hm.latched is not None:
                    self._hm_status = HM.HomingStatus.DONE
                    self._hm = None
                if done and hm.error:
                    self._hm = None
            else:
                d.vel = 0.0
            return POSITION
        d.vel = 0.0
        return POSITION  # no mode: hold position

    # ------------------------------------------------------------------ statusword
    def _statusword(self) -> int:
        st = self._power_state
        p = self.plant
        sw = STATE_BITS[st] | SW_REMOTE
        if p.vdc >= self._voltage_present:  # `p.voltage_present`, inlined
            sw |= SW_VOLTAGE_ENABLED
        # `p.warnings`, inlined
        if (
            p.winding_temp > self._warning_temp
            or p.i2t > self._i2t_warning_fraction * p._i2t_limit
            or self.device_temp > DEVICE_WARNING_C
        ):
            sw |= SW_WARNING
        if self._limit_active or p.velocity_limited:
            sw |= SW_INTERNAL_LIMIT
        mode = self._mode
        if self._fe_latched and mode in (PP, CSP, HOMING):
            sw |= SW_OMS13
        if st == _QUICK_STOP_ACTIVE and self._power.stop is None:
            sw |= SW_TARGET_REACHED
        if not self._following:
            return sw
        if mode in (CSP, CSV):
            sw |= SW_OMS12  # drive follows the command value
        elif mode == PP:
            if self._pp_ack:
                sw |= SW_OMS12
            halted = self._power.last_controlword & CW_HALT
            if (halted and self._halt_stopped) or (not halted and self._pp_reached()):
                sw |= SW_TARGET_REACHED
        elif mode == PV:
            rpu = self.rad_per_unit
            if abs(p.vel_meas) <= self._od[(0x606F, 0)] * rpu:
                sw |= SW_OMS12
            near = abs(p.vel_meas - self._pv_target()) <= self._od[(0x606D, 0)] * rpu
            if near and self._window_timer >= self._od[(0x606E, 0)] * 1e-3 - 1e-12:
                sw |= SW_TARGET_REACHED
        elif mode == HOMING:
            status = self._hm_status
            thr = self.params.loops.standstill_velocity
            if status == HM.HomingStatus.ERROR and abs(p.vel_meas) < thr:
                status = HM.HomingStatus.ERROR_STOPPED
            sw |= status.value
        return sw

    def _pv_target(self) -> float:
        """The velocity PV is heading for (rad/s): 0x60FF clamped by 0x607F, 0 while halted."""
        if self._power.last_controlword & CW_HALT:
            return 0.0
        vmax = self._od[(0x607F, 0)] * self._rpu
        return max(-vmax, min(vmax, self._od[(0x60FF, 0)] * self._rpu))

    def _pp_reached(self) -> bool:
        if self._pp_moving:
            return False
        window = self._od[(0x6067, 0)] * self.rad_per_unit
        if abs(self.plant.theta_meas - self._pp_target) > window:
            return False
        return self._window_timer >= self._od[(0x6068, 0)] * 1e-3 - 1e-12


def _i32(v: int) -> int:
    return max(-(1 << 31), min((1 << 31) - 1, v))


def _i16(v: int) -> int:
    return max(-(1 << 15), min((1 << 15) - 1, v))

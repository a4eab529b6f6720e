"""The physical plant behind one drive: inner loops, motor, ball screw, table, encoder, DC link.

One call to `Plant.step(h, ...)` integrates one sub-step of h seconds:

* velocity PI (with anti-windup) on the encoder speed, fed by the position P loop
  (gain Kv, velocity feed-forward) or by a velocity demand;
* a deadbeat (predictive) current controller limited by the DC-link voltage; the winding
  equation V = Kb·ω + R·I + L·dI/dt is integrated **exactly** over the sub-step for the
  applied voltage (zero-order hold), so it is stable for any h;
* mechanics by semi-implicit (symplectic) Euler: J·dω/dt = Km·I − b·ω − Tc·sgn(ω) − T_load with
  stiction at ω = 0, J = motor + reflected screw and table inertia; optional backlash between
  nut and table (the motor encoder does not see it: semi-closed loop);
* DC link capacitor fed by a rectifier, with a hysteresis brake chopper, integrated implicitly;
* winding thermal model, I²t accumulator, and the plant-level monitors.

The plant knows nothing of CANopen; `step` returns 0 or the CiA 402 fault code it detected.
This physics is written once, in `Plant._substeps`: `step` runs one sub-step of it and the
CSP fast path `follow_ramp` runs many on a demand ramp, with the state in local variables.
"""

from __future__ import annotations

import math
from typing import Final, final

from drives.plant.params import PlantParams

# Control modes of the inner loops.
OFF: Final = 0  # inverter disabled, motor coasts
POSITION: Final = 1  # position P (+ feed-forward) → velocity PI → current
VELOCITY: Final = 2  # velocity PI → current

# Fault codes the plant detects (CiA 402 / IEC 61800-7 numbering).
OVERCURRENT: Final = 0x2310
I2T: Final = 0x2350
MAINS_PHASE_FAILURE: Final = 0x3130
DC_OVERVOLTAGE: Final = 0x3210
DC_UNDERVOLTAGE: Final = 0x3220
OVERTEMPERATURE: Final = 0x4310
MOTOR_BLOCKED: Final = 0x7121
ENCODER: Final = 0x7305
FOLLOWING_ERROR: Final = 0x8611  # the drive's monitor, run inside `follow_ramp`

_TWO_PI: Final = 2.0 * math.pi
_NOISE_SEED: Final = 2463534242  # xorshift32: the same noise on every run (lockstep tests)


@final
class Constants:
    """The parameters as the sub-step loop uses them, by name, computed once per plant.

    All floats (a YAML integer becomes 2.0 here, the same value in every expression): the
    compiled plant (mypyc, drives/plant/mypyc.list) keeps them as C doubles.
    """

    def __init__(self, p: PlantParams, inertia: float, rad_per_count: float) -> None:
        m, sc, dl, th, mo, enc = p.motor, p.screw, p.dc_link, p.thermal, p.monitor, p.encoder
        mpr = p.metres_per_motor_rad
        # winding, inner loops, current limits
        self.resistance = float(m.resistance)
        self.inductance = float(m.inductance)
        self.kb = float(m.kb)
        self.km = float(m.km)
        self.kv = float(p.loops.kv)
        self.velocity_feedforward = float(p.loops.velocity_feedforward)
        self.peak_current = float(m.peak_current)
        self.overcurrent_trip = float(m.overcurrent_trip)
        self.rated_current_sq = float(m.rated_current**2)  # the I²t integrand's zero
        # mechanics at the motor shaft
        self.viscous = float(sc.viscous)
        self.coulomb_torque = float(sc.coulomb_torque)
        self.load_arm = float(mpr / sc.efficiency)  # N·m at the motor per N on the table
        self.inertia = float(inertia)
        self.metres_per_rad = float(mpr)
        # encoder: the plausible count change per second (faster is a broken signal)
        self.rad_per_count = float(rad_per_count)
        self.max_counts_per_s = float(
            enc.max_speed_factor * m.max_speed_rpm / 60.0 * enc.counts_per_rev
        )
        # DC link, as conductances
        self.capacitance = float(dl.capacitance)
        self.g_bleed = float(1.0 / dl.bleed_resistance)
        self.chopper_on = float(dl.chopper_on)
        self.chopper_off = float(dl.chopper_off)
        self.g_chopper = float(1.0 / dl.chopper_resistance)
        self.g_source = float(1.0 / dl.source_resistance)
        self.overvoltage_trip = float(dl.overvoltage_trip)
        self.undervoltage_trip = float(dl.undervoltage_trip)
        self.mains_loss = float(dl.mains_loss_detect)  # s without mains before 0x3130
        # winding temperature
        self.thermal_capacity = float(th.time_constant / th.thermal_resistance)
        self.thermal_resistance = float(th.thermal_resistance)
        self.temperature_trip = float(th.trip)
        # the blocked-motor monitor
        self.blocked_time = float(mo.blocked_time)
        self.blocked_speed = float(mo.blocked_speed)


class Plant:
    """Motor + screw + table + encoder + DC link with the drive's inner loops."""

    def __init__(self, params: PlantParams | None = None) -> None:
        self.params = p = params or PlantParams()
        m, lp = p.motor, p.loops
        self.inertia = p.total_inertia
        wc = 2.0 * math.pi * lp.velocity_bandwidth_hz
        self.kp_v = self.inertia * wc / m.km  # A per rad/s
        self.ki_v = self.kp_v * wc * lp.velocity_pi_corner_ratio  # A per rad
        self._rad_per_count = _TWO_PI / p.encoder.counts_per_rev
        self._mpr = p.metres_per_motor_rad
        self._h_cached = -1.0
        self._decay = 0.0
        self._k = Constants(p, self.inertia, self._rad_per_count)
        # the switch positions as a flag and a float (the parameter set is immutable): the
        # sub-step loop compares plain floats, without attribute lookups on the parameters
        sw = p.switches
        self._has_neg, self._neg = sw.negative_limit is not None, sw.negative_limit or 0.0
        self._has_pos, self._pos = sw.positive_limit is not None, sw.positive_limit or 0.0
        self._has_home, self._home = sw.home_switch is not None, sw.home_switch or 0.0
        self._home_below = sw.home_switch_active_below
        # the hard stops (none modelled on a side without a limit switch)
        over = sw.end_stop_overtravel
        self._stop_lo: float = self._neg - over if self._has_neg else -math.inf
        self._stop_hi: float = self._pos + over if self._has_pos else math.inf
        self.speed_limit = m.max_speed_rpm * _TWO_PI / 60.0  # rad/s, the drive's 0x6080
        self._i2t_limit = (m.peak_current**2 - m.rated_current**2) * p.thermal.i2t_peak_time
        # injections
        self.load_force = 0.0  # N on the table, + pushes toward +x
        self.blocked = False
        self.chopper_failed = False
        self.supply_on = True
        self.mains_voltage = p.dc_link.mains_voltage
        self.inverter_fault = False
        self.encoder_broken = False
        self.encoder_noise = 0.0  # counts: each reading is off by up to ± this (0: clean)
        self._noise_state = _NOISE_SEED
        self.ambient = p.thermal.ambient
        self.backlash = p.screw.backlash
        self.theta = 0.0
        self._nut_origin = p.switches.initial_position
        # physical rotor angle at encoder count zero: the rotor is keyed to the screw, so the
        # index mark sits at fixed table positions (rotor angle = x / metres-per-rad)
        self._rotor_origin = p.switches.initial_position / p.metres_per_motor_rad
        self.table_x = p.switches.initial_position
        self.power_on_reset()
        self.vdc = p.dc_link.mains_voltage
        self.winding_temp = p.thermal.ambient

    def power_on_reset(self) -> None:
        """Electrical and control state after a drive reboot; the table does not move."""
        # The incremental encoder counts from zero at power-on wherever the axis stands.
        self._nut_origin += self.theta * self._mpr
        self._rotor_origin += self.theta
        self.theta = 0.0
        self.omega = 0.0
        self.current = 0.0
        self.voltage = 0.0
        self.vel_integral = 0.0
        self.encoder_offset = 0  # counts added by an injected jump
        self.counts = 0
        self._prev_counts = 0
        self.vel_meas = 0.0
        self.i2t = 0.0
        self.chopper = False
        self.mains_lost_for = 0.0
        self.blocked_for = 0.0
        self.current_limited = False
        self.velocity_limited = False

    def set_encoder_noise(self, amplitude: float) -> None:
        """Noise on the encoder signal: each reading off by up to ±amplitude counts (0: off).

        The noise is on the reading only (interpolated sin/cos signals disturbed by a motor
        cable): the count does not drift, so clearing it leaves the position intact.
        """
        self.encoder_noise = amplitude
        self._noise_state = _NOISE_SEED

    def _noise_counts(self) -> int:
        """One reading's noise: uniform in ±encoder_noise counts (xorshift32)."""
        x = self._noise_state
        x ^= (x << 13) & 0xFFFFFFFF
        x ^= x >> 17
        x ^= (x << 5) & 0xFFFFFFFF
        self._noise_state = x
        return round((x * (2.0 / 4294967295.0) - 1.0) * self.encoder_noise)

    # -- geometry -----------------------------------------------------------------------
    def nut_x(self, theta: float | None = None) -> float:
        return self._nut_origin + (self.theta if theta is None else theta) * self._mpr

    def index_crossing(self, theta_from: float, theta_to: float) -> float | None:
        """Measured angle of an index mark passed between two measured angles, else None."""
        if theta_to == theta_from:
            return None
        ref = self.params.encoder.index_angle - self._rotor_origin
        k_from = math.floor((theta_from - ref) / _TWO_PI)
        k_to = math.floor((theta_to - ref) / _TWO_PI)
        if k_from == k_to:
            return None
        k = max(k_from, k_to)
        return ref + k * _TWO_PI

    @property
    def theta_meas(self) -> float:
        return self.counts * self._rad_per_count

    def switch_inputs(self) -> int:
        """0x60FD bits: 0 negative limit, 1 positive limit, 2 home switch (table position)."""
        s, x = self.params.switches, self.table_x
        bits = 0
        if s.negative_limit is not None and x <= s.negative_limit:
            bits |= 1
        if s.positive_limit is not None and x >= s.positive_limit:
            bits |= 2
        if s.home_switch is not None and (
            x <= s.home_switch if s.home_switch_active_below else x >= s.home_switch
        ):
            bits |= 4
        return bits

    @property
    def voltage_present(self) -> bool:
        return self.vdc >= self.params.dc_link.voltage_present

    @property
    def torque(self) -> float:
        return self.params.motor.km * self.current

    # -- the sub-steps --------------------------------------------------------------------
    def step(
        self,
        h: float,
        mode: int,
        pos_demand: float = 0.0,
        vel_ff: float = 0.0,
        vel_demand: float = 0.0,
        current_limit: float | None = None,
        block_negative: bool = False,
        block_positive: bool = False,
    ) -> int:
        """Integrate h seconds. Angles in motor rad (encoder frame). Returns a fault code or 0."""
        # one sub-step of `_substeps` on a demand that holds pos_demand (no ramp, no watched
        # following error: the drive runs its monitors around `step` itself)
        return self._substeps(
            h,
            1,
            mode,
            pos_demand,
            vel_ff,
            vel_demand,
            0.0,
            0.0,
            0.0,
            0.0,
            current_limit,
            block_negative,
            block_positive,
            None,
            0.0,
            0.0,
            0,
        )[1]

    def follow_ramp(
        self,
        h: float,
        n: int,
        pos: float,
        seg_t: float,
        seg_T: float,
        seg_to: float,
        seg_v: float,
        current_limit: float | None,
        block_negative: bool,
        block_positive: bool,
        fe_window: float | None,
        fe_timer: float,
        fe_timeout: float,
        inputs: int,
    ) -> tuple[int, int, int, float, float, float, float]:
        """Up to n sub-steps of `step(h, POSITION, ...)` following a linear position ramp.

        The demand moves at seg_v from `pos` until the ramp's time seg_T (then it holds
        seg_to); each sub-step controls on the demand at its start with the ramp speed as
        feed-forward, as the CSP fine interpolator does. `step` and this are the same loop
        (`_substeps`), so the CSP fast path computes what the drive's general sub-step
        computes, bit for bit (`tests/drives/test_fast_paths.py`), with the state in local
        variables for all n sub-steps: at 8 kHz per axis the attribute traffic of a call per
        sub-step was half the plant's cost.

        The loop also runs the monitors the drive checks every sub-step: the following error
        (`fe_window` rad for longer than `fe_timeout` s gives FOLLOWING_ERROR) and the switch
        inputs (`switch_inputs` bits). It stops after the first sub-step that ends with a
        fault or changed inputs. Returns (sub-steps done, fault or 0, inputs, demand
        position, demand velocity, ramp time, following-error timer).
        """
        if n <= 0:
            return 0, 0, inputs, pos, 0.0, seg_t, fe_timer
        return self._substeps(
            h,
            n,
            POSITION,
            pos,
            0.0,
            0.0,
            seg_t,
            seg_T,
            seg_to,
            seg_v,
            current_limit,
            block_negative,
            block_positive,
            fe_window,
            fe_timer,
            fe_timeout,
            inputs,
        )

    def _substeps(
        self,
        h: float,
        n: int,
        mode: int,
        pos: float,
        vel_ff: float,
        vel_demand: float,
        seg_t: float,
        seg_T: float,
        seg_to: float,
        seg_v: float,
        current_limit: float | None,
        block_negative: bool,
        block_positive: bool,
        fe_window: float | None,
        fe_timer: float,
        fe_timeout: float,
        inputs: int,
    ) -> tuple[int, int, int, float, float, float, float]:
        """The plant's physics, written once: up to n sub-steps of h seconds in `mode`.

        The position demand starts at `pos`; while the ramp time seg_t is below seg_T it
        moves at seg_v (feed-forward seg_v) and lands on seg_to, then it holds with
        feed-forward vel_ff (`step`: seg_t = seg_T = 0, a demand held for its one sub-step).
        VELOCITY mode commands vel_demand. Stops after the first sub-step that ends with a
        fault or changed switch inputs; returns what `follow_ramp` returns.
        """
        c = self._k
        res, kb, km = c.resistance, c.kb, c.km
        kv, kff = c.kv, c.velocity_feedforward
        ipk, itrip = c.peak_current, c.overcurrent_trip
        visc, coul, load_arm, j = c.viscous, c.coulomb_torque, c.load_arm, c.inertia
        mpr, rpc = c.metres_per_rad, c.rad_per_count
        cap, g_bleed, g_chop, g_src = c.capacitance, c.g_bleed, c.g_chopper, c.g_source
        chop_on, chop_off = c.chopper_on, c.chopper_off
        ov_trip, uv_trip, loss_detect = c.overvoltage_trip, c.undervoltage_trip, c.mains_loss
        c_th, r_th, temp_trip = c.thermal_capacity, c.thermal_resistance, c.temperature_trip
        ir2, blocked_time, blocked_speed = c.rated_current_sq, c.blocked_time, c.blocked_speed
        if h != self._h_cached:
            self._h_cached = h
            self._decay = math.exp(-h * res / c.inductance)
        a = self._decay
        one_minus_a = 1.0 - a
        vmax = self.speed_limit
        ilim = ipk if current_limit is None or current_limit > ipk else current_limit
        kp_v, ki_v = self.kp_v, self.ki_v
        # the injections hold for the whole call
        load = self.load_force * load_arm
        tc = coul + 1.0e3 if self.blocked else coul
        inverter_fault = self.inverter_fault
        noisy = self.encoder_noise > 0.0
        chopper_failed = self.chopper_failed
        supply_on = self.supply_on
        mains = self.mains_voltage
        ambient = self.ambient
        backlash = self.backlash
        half = 0.5 * backlash
        nut_origin = self._nut_origin
        stop_lo, stop_hi = self._stop_lo, self._stop_hi
        encoder_offset = self.encoder_offset
        jump = c.max_counts_per_s * h + 2
        k = h / cap
        i2t_limit = self._i2t_limit
        has_neg, neg, has_pos, posl = self._has_neg, self._neg, self._has_pos, self._pos
        has_home, home_x, home_below = self._has_home, self._home, self._home_below
        powered = mode != OFF  # the inverter switches (else the motor coasts)
        position_control = mode == POSITION
        # the optional window as a flag and a float: the loop compares plain floats
        check_fe = fe_window is not None
        fe_win = fe_window if fe_window is not None else 0.0
        # the state, in locals for the loop and written back once
        theta, omega, i_old = self.theta, self.omega, self.current
        integ, vel_m, counts = self.vel_integral, self.vel_meas, self.counts
        prev_counts, table_x, chopper = self._prev_counts, self.table_x, self.chopper
        vdc, temp, i2t = self.vdc, self.winding_temp, self.i2t
        mains_lost_for, blocked_for = self.mains_lost_for, self.blocked_for
        v_app = self.voltage
        current_limited = velocity_limited = False
        vel = 0.0
        fault = ENCODER if self.encoder_broken else 0
        new_inputs = inputs
        done = 0
        while done < n:
            done += 1
            # --- the demand at the start of the sub-step (the fine interpolation of the
            # ramp moves it to the end)
            pos_now = pos
            if seg_t < seg_T:
                seg_t += h
                if seg_t >= seg_T:
                    pos, vel = seg_to, seg_v
                else:
                    pos += seg_v * h
                    vel = seg_v
            else:
                vel = vel_ff

            # --- feedback: the encoder was read at the end of the previous sub-step
            theta_m = counts * rpc
            vel_read = vel_m

            # --- velocity and current loops
            current_limited = velocity_limited = False
            if not powered or fault:
                v_app = 0.0
                i_new = 0.0  # freewheel diodes clear the winding current within the sub-step
                integ = 0.0
            else:
                if position_control:
                    v_cmd = kv * (pos_now - theta_m) + kff * vel
                else:
                    v_cmd = vel_demand
                if v_cmd > vmax:
                    v_cmd, velocity_limited = vmax, True
                elif v_cmd < -vmax:
                    v_cmd, velocity_limited = -vmax, True
                if block_negative and v_cmd < 0.0:
                    v_cmd, velocity_limited = 0.0, True
                if block_positive and v_cmd > 0.0:
                    v_cmd, velocity_limited = 0.0, True
                err = v_cmd - vel_read
                i_cmd = kp_v * err + integ
                if i_cmd > ilim:
                    i_cmd, current_limited = ilim, True
                    if err < 0.0:
                        integ += ki_v * err * h
                elif i_cmd < -ilim:
                    i_cmd, current_limited = -ilim, True
                    if err > 0.0:
                        integ += ki_v * err * h
                else:
                    integ += ki_v * err * h
                # deadbeat: the voltage that brings I to i_cmd at the end of the sub-step
                v_app = res * (i_cmd - a * i_old) / one_minus_a + kb * omega
                if inverter_fault:
                    v_app = vdc  # a shorted switch: full link voltage, current runs away
                elif v_app > vdc:
                    v_app = vdc
                elif v_app < -vdc:
                    v_app = -vdc
                i_ss = (v_app - kb * omega) / res
                i_new = i_ss + (i_old - i_ss) * a
            i_avg = 0.5 * (i_old + i_new)

            # --- mechanics (semi-implicit Euler with stiction)
            net = km * i_avg + load - visc * omega
            if omega == 0.0:
                if -tc <= net <= tc:
                    w_new = 0.0
                else:
                    w_new = h * (net - math.copysign(tc, net)) / j
            else:
                w_new = omega + h * (net - math.copysign(tc, omega)) / j
                if w_new * omega < 0.0:
                    w_new = 0.0
            theta = theta + 0.5 * (omega + w_new) * h
            omega = w_new
            nut = nut_origin + theta * mpr
            if backlash > 0.0:
                if table_x < nut - half:
                    table_x = nut - half
                elif table_x > nut + half:
                    table_x = nut + half
            else:
                table_x = nut
            # The hard stop: an inelastic impact, table, screw and motor stop at it (only an
            # external force with the power stage off gets there: the drive lets no demand
            # move further into an active limit switch)
            if table_x > stop_hi or table_x < stop_lo:
                edge = stop_hi if table_x > stop_hi else stop_lo
                theta += (edge - table_x) / mpr
                omega = 0.0
                table_x = edge

            # --- encoder read at the end of the sub-step; speed from the count difference
            counts = math.floor(theta / rpc) + encoder_offset
            if noisy:
                counts += self._noise_counts()
            dc = counts - prev_counts
            if dc > jump or -dc > jump:
                fault = ENCODER  # implausible jump between two reads
            prev_counts = counts
            vel_m = dc * rpc / h

            # --- DC link (implicit in the conductances): C·dV/dt = I_src − I_inv − V·g
            i_inv = v_app * i_avg / vdc if vdc > 1.0 else 0.0
            if chopper_failed:
                chopper = False
            elif vdc >= chop_on:
                chopper = True
            elif vdc <= chop_off:
                chopper = False
            g = g_bleed + g_chop if chopper else g_bleed
            v_new = (vdc - k * i_inv) / (1.0 + k * g)
            if supply_on and v_new < mains:
                v_new = (vdc + k * (mains * g_src - i_inv)) / (1.0 + k * (g + g_src))
                if v_new > mains:
                    v_new = mains
            vdc = v_new if v_new > 0.0 else 0.0

            # --- thermal and I²t
            temp += h * (i_avg * i_avg * res - (temp - ambient) / r_th) / c_th
            i2t = i2t + (i_new * i_new - ir2) * h
            if not i2t > 0.0:
                i2t = 0.0
            i_old = i_new

            # --- plant monitors (first detected wins; checked every sub-step)
            if not fault:
                if i_new > itrip or i_new < -itrip:
                    fault = OVERCURRENT
                elif vdc > ov_trip:
                    fault = DC_OVERVOLTAGE
                elif powered and vdc < uv_trip:
                    fault = DC_UNDERVOLTAGE
                else:
                    if powered:
                        mains_lost_for = 0.0 if supply_on else mains_lost_for + h
                        if mains_lost_for > loss_detect:
                            fault = MAINS_PHASE_FAILURE
                        elif current_limited and -blocked_speed < vel_read < blocked_speed:
                            blocked_for += h
                            if blocked_for > blocked_time:
                                fault = MOTOR_BLOCKED
                        else:
                            blocked_for = 0.0
                    if not fault:
                        if i2t > i2t_limit:
                            fault = I2T
                        elif temp > temp_trip:
                            fault = OVERTEMPERATURE

            # --- the drive's monitors: following error, then the switch inputs
            if check_fe and abs(pos - counts * rpc) > fe_win:
                fe_timer += h
                if fe_timer > fe_timeout and not fault:
                    fault = FOLLOWING_ERROR
            else:
                fe_timer = 0.0
            new_inputs = 0
            if has_neg and table_x <= neg:
                new_inputs = 1
            if has_pos and table_x >= posl:
                new_inputs |= 2
            if has_home and (table_x <= home_x if home_below else table_x >= home_x):
                new_inputs |= 4
            if fault or new_inputs != inputs:
                break
        self.theta, self.omega, self.current, self.voltage = theta, omega, i_old, v_app
        self.vel_integral, self.vel_meas, self.counts = integ, vel_m, counts
        self._prev_counts, self.table_x, self.chopper = prev_counts, table_x, chopper
        self.vdc, self.winding_temp, self.i2t = vdc, temp, i2t
        self.mains_lost_for, self.blocked_for = mains_lost_for, blocked_for
        self.current_limited, self.velocity_limited = current_limited, velocity_limited
        return done, fault, new_inputs, pos, vel, seg_t, fe_timer

    @property
    def i2t_limit(self) -> float:
        return self._i2t_limit

    @property
    def warnings(self) -> bool:
        """True while a warning threshold (temperature, I²t) is exceeded."""
        th = self.params.thermal
        return self.winding_temp > th.warning or self.i2t > th.i2t_warning_fraction * self.i2t_limit

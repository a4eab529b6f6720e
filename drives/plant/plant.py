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
"""

from __future__ import annotations

import math

from drives.plant.params import PlantParams

# Control modes of the inner loops.
OFF = 0  # inverter disabled, motor coasts
POSITION = 1  # position P (+ feed-forward) → velocity PI → current
VELOCITY = 2  # velocity PI → current

# Fault codes the plant detects (CiA 402 / IEC 61800-7 numbering).
OVERCURRENT = 0x2310
I2T = 0x2350
MAINS_PHASE_FAILURE = 0x3130
DC_OVERVOLTAGE = 0x3210
DC_UNDERVOLTAGE = 0x3220
OVERTEMPERATURE = 0x4310
MOTOR_BLOCKED = 0x7121
ENCODER = 0x7305

_TWO_PI = 2.0 * math.pi


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
        # injections
        self.load_force = 0.0  # N on the table, + pushes toward +x
        self.blocked = False
        self.chopper_failed = False
        self.supply_on = True
        self.mains_voltage = p.dc_link.mains_voltage
        self.inverter_fault = False
        self.encoder_broken = False
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

    # -- one sub-step ---------------------------------------------------------------------
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
        p = self.params
        m = p.motor
        if h != self._h_cached:
            self._h_cached = h
            self._decay = math.exp(-h * m.resistance / m.inductance)
        a = self._decay
        fault = 0

        # --- feedback: the encoder was read at the end of the previous sub-step
        theta_m = self.counts * self._rad_per_count
        vel_m = self.vel_meas
        if self.encoder_broken:
            fault = ENCODER

        # --- velocity and current loops
        omega = self.omega
        i_old = self.current
        vdc = self.vdc
        self.current_limited = self.velocity_limited = False
        if mode == OFF or fault:
            v_app = 0.0
            i_new = 0.0  # freewheel diodes clear the winding current within the sub-step
            self.vel_integral = 0.0
        else:
            if mode == POSITION:
                v_cmd = p.loops.kv * (pos_demand - theta_m) + p.loops.velocity_feedforward * vel_ff
            else:
                v_cmd = vel_demand
            vmax = m.max_speed_rpm * _TWO_PI / 60.0
            if v_cmd > vmax:
                v_cmd, self.velocity_limited = vmax, True
            elif v_cmd < -vmax:
                v_cmd, self.velocity_limited = -vmax, True
            if block_negative and v_cmd < 0.0:
                v_cmd, self.velocity_limited = 0.0, True
            if block_positive and v_cmd > 0.0:
                v_cmd, self.velocity_limited = 0.0, True
            err = v_cmd - vel_m
            ilim = m.peak_current if current_limit is None else min(current_limit, m.peak_current)
            i_cmd = self.kp_v * err + self.vel_integral
            if i_cmd > ilim:
                i_cmd, self.current_limited = ilim, True
                if err < 0.0:
                    self.vel_integral += self.ki_v * err * h
            elif i_cmd < -ilim:
                i_cmd, self.current_limited = -ilim, True
                if err > 0.0:
                    self.vel_integral += self.ki_v * err * h
            else:
                self.vel_integral += self.ki_v * err * h
            # deadbeat: the voltage that brings I to i_cmd at the end of the sub-step
            v_app = m.resistance * (i_cmd - a * i_old) / (1.0 - a) + m.kb * omega
            if self.inverter_fault:
                v_app = vdc  # a shorted switch: full link voltage, current runs away
            elif v_app > vdc:
                v_app = vdc
            elif v_app < -vdc:
                v_app = -vdc
            i_ss = (v_app - m.kb * omega) / m.resistance
            i_new = i_ss + (i_old - i_ss) * a
        i_avg = 0.5 * (i_old + i_new)
        self.current = i_new
        self.voltage = v_app

        # --- mechanics (semi-implicit Euler with stiction)
        sc = p.screw
        t_ext = self.load_force * self._mpr / sc.efficiency
        net = m.km * i_avg + t_ext - sc.viscous * omega
        tc = sc.coulomb_torque + (1.0e3 if self.blocked else 0.0)
        j = self.inertia
        if omega == 0.0:
            if abs(net) <= tc:
                w_new = 0.0
            else:
                w_new = h * (net - math.copysign(tc, net)) / j
        else:
            w_new = omega + h * (net - math.copysign(tc, omega)) / j
            if w_new * omega < 0.0:
                w_new = 0.0
        self.theta += 0.5 * (omega + w_new) * h
        self.omega = w_new
        nut = self._nut_origin + self.theta * self._mpr
        b = self.backlash
        if b > 0.0:
            half = 0.5 * b
            if self.table_x < nut - half:
                self.table_x = nut - half
            elif self.table_x > nut + half:
                self.table_x = nut + half
        else:
            self.table_x = nut

        # --- encoder read at the end of the sub-step; speed from the count difference
        counts = math.floor(self.theta / self._rad_per_count) + self.encoder_offset
        dc = counts - self._prev_counts
        max_step = (
            p.encoder.max_speed_factor * m.max_speed_rpm * _TWO_PI / 60.0 * h / self._rad_per_count
        )
        if abs(dc) > max_step + 2:
            fault = ENCODER  # implausible jump between two reads
        self._prev_counts = counts
        self.counts = counts
        self.vel_meas = dc * self._rad_per_count / h

        # --- DC link (implicit in the conductances): C·dV/dt = I_src − I_inv − V·g
        dl = p.dc_link
        i_inv = v_app * i_avg / vdc if vdc > 1.0 else 0.0
        if self.chopper_failed:
            self.chopper = False
        elif vdc >= dl.chopper_on:
            self.chopper = True
        elif vdc <= dl.chopper_off:
            self.chopper = False
        g = 1.0 / dl.bleed_resistance + (1.0 / dl.chopper_resistance if self.chopper else 0.0)
        k = h / dl.capacitance
        v_new = (vdc - k * i_inv) / (1.0 + k * g)
        if self.supply_on and v_new < self.mains_voltage:
            gs = 1.0 / dl.source_resistance
            v_new = (vdc + k * (self.mains_voltage * gs - i_inv)) / (1.0 + k * (g + gs))
            v_new = min(v_new, self.mains_voltage)
        self.vdc = max(v_new, 0.0)

        # --- thermal and I²t
        th = p.thermal
        c_th = th.time_constant / th.thermal_resistance
        self.winding_temp += (
            h
            * (
                i_avg * i_avg * m.resistance
                - (self.winding_temp - self.ambient) / th.thermal_resistance
            )
            / c_th
        )
        self.i2t = max(0.0, self.i2t + (i_new * i_new - m.rated_current**2) * h)

        # --- plant monitors (first detected wins; checked every sub-step)
        if fault:
            return fault
        energized = mode != OFF
        if abs(i_new) > m.overcurrent_trip:
            return OVERCURRENT
        if self.vdc > dl.overvoltage_trip:
            return DC_OVERVOLTAGE
        if energized:
            if self.vdc < dl.undervoltage_trip:
                return DC_UNDERVOLTAGE
            self.mains_lost_for = 0.0 if self.supply_on else self.mains_lost_for + h
            if self.mains_lost_for > dl.mains_loss_detect:
                return MAINS_PHASE_FAILURE
            mo = p.monitor
            if self.current_limited and abs(vel_m) < mo.blocked_speed:
                self.blocked_for += h
                if self.blocked_for > mo.blocked_time:
                    return MOTOR_BLOCKED
            else:
                self.blocked_for = 0.0
        if self.i2t > self.i2t_limit:
            return I2T
        if self.winding_temp > th.trip:
            return OVERTEMPERATURE
        return 0

    @property
    def i2t_limit(self) -> float:
        m, th = self.params.motor, self.params.thermal
        return (m.peak_current**2 - m.rated_current**2) * th.i2t_peak_time

    @property
    def warnings(self) -> bool:
        """True while a warning threshold (temperature, I²t) is exceeded."""
        th = self.params.thermal
        return self.winding_temp > th.warning or self.i2t > th.i2t_warning_fraction * self.i2t_limit

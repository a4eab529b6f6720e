"""Plant parameters with realistic defaults: a 400 W servo on a 10 mm pitch ball screw.

All quantities are SI (m, kg, s, rad, A, V, N, N·m, K, F, Ω) unless the name says otherwise.
The defaults describe a typical 400 W AC servo (rated 1.27 N·m at 3000 rpm, 3× peak, 20-bit
encoder) driving a 16 mm × 10 mm ball screw, 0.6 m long, and a 30 kg table, fed from a
230 V AC mains rectifier (≈325 V DC link) with a brake chopper.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace


@dataclass(frozen=True, slots=True)
class MotorParams:
    """DC-equivalent servo motor: T = Km·I, V = Kb·ω + R·I + L·dI/dt."""

    km: float = 0.45  # torque constant, N·m/A
    kb: float = 0.45  # back-emf constant, V·s/rad (equal to km in SI)
    resistance: float = 1.2  # winding resistance, Ω
    inductance: float = 3.0e-3  # winding inductance, H
    inertia: float = 0.26e-4  # rotor inertia, kg·m²
    rated_current: float = 2.8  # A (continuous)
    peak_current: float = 8.4  # A (current-loop limit)
    overcurrent_trip: float = 11.0  # A, instantaneous hardware trip
    max_speed_rpm: float = 5000.0

    @property
    def rated_torque(self) -> float:
        return self.km * self.rated_current


@dataclass(frozen=True, slots=True)
class ScrewParams:
    """Ball screw, table and guideways."""

    lead: float = 0.010  # m per screw revolution
    diameter: float = 0.016  # m
    length: float = 0.6  # m
    density: float = 7850.0  # kg/m³ (steel)
    efficiency: float = 0.9  # forward efficiency η
    gear_ratio: float = 1.0  # motor revolutions per screw revolution
    table_mass: float = 30.0  # kg
    coulomb_torque: float = 0.04  # N·m at the motor (guide + nut preload drag)
    viscous: float = 1.0e-4  # N·m/(rad/s) at the motor
    backlash: float = 0.0  # m, total dead band between nut and table (0 = preloaded nut)

    @property
    def screw_inertia(self) -> float:
        r = self.diameter / 2.0
        return self.density * math.pi * r**4 * self.length / 2.0

    @property
    def reflected_inertia(self) -> float:
        """Screw plus table referred to the motor shaft: (J_s + m·h²/4π²)/i²."""
        j_table = self.table_mass * self.lead**2 / (4.0 * math.pi**2)
        return (self.screw_inertia + j_table) / self.gear_ratio**2


@dataclass(frozen=True, slots=True)
class LoopParams:
    """Cascaded loops inside the drive. Velocity loop runs every sub-step."""

    kv: float = 16.67  # position-loop gain, 1/s (1 (m/min)/mm)
    velocity_feedforward: float = 0.0  # 0..1; 0 gives the classical following error v/Kv
    velocity_bandwidth_hz: float = 150.0  # crossover used to derive the PI gains
    velocity_pi_corner_ratio: float = 0.25  # integral corner as a fraction of the crossover
    substep: float = 125e-6  # s, maximum integration sub-step (8 kHz loops)
    standstill_velocity: float = 0.5  # rad/s at the motor, "stopped" threshold


@dataclass(frozen=True, slots=True)
class EncoderParams:
    counts_per_rev: int = 1 << 20  # 20-bit single-turn
    index_angle: float = 0.5  # rad, motor angle of the index (zero) mark
    max_speed_factor: float = 1.5  # plausibility: |Δθ| per sub-step above this × max speed


@dataclass(frozen=True, slots=True)
class DcLinkParams:
    """Mains rectifier, DC-link capacitor, brake chopper and voltage monitors."""

    mains_voltage: float = 325.0  # V, rectified 230 V AC
    source_resistance: float = 1.5  # Ω, rectifier + mains impedance
    capacitance: float = 330e-6  # F
    bleed_resistance: float = 47e3  # Ω
    chopper_on: float = 380.0  # V
    chopper_off: float = 370.0  # V
    chopper_resistance: float = 100.0  # Ω
    overvoltage_trip: float = 420.0  # V → 0x3210
    undervoltage_trip: float = 200.0  # V → 0x3220 while the power stage is on
    voltage_present: float = 250.0  # V, statusword bit 4 and switch-on permitted above this
    mains_loss_detect: float = 0.020  # s, mains monitor (one 50 Hz period) → 0x3130


@dataclass(frozen=True, slots=True)
class ThermalParams:
    """First-order winding thermal model: C·dT/dt = R·I² − (T − T_amb)/R_th."""

    ambient: float = 40.0  # °C
    thermal_resistance: float = 8.5  # K/W (rated current → ≈80 K rise)
    time_constant: float = 600.0  # s
    warning: float = 130.0  # °C, statusword bit 7
    trip: float = 150.0  # °C → 0x4310
    i2t_peak_time: float = 2.0  # s at peak current before the I²t trip 0x2350
    i2t_warning_fraction: float = 0.8


@dataclass(frozen=True, slots=True)
class SwitchParams:
    """Switches on the table (table coordinates, m). None = not fitted."""

    negative_limit: float | None = -0.005  # active for x <= value
    positive_limit: float | None = 0.555  # active for x >= value
    home_switch: float | None = 0.010  # m, the dog's edge
    # True: active for x <= edge, a dog over the negative end (methods 5, 6, 21, 22);
    # False: active for x >= edge, a "positive home switch" (methods 3, 4, 19, 20)
    home_switch_active_below: bool = True
    initial_position: float = 0.200  # m, table position at power-on
    # the mechanical end of travel (hard stop), this far beyond each limit switch: a table
    # pushed on with the power stage off (an external force, no holding brake) stops there
    # instead of running off the screw
    end_stop_overtravel: float = 0.020  # m


@dataclass(frozen=True, slots=True)
class MonitorParams:
    blocked_time: float = 0.25  # s at the current limit with |ω| below blocked_speed → 0x7121
    blocked_speed: float = 2.0  # rad/s


@dataclass(frozen=True, slots=True)
class PlantParams:
    """Everything the physical plant and the inner loops need; override any field."""

    motor: MotorParams = field(default_factory=MotorParams)
    screw: ScrewParams = field(default_factory=ScrewParams)
    loops: LoopParams = field(default_factory=LoopParams)
    encoder: EncoderParams = field(default_factory=EncoderParams)
    dc_link: DcLinkParams = field(default_factory=DcLinkParams)
    thermal: ThermalParams = field(default_factory=ThermalParams)
    switches: SwitchParams = field(default_factory=SwitchParams)
    monitor: MonitorParams = field(default_factory=MonitorParams)

    @property
    def total_inertia(self) -> float:
        return self.motor.inertia + self.screw.reflected_inertia

    @property
    def metres_per_motor_rad(self) -> float:
        return self.screw.lead / (2.0 * math.pi * self.screw.gear_ratio)

    def for_substep(self, substep: float) -> PlantParams:
        """Copy integrating at `substep` seconds, with the velocity-loop crossover lowered to
        at most 1/(20·substep) Hz so that the discrete loops stay well damped (1 ms → 50 Hz).
        A coarse sub-step trades loop stiffness for speed when many axes must run faster than
        real time; the Kv following-error law still holds."""
        bandwidth = min(self.loops.velocity_bandwidth_hz, 0.05 / substep)
        return self.with_(loops={"substep": substep, "velocity_bandwidth_hz": bandwidth})

    def with_(self, **groups: dict) -> PlantParams:
        """Copy with some fields of some groups replaced: `p.with_(loops={"kv": 30})`."""
        changes = {name: replace(getattr(self, name), **vals) for name, vals in groups.items()}
        return replace(self, **changes)

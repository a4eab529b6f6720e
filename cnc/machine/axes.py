"""Axis layers for the machine: CiA 402 drives on a simulated CAN bus, or ideal axes.

Both have the same two calls, once per IPO cycle: `feedback()` (what the NC sees this cycle)
and `apply(outputs, dt)` (the controller's axis command, then its targets for one cycle).

`CanopenAxes` is the real thing: one lockstep `CanHub` per machine, one `VirtualDrive` per
axis, the `drives.master.AxisGroup` as the CANopen master. Machine coordinates (mm) are the
drives' position actual 0x6064 at 1 um per unit; homing (method 19, a dog at the positive end
of travel, search then creep) sets 0x6064 = home_mm at the dog's edge, as the NC book's
reference point approach does. The sequences the group runs as blocking calls (enable,
homing, fault reset, disable) advance the same virtual clock: `apply` returns how long the
sequence took so the machine can let the PLC catch up.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TextIO

from cnc.controller import AxisFeedback
from cnc.controller import IdealAxes as _ControllerIdealAxes

HOMING_METHOD = 19  # falling edge of a positive home switch (dog active above its edge)
VELOCITY_FEEDFORWARD = 1.0  # unless drives.plant.loops.velocity_feedforward says otherwise
HOME_DOG_BEFORE_M = 0.030  # power-on position: this far below the dog (m, table coordinates)
# Communication monitoring on the machine's bus (docs/recovery.md): each drive faults when
# its RPDO stops for 50 ms (0x1400:5, EMCY 0x8250), the master reports an axis whose TPDO1
# is missing for 5 consecutive SYNC cycles (lost, destroyed or late: 0x8100)
MONITORING = {"rpdo_deadline_ms": 50, "feedback_timeout_cycles": 5}


# EMCY codes the ideal axes report for the drive fault kinds (what the real drive would send)
_IDEAL_CODES = {
    "encoder_break": 0x7305,
    "encoder_jump": 0x7305,
    "inverter_fault": 0x2310,
    "supply_loss": 0x3130,
    "mains_voltage": 0x3220,
    "chopper_failure": 0x3210,
    "blocked": 0x8611,
    "load_force": 0x8611,
    "ambient_temperature": 0x4310,
    "winding_temperature": 0x4310,
    "power_cycle": 0x0000,
}


class IdealAxes(_ControllerIdealAxes):
    """The controller's ideal axes (no drives, no bus) with the machine's axis-layer extras:
    drive faults by spec (reported with the code the real drive would send), no bus load."""

    bus_load = None

    def __init__(self, config, **kwargs) -> None:
        super().__init__(config, **kwargs)
        self.active_faults: tuple = ()

    def apply(self, outputs, dt: float) -> float:
        super().apply(outputs, dt)
        if outputs.axis_command == "fault_reset":
            self.active_faults = ()
        return 0.0

    def inject(self, spec) -> None:
        code = _IDEAL_CODES.get(spec.kind)
        if spec.target == "bus" or code is None:
            raise ValueError(
                f"fault {spec}: not modelled on ideal axes (no CAN bus, no plant); run the"
                " machine with its CANopen drives"
            )
        text = f"{spec.kind} (injected)"
        lose = spec.kind in ("encoder_break", "encoder_jump", "power_cycle")
        self.inject_fault(spec.axis, code, text, lose_reference=lose)
        self.active_faults = (*self.active_faults, (spec.axis, code, text))

    def clear(self, spec) -> None:
        self.active_faults = tuple(f for f in self.active_faults if f[0] != spec.axis)

    def close(self) -> None:
        pass


class CanopenAxes:
    """Virtual CiA 402 drives on the machine's own lockstep CAN hub, driven by an AxisGroup."""

    def __init__(
        self,
        config,
        name: str = "machine",
        *,
        candump: TextIO | None = None,
        substep: float | None = None,
    ) -> None:
        # deferred: python-can and canopen load only for CiA 402 axes (ideal axes and
        # `import cnc.machine` run without them)
        from drives.bus.hub import CanHub
        from drives.bus.loadplan import BusOverloadError
        from drives.faults import FaultInjector
        from drives.master import AxisConfig, AxisGroup
        from drives.virtual_drive import VirtualDrive

        self.names = tuple(config.axes)
        self.ipo_s = config.ipo_cycle_ms / 1000.0
        channel = config.can.channel or name
        # one lockstep hub per CAN line (`drives.axes.<AXIS>.line`; line 0 is the machine's
        # channel, line k its channel + ".k"): five axes at a 1 ms SYNC need two lines
        n_lines = 1 + max((config.drives.line(axis) for axis in config.axes), default=0)
        self.hubs = [
            CanHub(
                config.can.bitrate,
                mode="lockstep",
                channel=channel if k == 0 else f"{channel}.{k}",
                log=candump,
            )
            for k in range(n_lines)
        ]
        self.hub = self.hubs[0]
        self.drives: dict[str, VirtualDrive] = {}
        axes = []
        for i, (axis, a) in enumerate(config.axes.items()):
            node = config.drives.node_id(axis, i)
            line = config.drives.line(axis)
            groups = _plant_groups(a, config.drives.plant_overrides(axis))
            kwargs = {"substep": substep} if substep is not None else {}
            self.drives[axis] = VirtualDrive(
                node,
                self.hubs[line].endpoint(f"drive-{axis}"),
                name=f"{name}.{axis}",
                **kwargs,
                **groups,
            )
            axes.append(
                AxisConfig(
                    axis,
                    node,
                    max_velocity_mm_s=a.max_velocity / 60.0,
                    max_accel_mm_s2=a.max_accel,
                    quick_stop_decel_mm_s2=a.max_accel,
                    homing_method=HOMING_METHOD,
                    home_offset_mm=a.home_mm,
                    homing_search_mm_s=50.0,
                    homing_creep_mm_s=5.0,
                    homing_accel_mm_s2=min(a.max_accel, 1000.0),
                    homing_timeout_s=60.0,
                    line=line,
                )
            )
        try:
            masters = [hub.endpoint("master") for hub in self.hubs]
            self.master_bus = masters if len(masters) > 1 else masters[0]
            self.following_error_mapped = True
            self.group = AxisGroup(
                self.master_bus,
                axes,
                ipo_cycle_s=self.ipo_s,
                master_node_id=127,
                following_error_every=1,
                **MONITORING,
            )
            try:
                self.group.plan()
            except BusOverloadError:
                # no room for the drives' following error (TPDO2) at this SYNC rate: the NC
                # computes it from commanded - actual; a plan that still overloads is refused
                self.group.close()
                self.following_error_mapped = False
                self.group = AxisGroup(
                    self.master_bus,
                    axes,
                    ipo_cycle_s=self.ipo_s,
                    master_node_id=127,
                    following_error_every=0,
                    **MONITORING,
                )
            self.injector = FaultInjector(self.drives)
            self.group.boot()
            self.group.configure()
        except Exception:
            # a refused configuration (bus overload, a drive that does not boot) leaves
            # nothing attached behind it
            for vd in self.drives.values():
                vd.close()
            for hub in self.hubs:
                for endpoint in list(hub.endpoints):
                    endpoint.shutdown()
            raise
        self.homed = dict.fromkeys(self.names, False)
        self.homing = False
        self.enabled = False
        self._fresh: tuple = ()  # faults reported in the last cycle (axis, code, text)
        self._fb = self.group.cycle()
        self.errors: list[str] = []  # sequences the group refused (AxisError text)

    @property
    def time(self) -> float:
        return self.group.time

    @property
    def bus_load(self):
        """The load account of the busiest CAN line (by mean load)."""
        if len(self.hubs) == 1:
            return self.hub.load
        return max((hub.load for hub in self.hubs), key=lambda load: load.mean)

    def feedback(self) -> AxisFeedback:
        fb = self._fb
        return AxisFeedback(
            actual=dict(fb.position_mm),
            # an axis left out: the NC computes its following error from commanded - actual
            following_error={n: v for n, v in fb.following_error_mm.items() if v is not None},
            enabled=self.enabled and all(s == "OPERATION ENABLED" for s in fb.state.values()),
            homed=dict(self.homed),
            homing=self.homing,
            faults=self._fresh,
        )

    @property
    def active_faults(self) -> tuple:
        """Faults active on the drives now, (axis, EMCY code, text)."""
        return tuple((f.axis, f.emcy_code, f.text) for f in self.group.faults)

    def _note_faults(self, new) -> None:
        for f in new:
            # an incremental encoder loses its reference when its drive reboots or its
            # encoder signal breaks
            if f.source == "bootup" or f.emcy_code == 0x7305:
                self.homed[f.axis] = False
            self._fresh += ((f.axis, f.emcy_code, f.text),)

    def apply(self, outputs, dt: float) -> float:
        """Run the axis command (if any) and one IPO cycle; return extra virtual seconds a
        blocking drive sequence took (0 for an ordinary cycle)."""
        from drives.master import AxisError  # deferred: as in __init__ (canopen)

        cmd = outputs.axis_command
        t0 = self.group.time
        self._fresh = ()
        if cmd != "none":
            try:
                self._command(cmd, outputs.home_axes)
            except AxisError as exc:
                self.errors.append(str(exc))
                for axis in exc.axes or self.names[:1]:
                    self._fresh += ((axis, 0, f"drive sequence {cmd}: {exc}"),)
            self._note_faults(self.group.take_faults())
        targets = {n: v for n, v in outputs.targets.items() if n in self.drives}
        if cmd == "home":
            # the controller computed this cycle's targets before the homing ran: for the
            # axes just homed they are positions in the old (unreferenced) frame, a jump of
            # up to the whole travel; those axes hold where homing left them
            for n in outputs.home_axes or self.names:
                targets.pop(n, None)
        for n, v in targets.items():
            if not math.isfinite(v):
                raise ValueError(f"axis {n}: target {v!r} is not finite")
        self._fb = self.group.cycle(targets if self.enabled else None)
        self._note_faults(self._fb.faults)
        return max(0.0, self.group.time - t0 - self.ipo_s)

    def _command(self, cmd: str, home_axes: tuple[str, ...]) -> None:
        g = self.group
        if cmd == "enable":
            g.enable()
            self.enabled = True
        elif cmd == "disable":
            self.enabled = False
            g.disable()
        elif cmd == "quick_stop":
            self.enabled = False
            g.quick_stop()
            # an E-stop drops the incremental encoders' reference (the NC book, section 8)
            self.homed = dict.fromkeys(self.names, False)
        elif cmd == "fault_reset":
            g.fault_reset()
        elif cmd == "home":
            axes = tuple(home_axes) or self.names
            self.homing = True
            try:
                g.home(axes)
            finally:
                self.homing = False
            for n in axes:
                self.homed[n] = True

    def inject(self, spec) -> None:
        """Apply a drive/bus/node fault spec (`cnc.machine.faults.FaultSpec`)."""
        self.injector.inject(spec.axis, spec.kind, **spec.params)

    def clear(self, spec) -> None:
        self.injector.clear(spec.axis, spec.kind)

    def close(self) -> None:
        self.group.close()
        for vd in self.drives.values():
            vd.close()
        for hub in self.hubs:
            for endpoint in list(hub.endpoints):
                endpoint.shutdown()
            hub.close()


def _plant_groups(axis, overrides: Mapping[str, Mapping]) -> dict[str, dict]:
    """Plant overrides plus the switch layout that puts machine coordinates on the table.

    Table coordinate 0 m is the negative end of travel (min_mm); the home dog's edge sits at
    home_mm, active above it; limit switches 5 mm beyond each end of travel; at power-on the
    table stands a little below the dog, so homing is short.
    """
    span_m = (axis.max_mm - axis.min_mm) / 1000.0
    dog_m = (axis.home_mm - axis.min_mm) / 1000.0
    # a rotary axis' plant is the same servo on a worm-geared table: one plant mm is one
    # table degree; an endless (continuous) one has no limit switches
    endless = getattr(axis, "continuous", False)
    switches = {
        "negative_limit": None if endless else -0.005,
        "positive_limit": None if endless else span_m + 0.005,
        "home_switch": dog_m,
        "home_switch_active_below": False,
        "initial_position": max(0.0, dog_m - HOME_DOG_BEFORE_M),
    }
    groups = {g: dict(v) for g, v in overrides.items()}
    groups["switches"] = {**switches, **groups.get("switches", {})}
    # machine-tool drives run with velocity feed-forward: the following error is then the
    # transport delay and the acceleration lag, not v/Kv (30 mm at a 30 m/min rapid)
    groups.setdefault("loops", {}).setdefault("velocity_feedforward", VELOCITY_FEEDFORWARD)
    screw = groups.setdefault("screw", {})
    screw.setdefault("length", max(0.6, span_m + 0.1))
    return groups

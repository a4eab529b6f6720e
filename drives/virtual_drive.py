"""VirtualDrive: one simulated CiA 402 servo axis (CiA 301 slave + Drive402) on a CAN bus.

The drive is a CANopen node on any python-can bus: the project's `SimBus` (lockstep or
realtime `CanHub`), python-can's in-process `virtual` interface, or a real SocketCAN
interface. Under a lockstep hub it is a clocked participant (the hub's `advance(dt)` moves
its plant); otherwise `start()` serves it in realtime, integrating the plant from the wall
clock at a fixed tick.
"""

from __future__ import annotations

from typing import Any

import can

from drives import EDS_PATH
from drives.bus.hub import SimBus
from drives.cia301 import CanopenSlave
from drives.cia402 import Drive402
from drives.plant import PlantParams

#: PlantParams groups a VirtualDrive accepts as keyword overrides (`loops={"kv": 30.0}`).
PLANT_GROUPS = ("motor", "screw", "loops", "encoder", "dc_link", "thermal", "switches", "monitor")


def build_params(
    plant: PlantParams | None = None, substep: float | None = None, **groups: dict
) -> PlantParams:
    """PlantParams from a base, optional coarse `substep` and group overrides.

    Raises ValueError naming an unknown group or field (config errors must say where).
    """
    params = plant or PlantParams()
    unknown = set(groups) - set(PLANT_GROUPS)
    if unknown:
        raise ValueError(
            f"VirtualDrive: unknown parameter group(s) {sorted(unknown)}; "
            f"allowed: {', '.join(PLANT_GROUPS)}, objects, substep, plant"
        )
    for name, values in groups.items():
        if not isinstance(values, dict):
            raise ValueError(f"VirtualDrive: {name} must be a dict of fields, got {values!r}")
        fields = set(type(getattr(params, name)).__dataclass_fields__)
        bad = set(values) - fields
        if bad:
            raise ValueError(
                f"VirtualDrive: unknown field(s) {sorted(bad)} in {name}; allowed {sorted(fields)}"
            )
    if groups:
        params = params.with_(**groups)
    if substep is not None:
        if not substep > 0:
            raise ValueError(f"VirtualDrive: substep must be > 0 s, got {substep!r}")
        params = params.for_substep(substep)
    return params


class VirtualDrive:
    """A virtual CiA 402 servo drive attached to a python-can bus as CANopen node `node_id`.

    Parameters
    ----------
    node_id:
        CANopen node-ID 1..127.
    bus:
        Any python-can bus. On a `SimBus` the drive attaches to its hub (lockstep: the hub's
        `advance` clocks it; realtime: `start()` starts the hub). On another bus `start()`
        runs a receive-and-tick thread.
    plant:
        Base `PlantParams` (default: 400 W servo on a 10 mm lead screw, see docs/cia402.md).
    substep:
        Plant integration sub-step in seconds; sets `PlantParams.for_substep(substep)` (e.g.
        1e-3 for many axes faster than real time). Default: the plant's 125 us.
    objects:
        Initial CiA 402 object values, `{0x6065: 5000, (0x6099, 1): 20000}`, validated like
        SDO writes; they are also what NMT reset node returns to.
    eds_path, boot:
        Passed to `CanopenSlave` (boot=True sends the boot-up frame now).
    tick_s:
        Realtime tick of `start()` on a plain python-can bus (default 1 ms).
    **groups:
        PlantParams group overrides: `motor`, `screw`, `loops`, `encoder`, `dc_link`,
        `thermal`, `switches`, `monitor`, each a dict of fields, e.g.
        `switches={"initial_position": 0.1}, loops={"velocity_feedforward": 1.0}`.

    NMT reset node reboots the drive (`Drive402.power_on_reset()`: objects back to their
    defaults and `objects`, incremental position lost); reset communication leaves it alone.
    """

    def __init__(
        self,
        node_id: int,
        bus: can.BusABC,
        *,
        plant: PlantParams | None = None,
        substep: float | None = None,
        objects: dict[int | tuple[int, int], int] | None = None,
        eds_path: str = EDS_PATH,
        boot: bool = True,
        tick_s: float = 0.001,
        name: str = "",
        **groups: Any,
    ) -> None:
        if not tick_s > 0:
            raise ValueError(f"VirtualDrive: tick_s must be > 0, got {tick_s!r}")
        self.node_id = node_id
        self.bus = bus
        self.name = name or f"node{node_id}"
        self.tick_s = tick_s
        self.drive = Drive402(build_params(plant, substep, **groups), objects)
        # CanopenSlave calls Drive402.on_nmt_reset("node") -> power_on_reset() on reset node.
        self.slave = CanopenSlave(node_id, bus, self.drive, eds_path=eds_path, boot=boot)
        self._started = False

    # ------------------------------------------------------------------ realtime shell
    def start(self) -> VirtualDrive:
        """Serve in realtime (plant integrated from the wall clock). Returns self.

        Refused on a lockstep hub: there the hub's owner moves time with `hub.advance(dt)`.
        """
        self.slave.start(self.tick_s)
        self._started = True
        return self

    def stop(self) -> None:
        """Stop serving (realtime). A realtime hub keeps running for its other nodes."""
        if self._started and not isinstance(self.bus, SimBus):
            self.slave.stop()
        self._started = False

    def close(self) -> None:
        """Stop, and detach from a simulated hub (no more frames, no more ticks)."""
        self.stop()
        if isinstance(self.bus, SimBus):
            self.bus.hub.remove_clocked(self.slave)
            self.bus.remove_listener(self.slave.handle)

    def __enter__(self) -> VirtualDrive:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ faults and power
    def inject(self, kind: str, **params: float) -> None:
        """Physical fault (kinds in `drives.cia402.INJECT_KINDS`); see drives.faults for all."""
        with self.slave._lock:
            self.drive.inject(kind, **params)

    def clear_injection(self, kind: str) -> None:
        with self.slave._lock:
            self.drive.clear_injection(kind)

    def power_cycle(self) -> None:
        """Switch the drive off and on: power-on reset of the application, then boot-up."""
        with self.slave._lock:
            self.slave.reset_node()

    # ------------------------------------------------------------------ observation
    @property
    def nmt_state(self) -> str:
        return self.slave.state.label

    @property
    def state_name(self) -> str:
        """CiA 402 power state, e.g. 'OPERATION ENABLED'."""
        return self.drive.state_name

    @property
    def statusword(self) -> int:
        return self.drive.statusword

    @property
    def position_actual(self) -> int:
        """0x6064 in user units (1 um by default)."""
        return self.drive.position_actual

    @property
    def table_position_m(self) -> float:
        """The true table position in metres (not what the encoder says)."""
        return self.drive.plant.table_x

    def __repr__(self) -> str:
        return f"VirtualDrive({self.node_id}, {self.name!r}, {self.nmt_state}, {self.state_name})"

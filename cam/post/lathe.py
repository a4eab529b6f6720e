"""The 2-axis lathe post (kind `lathe`, Fanuc lathe dialect, G-code system A).

The turned profile is programmed in the XZ plane of the CL frame: x is the distance from
the spindle axis (radius), z runs along the spindle axis, y must be 0. X words are
diameters when the machine programs diameters (`lathe_diameter_mode`); arc centres I/K are
radius values; arcs are about the Y axis (G18). A turret has no M06: `LOADTL/n` is
`T<nn><nn>` (tool n with its offset n). Feed per minute is G98, per revolution G99;
spindle speeds go with G97 (constant RPM). System A has no G90/G91 (G90 is the turning
cycle), so the unit block is `G20|G21 G18`.
"""

from __future__ import annotations

from cam.cl import ClRecord
from cam.post.base import FanucPost

Y_TOLERANCE = 1e-9


class LathePost(FanucPost):
    kind = "lathe"
    name = "fanuc-lathe"
    axes = ("X", "Z")
    header_feed_mode = None  # power-on G99: the first feed says which

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.plane_out = "G18"  # the unit block selects it

    @property
    def diameter(self) -> bool:
        return bool(getattr(self.machine.config, "lathe_diameter_mode", True))

    def unit_block(self) -> str:
        return ("G20" if self.units == "INCHES" else "G21") + " G18"

    def tool_change(self, tool: int, rec: ClRecord) -> str:
        if tool > 99:
            raise self.err(f"turret station {tool} beyond T99", rec)
        return f"T{tool:02d}{tool:02d}"

    def feed_mode_code(self, per_rev: bool) -> str:
        return "G99" if per_rev else "G98"

    def speed_prefix(self) -> str:
        return "G97 "

    def comp_register(self, rec: ClRecord) -> str:
        return ""  # the nose radius comes with the tool offset

    def machine_target(self, pose: tuple[float, ...], rec: ClRecord) -> dict[str, float]:
        self.check_axis(pose[3:], rec)
        if abs(pose[1]) > Y_TOLERANCE:
            raise self.err(
                f"a lathe has no Y axis: the CL point has y = {pose[1]:.6g} (turned profiles"
                " are programmed in the XZ plane, x = radius)",
                rec,
            )
        return {"X": pose[0] * (2.0 if self.diameter else 1.0), "Z": pose[2]}

    def arc_plane(self, axis, rec):
        i, j, k = axis
        if abs(abs(j) - 1) < 1e-6:
            return ("G18", "I", "K", 0, 2, 1)
        raise self.err(
            f"a lathe turns arcs about Y only: CIRCLE axis ({i:.6g}, {j:.6g}, {k:.6g})", rec
        )

    def do_FROM(self, rec: ClRecord):
        yield from super().do_FROM(rec)
        if self.pos is not None and abs(self.pos[1]) > Y_TOLERANCE:
            raise self.err(f"a lathe has no Y axis: FROM has y = {self.pos[1]:.6g}", rec)

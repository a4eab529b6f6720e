"""The 5-axis machine as the post-processor sees it: kinematics constants and axis limits.

A small YAML document (cam/machines/mill5.yaml is the shipped one), validated with the
same care as the NC kernel's machine files: every problem names its key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from cam.errors import CamError

MILL5_FILE = Path(__file__).resolve().parent / "machines" / "mill5.yaml"


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Kinematics5(_Section):
    type: Literal["table_table_bc45"] = "table_table_bc45"
    d_mm: float = Field(0.0, description="C-table surface to the B/C axes' intersection, mm")
    tool_length_mm: float = Field(0.0, description="Z_T, mm")
    z_offset_mm: float = Field(0.0, description="z_OwOt, mm")
    branch: Literal["positive", "negative"] = "positive"


class LinearLimit(_Section):
    min: float
    max: float

    @model_validator(mode="after")
    def _order(self) -> LinearLimit:
        if not self.min < self.max:
            raise ValueError(f"min {self.min:g} must be below max {self.max:g}")
        return self


class RotaryLimit(_Section):
    min: float | None = None
    max: float | None = None
    continuous: bool = False

    @model_validator(mode="after")
    def _order(self) -> RotaryLimit:
        if self.continuous and (self.min is not None or self.max is not None):
            raise ValueError("a continuous axis has no min/max")
        if not self.continuous and (
            self.min is None or self.max is None or not self.min < self.max
        ):
            raise ValueError("give min < max (degrees) or continuous: true")
        return self


class Axes5(_Section):
    X: LinearLimit
    Y: LinearLimit
    Z: LinearLimit
    B: RotaryLimit
    C: RotaryLimit


class PostSection(_Section):
    tolerance_mm: float = Field(0.01, gt=0)
    max_depth: int = Field(20, ge=1, le=40)
    linear_decimals: int = Field(3, ge=1, le=6)
    rotary_decimals: int = Field(4, ge=1, le=6)
    feed: Literal["per_minute", "inverse_time"] = Field(
        "per_minute",
        description="per_minute: G94 F as programmed; inverse_time: G93 F = 1/minutes of each"
        " block, from the tool tip's path in the workpiece frame",
    )
    rotary_feed_deg_min: float = Field(
        3600.0, gt=0, description="inverse time: the rate of a block that only turns B/C"
    )


class Mill5Config(_Section):
    kind: Literal["mill5"]
    description: str = ""
    kinematics: Kinematics5 = Field(default_factory=Kinematics5)
    axes: Axes5
    post: PostSection = Field(default_factory=PostSection)


def load_mill5(source: str | Path | dict[str, Any]) -> Mill5Config:
    """Validate a mill5 description; errors say `FILE: key.path: why`."""
    name = str(source) if not isinstance(source, dict) else "<mill5>"
    if isinstance(source, dict):
        data = source
    else:
        try:
            data = yaml.safe_load(Path(source).read_text(encoding="utf-8"))
        except (OSError, yaml.YAMLError) as e:
            raise CamError(f"cannot read the machine file: {e}", 0, 0, name) from None
    try:
        return Mill5Config.model_validate(data)
    except ValidationError as e:
        first = e.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "(top)"
        raise CamError(f"{where}: {first['msg']}", 0, 0, name) from None


def from_nc_config(nc: Any, post: Mill5Config | None = None) -> Mill5Config:
    """The post's view of an NC machine of kind mill5 (a `cnc.config.MachineConfig`): its
    kinematics constants and axis limits (C endless when the NC's C is continuous), so a
    cell's machine is posted with its own figures; the post section (T, decimals, feed
    mode) and the IK branch, which the NC's file does not carry, from `post` (default: the
    shipped cam/machines/mill5.yaml).

    The posted program runs in G54 (the NC's power-on work offset), so the linear travel
    the post may use is the machine's soft limits less the G54 offset of its factory setup;
    the NC kernel's check of the posted program (dnc/posting.py) judges it with the
    machine's whole setup."""
    base = post if post is not None else load_mill5(MILL5_FILE)
    if nc.kind != "mill5" or nc.kinematics is None:
        raise CamError(f"a mill5 post needs a mill5 machine, not a {nc.kind}", 0, 0, "<machine>")
    missing = [a for a in "XYZBC" if a not in nc.axes]
    if missing:
        raise CamError(f"a mill5 has axes X Y Z B C; missing {' '.join(missing)}", 0, 0, "")

    def rotary(name: str) -> dict[str, Any]:
        a = nc.axes[name]
        return {"continuous": True} if a.continuous else {"min": a.min_mm, "max": a.max_mm}

    k = nc.kinematics
    md = nc.machine_data
    g54 = list(md.work_offsets.get("G54", ())) if md is not None else []
    shift = dict(zip("XYZ", [*g54, 0.0, 0.0, 0.0][:3], strict=True))
    return Mill5Config.model_validate(
        {
            "kind": "mill5",
            "description": nc.description,
            "kinematics": {
                "d_mm": k.d_mm,
                "tool_length_mm": k.tool_length_mm,
                "z_offset_mm": k.z_offset_mm,
                "branch": base.kinematics.branch,
            },
            "axes": {
                **{
                    a: {"min": nc.axes[a].min_mm - shift[a], "max": nc.axes[a].max_mm - shift[a]}
                    for a in "XYZ"
                },
                "B": rotary("B"),
                "C": rotary("C"),
            },
            "post": base.post.model_dump(),
        }
    )

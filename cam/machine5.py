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

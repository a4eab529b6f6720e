"""Physical plant of a virtual servo axis: motor, ball screw, table, encoder, DC link, loops."""

from drives.plant.params import (
    DcLinkParams,
    EncoderParams,
    LoopParams,
    MonitorParams,
    MotorParams,
    PlantParams,
    ScrewParams,
    SwitchParams,
    ThermalParams,
)
from drives.plant.plant import OFF, POSITION, VELOCITY, Plant

__all__ = [
    "OFF",
    "POSITION",
    "VELOCITY",
    "DcLinkParams",
    "EncoderParams",
    "LoopParams",
    "MonitorParams",
    "MotorParams",
    "Plant",
    "PlantParams",
    "ScrewParams",
    "SwitchParams",
    "ThermalParams",
]

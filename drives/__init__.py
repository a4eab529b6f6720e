"""Virtual CiA 402 servo drives on a simulated CAN bus, and the master-side axis group."""

from pathlib import Path

#: The electronic data sheet (CiA 306) of the virtual servo drive; `canopen.import_od` loads it.
EDS_PATH = str(Path(__file__).parent / "eds" / "fmscell_servo.eds")

__all__ = ["EDS_PATH"]

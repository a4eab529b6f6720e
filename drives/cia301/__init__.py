"""CiA 301 slave: NMT, heartbeat, SDO, PDO, SYNC, EMCY around a DriveApplication."""

from drives.cia301.nmt import NmtState
from drives.cia301.od import ObjectDictionary, load_od
from drives.cia301.slave import CanopenSlave

__all__ = ["CanopenSlave", "NmtState", "ObjectDictionary", "load_od"]

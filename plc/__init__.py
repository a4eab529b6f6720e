"""Soft-PLC: ladder language, compiler, scan runtime and Modbus TCP face.

    from plc import load_file, Runtime, RuntimeConfig
    rt = Runtime(load_file("program.ld"), RuntimeConfig(period_ms=10))
    rt.scan(0)

The ladder and runtime names are imported on first use, so `import plc` stays light.
"""

from plc.image import ImageSize, ProcessImage, Snapshot, Write, WriteQueue

_LAZY = {
    "CompiledProgram": "plc.ladder",
    "Diagnostic": "plc.ladder",
    "LadderError": "plc.ladder",
    "check_file": "plc.ladder",
    "check_text": "plc.ladder",
    "compile_text": "plc.ladder",
    "load_file": "plc.ladder",
    "Alarm": "plc.runtime",
    "Mode": "plc.runtime",
    "RealtimeRunner": "plc.runtime",
    "Runtime": "plc.runtime",
    "RuntimeConfig": "plc.runtime",
    "SimulatedIO": "plc.runtime",
    "FileRetainStore": "plc.runtime",
    "MemoryRetainStore": "plc.runtime",
}


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'plc' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


__all__ = ["ImageSize", "ProcessImage", "Snapshot", "Write", "WriteQueue", *_LAZY]

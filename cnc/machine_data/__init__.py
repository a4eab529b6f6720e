"""The machine data a controller owns: tool offsets, work offsets, G92, kept parameters.

Public API: `MachineData`, `ToolData`, `MachineDataError`, `work_offset_name`,
`work_offset_index`, the store (`save`, `load`, `state_file`, `write_atomically`; for the
part counter `counters_file`, `save_part_count`, `load_part_count`) and the operator files
(`load_tools`, `load_offsets`, `apply_files`, `FileErrors`).
docs/machine_data.md describes the data, the files and the faces that reach it.
"""

from cnc.machine_data.core import (
    EXTENDED_OFFSETS,
    MAX_TOOL_OFFSET,
    WORK_OFFSET_COUNT,
    MachineData,
    MachineDataError,
    ToolData,
    work_offset_index,
    work_offset_name,
)
from cnc.machine_data.files import (
    FileErrors,
    apply_files,
    load_offsets,
    load_tools,
    offsets_csv,
    parse_offsets,
    parse_tools,
    tools_csv,
)
from cnc.machine_data.store import (
    counters_file,
    load,
    load_or,
    load_part_count,
    save,
    save_part_count,
    state_file,
    write_atomically,
)

__all__ = [
    "EXTENDED_OFFSETS",
    "MAX_TOOL_OFFSET",
    "WORK_OFFSET_COUNT",
    "FileErrors",
    "MachineData",
    "MachineDataError",
    "ToolData",
    "apply_files",
    "counters_file",
    "load",
    "load_offsets",
    "load_or",
    "load_part_count",
    "load_tools",
    "offsets_csv",
    "parse_offsets",
    "parse_tools",
    "save",
    "save_part_count",
    "state_file",
    "tools_csv",
    "work_offset_index",
    "work_offset_name",
    "write_atomically",
]

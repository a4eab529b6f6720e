"""Tool-table and offset files an operator writes by hand (`nc check --tools/--offsets`).

Both are CSV with a header row naming the columns (any order, columns may be left out):

    tools:   number,length,length_wear,radius,radius_wear,x,x_wear,z,z_wear,tip,
             uses,cut_time_s,life_uses,life_time_s,comment
    offsets: offset,x,y,z        (offset: EXT, G54..G59, G54.1P1..G54.1P48, G92)

Blank lines and lines starting with `#` are skipped. A LinuxCNC tool table (`.tbl`:
`T1 P1 Z+50.0 D10.0 ;comment`) is read too: Z is the length, D the diameter (radius =
D/2), X the lathe X offset, Q the tip orientation. Every bad row is reported as
`FILE:LINE:COL: reason`; nothing is taken from a file with a bad row.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from cnc.errors import NcError
from cnc.machine_data.core import (
    TOOL_FIELDS,
    MachineData,
    MachineDataError,
    ToolData,
    check_tool_number,
    tool_from_mapping,
    work_offset_index,
    work_offset_name,
)

_INT_COLS = ("tip", "uses", "life_uses")


class FileErrors(NcError):
    """All the problems of one file; str() gives one `FILE:LINE:COL: reason` per line."""

    def __init__(self, errors: list[NcError]) -> None:
        first = errors[0]
        super().__init__(first.message, first.line, first.col, first.file)
        self.errors = errors

    def __str__(self) -> str:
        return "\n".join(NcError.__str__(e) for e in self.errors)


def _cells(line: str) -> list[tuple[str, int]]:
    """Split a CSV line at commas: (stripped text, 1-based column of the cell's text)."""
    out = []
    start = 0
    for part in line.split(","):
        lead = len(part) - len(part.lstrip())
        out.append((part.strip(), start + lead + 1))
        start += len(part) + 1
    return out


def _rows(text: str):
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.rstrip("\r\n")
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        yield n, line


def _read(path: str | Path) -> tuple[str, str]:
    try:
        return str(path), Path(path).read_text(encoding="utf-8-sig")
    except OSError as e:
        raise NcError(f"cannot read: {e.strerror}", 0, 0, str(path)) from None
    except UnicodeDecodeError as e:
        raise NcError(f"not UTF-8 text: {e.reason}", 0, 0, str(path)) from None


def _value(text: str, col_name: str) -> float | int:
    if col_name in _INT_COLS:
        return int(text)
    v = float(text)
    if not math.isfinite(v):
        raise ValueError("not finite")
    return v


def parse_tools(text: str, file: str = "<tools>") -> dict[int, ToolData]:
    """Tool offsets from CSV (or LinuxCNC .tbl when `file` ends in .tbl)."""
    if file.lower().endswith(".tbl"):
        return _parse_tbl(text, file)
    errors: list[NcError] = []
    tools: dict[int, ToolData] = {}
    header: list[tuple[str, int]] | None = None
    where: dict[int, int] = {}
    for n, line in _rows(text):
        cells = _cells(line)
        if header is None:
            header = cells
            names = [c for c, _ in cells]
            for name, col in cells:
                if name != "number" and name not in TOOL_FIELDS:
                    errors.append(
                        NcError(
                            f"unknown column {name!r} (columns: number, {', '.join(TOOL_FIELDS)})",
                            n,
                            col,
                            file,
                        )
                    )
            if "number" not in names:
                errors.append(NcError("the header needs a 'number' column", n, 1, file))
            if errors:
                raise FileErrors(errors)
            continue
        if len(cells) != len(header):
            col = cells[min(len(cells), len(header)) - 1][1]
            errors.append(
                NcError(f"{len(cells)} cells, the header has {len(header)}", n, col, file)
            )
            continue
        values: dict[str, object] = {}
        number = None
        bad = False
        for (name, _), (text_, col) in zip(header, cells, strict=True):
            if name == "comment":
                values[name] = text_
                continue
            if text_ == "":
                continue
            try:
                v = _value(text_, "tip" if name == "number" else name)
            except ValueError:
                kind = "an integer" if name in (*_INT_COLS, "number") else "a number"
                errors.append(NcError(f"{name}: {text_!r} is not {kind}", n, col, file))
                bad = True
                continue
            if name == "number":
                try:
                    number = check_tool_number(v)
                except MachineDataError as e:
                    errors.append(NcError(f"number: {e.message}", n, col, file))
                    bad = True
                continue
            values[name] = v
        if bad:
            continue
        if number is None:
            errors.append(NcError("number: missing", n, header[0][1], file))
            continue
        if number in tools:
            errors.append(
                NcError(f"tool offset {number} is already on line {where[number]}", n, 1, file)
            )
            continue
        try:
            tools[number] = tool_from_mapping(values, "")
        except MachineDataError as e:
            key = e.pointer.lstrip("/")
            col = next((c for (h, _), (_, c) in zip(header, cells, strict=True) if h == key), 1)
            errors.append(NcError(f"{key}: {e.message}", n, col, file))
            continue
        where[number] = n
    if errors:
        raise FileErrors(errors)
    return tools


_TBL_WORD = re.compile(r"\s*([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")


def _parse_tbl(text: str, file: str) -> dict[int, ToolData]:
    errors: list[NcError] = []
    tools: dict[int, ToolData] = {}
    for n, line in _rows(text):
        body = line.split(";", 1)[0]
        comment = line.split(";", 1)[1].strip() if ";" in line else ""
        pos = 0
        words: dict[str, tuple[float, int]] = {}
        bad = False
        while pos < len(body):
            if body[pos:].strip() == "":
                break
            m = _TBL_WORD.match(body, pos)
            if m is None:
                col = pos + len(body[pos:]) - len(body[pos:].lstrip()) + 1
                errors.append(NcError("expected a word like T1 or Z+50.0", n, col, file))
                bad = True
                break
            words[m.group(1).upper()] = (float(m.group(2)), m.start(1) + 1)
            pos = m.end()
        if bad:
            continue
        if "T" not in words:
            errors.append(NcError("a tool line needs T<number>", n, 1, file))
            continue
        tnum, tcol = words["T"]
        try:
            number = check_tool_number(int(tnum) if tnum.is_integer() else tnum)
        except MachineDataError as e:
            errors.append(NcError(f"T: {e.message}", n, tcol, file))
            continue
        fields: dict[str, object] = {"comment": comment[:80]}
        mapping = {"Z": "length", "X": "x", "Q": "tip"}
        for letter, (v, col) in words.items():
            if letter in ("T", "P", "Y", "A", "B", "C", "U", "V", "W", "I", "J"):
                continue  # pocket, other axes, angles: not offsets this kernel applies
            if letter == "D":
                fields["radius"] = v / 2.0
            elif letter in mapping:
                fields[mapping[letter]] = int(v) if letter == "Q" else v
            else:
                errors.append(NcError(f"unknown word {letter}", n, col, file))
                bad = True
        if bad:
            continue
        try:
            tools[number] = tool_from_mapping(fields, "")
        except MachineDataError as e:
            errors.append(NcError(f"{e.pointer.lstrip('/')}: {e.message}", n, tcol, file))
    if errors:
        raise FileErrors(errors)
    return tools


def parse_offsets(text: str, file: str = "<offsets>") -> dict[str, tuple[float, float, float]]:
    """Work offsets (and G92) by name from CSV `offset,x,y,z`."""
    errors: list[NcError] = []
    out: dict[str, tuple[float, float, float]] = {}
    header: list[tuple[str, int]] | None = None
    for n, line in _rows(text):
        cells = _cells(line)
        if header is None:
            header = cells
            names = [c.lower() for c, _ in cells]
            if names[:1] != ["offset"] or not set(names[1:]) <= {"x", "y", "z"}:
                errors.append(NcError("the header must be offset,x,y,z", n, 1, file))
                raise FileErrors(errors)
            continue
        if len(cells) != len(header):
            col = cells[min(len(cells), len(header)) - 1][1]
            errors.append(
                NcError(f"{len(cells)} cells, the header has {len(header)}", n, col, file)
            )
            continue
        name, ncol = cells[0]
        key = name.upper().replace(" ", "")
        if key != "G92":
            try:
                work_offset_index(name)
            except MachineDataError as e:
                errors.append(NcError(e.message, n, ncol, file))
                continue
            key = _canonical(name)
        vec = {"x": 0.0, "y": 0.0, "z": 0.0}
        bad = False
        for (h, _), (text_, col) in zip(header[1:], cells[1:], strict=True):
            if text_ == "":
                continue
            try:
                v = float(text_)
                if not math.isfinite(v) or abs(v) > 10_000.0:
                    raise ValueError
            except ValueError:
                errors.append(
                    NcError(f"{h}: {text_!r} is not a number within ±10000 mm", n, col, file)
                )
                bad = True
                continue
            vec[h.lower()] = v
        if bad:
            continue
        if key in out:
            errors.append(NcError(f"{name} is given twice", n, ncol, file))
            continue
        out[key] = (vec["x"], vec["y"], vec["z"])
    if errors:
        raise FileErrors(errors)
    return out


def _canonical(name: str) -> str:
    return work_offset_name(work_offset_index(name))


def load_tools(path: str | Path) -> dict[int, ToolData]:
    file, text = _read(path)
    return parse_tools(text, file)


def load_offsets(path: str | Path) -> dict[str, tuple[float, float, float]]:
    file, text = _read(path)
    return parse_offsets(text, file)


def apply_files(
    data: MachineData, tools: str | Path | None = None, offsets: str | Path | None = None
) -> MachineData:
    """`data` with a tool file's table (replacing the whole table) and an offsets file's
    offsets (replacing those it names) taken in; `data` itself is left unchanged."""
    out = data.copy()
    if tools is not None:
        table = load_tools(tools)
        out.tools = dict(table)
    if offsets is not None:
        ofs = load_offsets(offsets)
        g92 = ofs.pop("G92", None)
        doc: dict[str, object] = {"work_offsets": {k: list(v) for k, v in ofs.items()}}
        if g92 is not None:
            doc["g92"] = list(g92)
        out.set_offsets_from(doc)
    return out


def tools_csv(data: MachineData) -> str:
    """The tool table as the CSV `parse_tools` reads (an operator's starting point)."""
    lines = ["number," + ",".join(TOOL_FIELDS)]
    for n in sorted(data.tools):
        t = data.tools[n]
        vals = [str(getattr(t, f)) if f != "comment" else t.comment.replace(",", ";")
                for f in TOOL_FIELDS]  # fmt: skip
        lines.append(f"{n}," + ",".join(vals))
    return "\n".join(lines) + "\n"


def offsets_csv(data: MachineData) -> str:
    """The work offsets that are set (and G92 when set) as the CSV `parse_offsets` reads."""
    lines = ["offset,x,y,z"]
    for i, (x, y, z) in enumerate(data.work_offsets):
        if (x, y, z) != (0.0, 0.0, 0.0):
            lines.append(f"{work_offset_name(i)},{x!r},{y!r},{z!r}")
    if data.g92 != (0.0, 0.0, 0.0):
        lines.append("G92," + ",".join(repr(v) for v in data.g92))
    return "\n".join(lines) + "\n"

"""Compile a ladder program to one Python function, cached by program hash.

`compile_text` / `compile_program` check the program (raising `LadderError` with every
diagnostic on errors), generate the scan function's source, `compile()` it once and wrap it
in a `CompiledProgram`. A runtime failure inside the generated code is traced back to the
source rung through `CompiledProgram.locate`.
"""

from __future__ import annotations

import gc
import hashlib
import linecache
import traceback
from collections import OrderedDict
from dataclasses import dataclass, field
from types import CodeType, TracebackType

from plc.image import ImageSize
from plc.ladder.analysis import analyse
from plc.ladder.ast import Program, format_program
from plc.ladder.codegen import FUNC_NAME, RUNTIME_GLOBALS, generate
from plc.ladder.diagnostics import Diagnostic, DiagnosticSink, LadderError
from plc.ladder.parser import parse_program
from plc.ladder.symbols import Symbol

_CACHE_SIZE = 32
_code_cache: OrderedDict[str, CodeType] = OrderedDict()
_text_cache: OrderedDict[str, CompiledProgram] = OrderedDict()


@dataclass(frozen=True, slots=True)
class TagInfo:
    """Where a tag lives: `area` is an image area (IX ... MW) or 'V' for the slot list."""

    name: str
    type: str
    retain: bool
    area: str | None = None  # BOOL / INT
    index: int | None = None
    members: dict[str, int] = field(default_factory=dict)  # TIMER / COUNTER member -> v slot
    comment: str = ""


@dataclass(frozen=True, slots=True)
class AlarmInfo:
    """A program alarm: shown by the runtime while the bit at (area, index) is 1."""

    number: int
    text: str
    area: str  # image area or 'V'
    index: int


@dataclass(frozen=True, slots=True)
class RungInfo:
    number: int
    line: int
    comment: str


@dataclass(frozen=True, eq=False)
class CompiledProgram:
    """A checked program and its compiled scan function.

    `scan_fn(ix, qx, mx, iw, qw, mw, v, dt)` solves every rung once over the image lists and
    the slot list `v` (start from a copy of `v_init`); `dt` is the time step in ms.
    """

    name: str
    file: str
    hash: str
    size: ImageSize
    scan_fn: object
    python_source: str
    filename: str  # the pseudo file name the generated code is compiled under
    line_rung: tuple[int | None, ...]
    rungs: tuple[RungInfo, ...]
    tags: dict[str, TagInfo]  # key: upper-case tag name
    v_init: tuple[int | bool, ...]
    diagnostics: tuple[Diagnostic, ...]
    estimate_us: float
    alarms: tuple[AlarmInfo, ...] = ()

    @property
    def warnings(self) -> list[Diagnostic]:
        return [d for d in self.diagnostics if d.severity == "warning"]

    def tag(self, name: str) -> TagInfo:
        try:
            return self.tags[name.upper()]
        except KeyError:
            raise KeyError(f"no tag {name!r} in program {self.name!r}") from None

    def locate(self, tb: TracebackType | BaseException | None) -> RungInfo | None:
        """The source rung where an exception raised inside the generated code happened."""
        if isinstance(tb, BaseException):
            tb = tb.__traceback__
        found: RungInfo | None = None
        for frame, lineno in traceback.walk_tb(tb):
            if frame.f_code.co_filename == self.filename and 0 < lineno <= len(self.line_rung):
                rung = self.line_rung[lineno - 1]
                if rung is not None:
                    found = self.rungs[rung]
        return found

    def describe_rung(self, rung: RungInfo) -> str:
        return f"{self.file}:{rung.line}: rung {rung.number}"


def _without_gc(fn):
    """Run a compile step with the cyclic GC paused: building many small objects otherwise
    triggers collections whose cost grows with the heap (superlinear compile times)."""

    def wrapper(*args, **kwargs):
        enabled = gc.isenabled()
        gc.disable()
        try:
            return fn(*args, **kwargs)
        finally:
            if enabled:
                gc.enable()

    wrapper.__doc__ = fn.__doc__
    wrapper.__name__ = fn.__name__
    return wrapper


def _tag_infos(program: Program, symbols: dict[str, Symbol]) -> dict[str, TagInfo]:
    out: dict[str, TagInfo] = {}
    for key, sym in symbols.items():
        decl = sym.decl
        retain = bool(decl and decl.retain)
        comment = decl.comment if decl else "system tag"
        if sym.members:
            out[key] = TagInfo(
                sym.name, sym.type, retain, members=dict(sym.members), comment=comment
            )
        else:
            assert sym.location is not None
            out[key] = TagInfo(
                sym.name, sym.type, retain, sym.location.area, sym.location.index, comment=comment
            )
    return out


def check_program(
    program: Program,
    sink: DiagnosticSink,
    size: ImageSize | None = None,
    watchdog_ms: float | None = None,
) -> list[Diagnostic]:
    """All diagnostics for a parsed program; `sink` already holds the parse diagnostics.

    The semantic pass runs even after syntax errors so that one run reports everything.
    """
    analyse(program, sink, size, watchdog_ms)
    return sink.sorted()


def check_text(
    text: str,
    file: str = "<ladder>",
    size: ImageSize | None = None,
    watchdog_ms: float | None = None,
) -> list[Diagnostic]:
    """Every error and warning for a neutral-text program, sorted by position."""
    program, sink = parse_program(text, file)
    return check_program(program, sink, size, watchdog_ms)


@_without_gc
def compile_program(
    program: Program,
    sink: DiagnosticSink | None = None,
    size: ImageSize | None = None,
    watchdog_ms: float | None = None,
) -> CompiledProgram:
    """Check and compile a parsed program; raises `LadderError` when it has errors."""
    size = size or ImageSize()
    sink = sink or DiagnosticSink(program.file)
    resolved = analyse(program, sink, size, watchdog_ms)
    if sink.has_errors:
        raise LadderError(sink.sorted())
    source, line_rung = generate(resolved)
    digest = hashlib.sha256(source.encode()).hexdigest()
    filename = f"<ladder {program.file} {digest[:12]}>"
    code = _code_cache.get(filename)
    if code is None:
        code = compile(source, filename, "exec")
        _code_cache[filename] = code
        if len(_code_cache) > _CACHE_SIZE:
            _code_cache.popitem(last=False)
    else:
        _code_cache.move_to_end(filename)
    # so tracebacks through generated code show its lines
    linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)
    namespace = dict(RUNTIME_GLOBALS)
    exec(code, namespace)  # noqa: S102 - our own generated, checked source
    rungs = tuple(RungInfo(r.number, r.line, r.comment) for r in program.rungs)
    return CompiledProgram(
        name=program.name,
        file=program.file,
        hash=digest,
        size=size,
        scan_fn=namespace[FUNC_NAME],
        python_source=source,
        filename=filename,
        line_rung=tuple(line_rung),
        rungs=rungs,
        tags=_tag_infos(program, resolved.table.symbols),
        v_init=tuple(resolved.table.v_init),
        diagnostics=tuple(sink.sorted()),
        estimate_us=resolved.estimate_us,
        alarms=tuple(AlarmInfo(*a) for a in resolved.alarms),
    )


@_without_gc
def compile_text(
    text: str,
    file: str = "<ladder>",
    size: ImageSize | None = None,
    watchdog_ms: float | None = None,
) -> CompiledProgram:
    """Parse, check and compile neutral text (cached: the same text compiles once)."""
    size = size or ImageSize()
    key = hashlib.sha256(f"{file}\0{size}\0{watchdog_ms}\0{text}".encode()).hexdigest()
    hit = _text_cache.get(key)
    if hit is not None:
        _text_cache.move_to_end(key)
        return hit
    program, sink = parse_program(text, file)
    if sink.has_errors:
        check_program(program, sink, size, watchdog_ms)
        raise LadderError(sink.sorted())
    compiled = compile_program(program, sink, size, watchdog_ms)
    _text_cache[key] = compiled
    if len(_text_cache) > _CACHE_SIZE:
        _text_cache.popitem(last=False)
    return compiled


def load_file(
    path: str, size: ImageSize | None = None, watchdog_ms: float | None = None
) -> CompiledProgram:
    """Compile a program file: `.xml` is PLCopen TC6, anything else neutral text."""
    if str(path).lower().endswith(".xml"):
        # deferred: the PLCopen importer (and expat) only for .xml programs: start-up cost
        from plc.ladder.plcopen import import_plcopen

        program, sink = import_plcopen(path)
        if sink.has_errors:
            raise LadderError(sink.sorted())
        return compile_program(program, sink, size, watchdog_ms)
    with open(path, encoding="utf-8") as f:
        text = f.read()
    return compile_text(text, str(path), size, watchdog_ms)


def export_text(program: Program) -> str:
    return format_program(program)

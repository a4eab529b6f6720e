"""Neutral-text ladder parser: one rung per line, `BST … NXB … BND` branches, a tag table.

Grammar (see docs/ladder.md for the full description with examples)::

    file      := { line }
    line      := [ statement ] [ "//" comment ]        ; a trailing "\\" joins the next line
    statement := "PROGRAM" name
               | "TAG" name ":" type [ "AT" address ] [ "RETAIN" ] [ ":=" int ]
               | "ALARM" int bit '"' text '"'
               | [ "SOR" ] element { element } [ "EOR" ]          ; a rung
    element   := mnemonic operand*      ; operand count fixed by the mnemonic
               | "BST" element+ { "NXB" element+ } "BND"
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from plc.ladder.ast import AlarmDecl, Branch, Element, Instr, Operand, Program, Rung, TagDecl
from plc.ladder.diagnostics import DiagnosticSink
from plc.ladder.instructions import INSTRUCTIONS, KEYWORDS

_TOKEN = re.compile(
    r"""
    (?P<ws>\s+)
  | (?P<time>T\#[0-9A-Za-z_.]+)
  | (?P<addr>%[A-Za-z]+[0-9]+(?:\.[0-9]+)?)
  | (?P<int>[-+]?(?:16\#[0-9A-Fa-f_]+|2\#[01_]+|[0-9][0-9_]*))
  | (?P<name>[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)?)
  | (?P<string>"[^"]*")
  | (?P<assign>:=)
  | (?P<colon>:)
  | (?P<bad>\S+)
    """,
    re.VERBOSE,
)
_TIME_PART = re.compile(r"(\d+(?:\.\d+)?)(ms|d|h|m|s)", re.IGNORECASE)
_TIME_UNIT_MS = {"d": 86_400_000, "h": 3_600_000, "m": 60_000, "s": 1000, "ms": 1}
TYPES = ("BOOL", "INT", "TIMER", "COUNTER")
MAX_BRANCH_DEPTH = 32  # deeper nesting is refused: no drawn rung needs it, recursion does


@dataclass(slots=True)
class Token:
    kind: str
    text: str
    line: int
    col: int


def parse_int(text: str) -> int:
    sign = -1 if text.startswith("-") else 1
    body = text.lstrip("+-").replace("_", "")
    if body.startswith("16#"):
        return sign * int(body[3:], 16)
    if body.startswith("2#"):
        return sign * int(body[2:], 2)
    return sign * int(body)


def parse_time_ms(text: str) -> int | None:
    """`T#1m30s` -> 90000; `T#250ms` -> 250; None when malformed."""
    body = text[2:].replace("_", "")
    pos, total = 0, 0.0
    for m in _TIME_PART.finditer(body):
        if m.start() != pos:
            return None
        total += float(m.group(1)) * _TIME_UNIT_MS[m.group(2).lower()]
        pos = m.end()
    if pos != len(body) or not body:
        return None
    return round(total)


def _tokenize(code: str, line: int, col0: int, sink: DiagnosticSink) -> list[Token]:
    tokens: list[Token] = []
    for m in _TOKEN.finditer(code):
        kind = m.lastgroup
        if kind == "ws":
            continue
        col = col0 + m.start()
        if kind == "bad":
            sink.error(line, col, f"unexpected characters {m.group()!r}")
            continue
        tokens.append(Token(kind, m.group(), line, col))
    return tokens


def _split_comment(raw: str) -> tuple[str, str, str]:
    """Like `raw.partition("//")`, but a `//` inside a "string" is not a comment."""
    if '"' not in raw:
        return raw.partition("//")
    quoted = False
    for i, ch in enumerate(raw):
        if ch == '"':
            quoted = not quoted
        elif not quoted and raw.startswith("//", i):
            return raw[:i], "//", raw[i + 2 :]
    return raw, "", ""


def _logical_lines(text: str) -> list[tuple[list[tuple[int, int, str]], str]]:
    """Split into statements: each is a list of (line, first col, code) pieces and a comment.

    A piece is one physical line's code part; a trailing backslash continues the statement.
    """
    out: list[tuple[list[tuple[int, int, str]], str]] = []
    pending: list[tuple[int, int, str]] = []
    comments: list[str] = []
    for n, raw in enumerate(text.splitlines(), start=1):
        code, sep, comment = _split_comment(raw)
        if sep:
            comments.append(comment.strip())
        stripped = code.rstrip()
        cont = stripped.endswith("\\")
        if cont:
            stripped = stripped[:-1]
        pending.append((n, 1, stripped))
        if not cont:
            out.append((pending, "\n".join(comments)))
            pending, comments = [], []
    if pending:
        out.append((pending, "\n".join(comments)))
    return out


class _RungParser:
    def __init__(self, tokens: list[Token], sink: DiagnosticSink) -> None:
        self.toks = tokens
        self.i = 0
        self.sink = sink
        self.depth = 0

    def peek(self) -> Token | None:
        return self.toks[self.i] if self.i < len(self.toks) else None

    def elements(self, stop: tuple[str, ...]) -> list[Element] | None:
        items: list[Element] = []
        while (tok := self.peek()) is not None:
            word = tok.text.upper()
            if tok.kind == "name" and word in stop:
                return items
            if tok.kind == "name" and word in ("NXB", "BND"):
                self.sink.error(tok.line, tok.col, f"{word} outside a branch (no open BST)")
                return None
            el = self.element()
            if el is None:
                return None
            items.append(el)
        return items

    def element(self) -> Element | None:
        tok = self.toks[self.i]
        word = tok.text.upper()
        if tok.kind != "name":
            self.sink.error(tok.line, tok.col, f"expected an instruction, found {tok.text!r}")
            return None
        self.i += 1
        if word == "BST":
            return self.branch(tok)
        spec = INSTRUCTIONS.get(word)
        if spec is None:
            self.sink.error(tok.line, tok.col, f"unknown instruction {tok.text!r}")
            return None
        ops: list[Operand] = []
        for kind in spec.operands:
            op_tok = self.peek()
            if op_tok is None or (op_tok.kind == "name" and op_tok.text.upper() in KEYWORDS):
                where = op_tok or tok
                found = f"found {op_tok.text!r}" if op_tok else "the rung ends"
                self.sink.error(
                    where.line,
                    where.col,
                    f"{word} expects {len(spec.operands)} operand(s), {found} "
                    f"where operand {len(ops) + 1} ({kind}) should be",
                )
                return None
            self.i += 1
            op = _operand(op_tok, self.sink)
            if op is None:
                return None
            ops.append(op)
        return Instr(word, ops, tok.line, tok.col)

    def branch(self, bst: Token) -> Branch | None:
        if self.depth >= MAX_BRANCH_DEPTH:
            self.sink.error(bst.line, bst.col, f"branches nested deeper than {MAX_BRANCH_DEPTH}")
            return None
        self.depth += 1
        try:
            return self._branch(bst)
        finally:
            self.depth -= 1

    def _branch(self, bst: Token) -> Branch | None:
        legs: list[list[Element]] = []
        while True:
            start = self.peek()
            leg = self.elements(stop=("NXB", "BND"))
            if leg is None:
                return None
            end = self.peek()
            if end is None:
                self.sink.error(
                    bst.line, bst.col, "branch opened here is never closed (BND missing)"
                )
                return None
            if not leg:
                self.sink.error(end.line, end.col, f"empty branch leg before {end.text.upper()}")
                return None
            legs.append(leg)
            self.i += 1
            if end.text.upper() == "BND":
                if len(legs) < 2:
                    at = start or bst
                    self.sink.error(at.line, bst.col, "branch with a single leg (NXB missing)")
                    return None
                return Branch(legs, bst.line, bst.col)


def _operand(tok: Token, sink: DiagnosticSink) -> Operand | None:
    if tok.kind == "addr":
        return Operand("address", tok.text.upper(), tok.line, tok.col)
    if tok.kind == "int":
        return Operand("int", tok.text, tok.line, tok.col, parse_int(tok.text))
    if tok.kind == "time":
        ms = parse_time_ms(tok.text)
        if ms is None:
            sink.error(
                tok.line, tok.col, f"malformed time literal {tok.text!r} (e.g. T#1m30s, T#250ms)"
            )
            return None
        return Operand("time", tok.text, tok.line, tok.col, ms)
    if tok.kind == "name":
        return Operand("tag", tok.text, tok.line, tok.col)
    sink.error(tok.line, tok.col, f"expected an operand, found {tok.text!r}")
    return None


def _parse_tag(tokens: list[Token], comment: str, sink: DiagnosticSink) -> TagDecl | None:
    kw = tokens[0]

    def fail(tok: Token | None, msg: str) -> None:
        at = tok or tokens[-1]
        sink.error(at.line, at.col if tok else at.col + len(at.text), msg)

    if len(tokens) < 2 or tokens[1].kind != "name" or "." in tokens[1].text:
        fail(tokens[1] if len(tokens) > 1 else None, "TAG needs a name: TAG Name : TYPE ...")
        return None
    name_tok = tokens[1]
    if name_tok.text.upper() in KEYWORDS:
        fail(name_tok, f"{name_tok.text!r} is a keyword and cannot name a tag")
        return None
    if len(tokens) < 3 or tokens[2].kind != "colon":
        fail(tokens[2] if len(tokens) > 2 else None, "expected ':' after the tag name")
        return None
    if len(tokens) < 4 or tokens[3].text.upper() not in TYPES:
        fail(tokens[3] if len(tokens) > 3 else None, f"expected a type ({', '.join(TYPES)})")
        return None
    decl = TagDecl(name_tok.text, tokens[3].text.upper(), kw.line, name_tok.col, comment=comment)
    i = 4
    while i < len(tokens):
        t = tokens[i]
        word = t.text.upper()
        if word == "AT" and t.kind == "name":
            if i + 1 >= len(tokens) or tokens[i + 1].kind != "addr":
                fail(
                    tokens[i + 1] if i + 1 < len(tokens) else None,
                    "AT needs an address like %IX0.0",
                )
                return None
            a = tokens[i + 1]
            decl.address = Operand("address", a.text.upper(), a.line, a.col)
            i += 2
        elif word == "RETAIN" and t.kind == "name":
            decl.retain = True
            i += 1
        elif t.kind == "assign":
            if i + 1 >= len(tokens) or tokens[i + 1].kind != "int":
                fail(tokens[i + 1] if i + 1 < len(tokens) else None, "':=' needs an integer")
                return None
            decl.init = parse_int(tokens[i + 1].text)
            i += 2
        else:
            fail(t, f"unexpected {t.text!r} in tag declaration (AT, RETAIN or := expected)")
            return None
    return decl


def _parse_alarm(tokens: list[Token], sink: DiagnosticSink) -> AlarmDecl | None:
    kw = tokens[0]
    expected = (("int",), ("name", "addr"), ("string",))
    args = tokens[1:]
    for i, kinds in enumerate(expected):
        if i >= len(args) or args[i].kind not in kinds:
            at = args[i] if i < len(args) else tokens[-1]
            sink.error(at.line, at.col, 'expected: ALARM number tag "text"')
            return None
    if len(args) > 3:
        sink.error(args[3].line, args[3].col, 'expected: ALARM number tag "text"')
        return None
    num, tag, text = args
    kind = "address" if tag.kind == "addr" else "tag"
    operand = Operand(kind, tag.text.upper() if kind == "address" else tag.text, tag.line, tag.col)
    return AlarmDecl(parse_int(num.text), operand, text.text[1:-1], kw.line, num.col)


def parse_program(text: str, file: str = "<ladder>") -> tuple[Program, DiagnosticSink]:
    """Parse neutral text. Returns the tree and the sink holding syntax diagnostics."""
    sink = DiagnosticSink(file)
    program = Program(name="main", file=file)
    carried: list[str] = []  # comment lines above the next rung describe it
    for pieces, comment in _logical_lines(text):
        tokens: list[Token] = []
        for line, col, code in pieces:
            tokens.extend(_tokenize(code, line, col, sink))
        if not tokens:
            if comment:
                carried.append(comment)
            else:
                carried.clear()  # a blank line ends a comment block
            continue
        above, carried = "\n".join(carried), []
        head = tokens[0].text.upper() if tokens[0].kind == "name" else ""
        if head == "TAG":
            decl = _parse_tag(tokens, comment, sink)
            if decl is not None:
                program.tags.append(decl)
            continue
        if head == "ALARM":
            alarm = _parse_alarm(tokens, sink)
            if alarm is not None:
                program.alarms.append(alarm)
            continue
        if head == "PROGRAM":
            if len(tokens) != 2 or tokens[1].kind != "name":
                sink.error(tokens[0].line, tokens[0].col, "expected: PROGRAM name")
            else:
                program.name = tokens[1].text
            continue
        if head == "SOR":
            tokens = tokens[1:]
            if tokens and tokens[-1].kind == "name" and tokens[-1].text.upper() == "EOR":
                tokens = tokens[:-1]
            if not tokens:
                continue
        p = _RungParser(tokens, sink)
        elements = p.elements(stop=())
        if elements:
            first = tokens[0]
            text_comment = "\n".join(c for c in (above, comment) if c)
            program.rungs.append(
                Rung(len(program.rungs), elements, first.line, first.col, text_comment)
            )
    return program, sink

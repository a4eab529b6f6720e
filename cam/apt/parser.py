"""APT parser: token statements -> statement trees (names checked, expressions built)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

from cam.apt.lexer import NAME_MAX, Token, statements
from cam.errors import CamError

GEOMETRY = frozenset(
    {"POINT", "LINE", "CIRCLE", "PLANE", "VECTOR", "ELLIPS", "ELIPS", "HYPERB", "PARABL",
     "LCONIC", "PARSRF", "QADRIC", "RLDSRF", "TABCYL", "MATRIX", "PATERN", "CIRCL"}
)  # fmt: skip
MAJORS = GEOMETRY | frozenset(
    {"MACRO", "TERMAC", "CALL", "CUTTER", "FROM", "GOTO", "GODLTA", "GO", "GOLFT", "GORGT",
     "GOFWD", "GOBACK", "GOUP", "GODOWN", "TLLFT", "TLRGT", "TLON", "TLOFPS", "TLONPS",
     "INDIRV", "INDIRP", "PARTNO", "MACHIN", "UNITS", "LOADTL", "TURRET", "SPINDL", "FEDRAT",
     "RAPID", "COOLNT", "CUTCOM", "DELAY", "END", "FINI", "STOP", "OPSTOP", "ZSURF", "INTOL",
     "OUTTOL", "TOLER", "CLPRNT", "NOPOST", "REMARK", "PPRINT", "INSERT", "MULTAX", "TLAXIS",
     "AUTOPS", "DNTCUT", "CUT", "PSIS", "THICK", "LOOPST", "LOOPND", "JUMPTO", "IF"}
)  # fmt: skip
MINORS = frozenset(
    {"XLARGE", "XSMALL", "YLARGE", "YSMALL", "ZLARGE", "ZSMALL", "LARGE", "SMALL", "LEFT",
     "RIGHT", "IN", "OUT", "INTOF", "TANTO", "CENTER", "RADIUS", "ATANGL", "PARLEL",
     "PERPTO", "DELTA", "CLW", "CCLW", "ON", "OFF", "TO", "PAST", "THRU", "XYPLAN", "YZPLAN",
     "ZXPLAN", "XAXIS", "YAXIS", "RTHETA", "MM", "INCHES", "IPM", "IPR", "MMPM", "MMPR",
     "FLOOD", "MIST", "RPM", "SFM", "SMM", "MAXRPM", "NOMORE", "TIMES", "SAME", "AUTO",
     "MILL", "LATHE", "TAP", "ALL", "NORMAL", "UNIT", "PLUS", "MINUS", "ADJUST",
     "LENGTH", "OMIT", "AT", "INCR", "LINEAR", "ARC", "SCALE", "TRANSL", "ROTATE"}
)  # fmt: skip
FUNCTIONS = frozenset(
    {"SQRTF", "SINF", "COSF", "TANF", "ASINF", "ACOSF", "ATANF", "ATAN2F", "ABSF", "EXPF",
     "LOGF", "INTF", "SIGNF", "MAXF", "MINF", "DOTF", "DISTF"}
)  # fmt: skip
KEYWORDS = MAJORS | MINORS | FUNCTIONS


# --- trees -------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Num:
    value: float
    tok: Token


@dataclass(frozen=True, slots=True)
class Ref:
    """A name defined earlier (a scalar or a geometric entity)."""

    name: str
    tok: Token


@dataclass(frozen=True, slots=True)
class Minor:
    word: str
    tok: Token


@dataclass(frozen=True, slots=True)
class BinOp:
    op: str
    left: object
    right: object
    tok: Token


@dataclass(frozen=True, slots=True)
class Neg:
    operand: object
    tok: Token


@dataclass(frozen=True, slots=True)
class Call:
    func: str
    args: list
    tok: Token


@dataclass(frozen=True, slots=True)
class Definition:
    """`MAJOR/args`, as the right side of `=` or nested in parentheses."""

    major: str
    args: list
    tok: Token


@dataclass(slots=True)
class Statement:
    kind: str  # "assign" | "command"
    tok: Token  # first token: where errors about the whole statement point
    name: str | None = None  # assign: the name defined
    value: object = None  # assign: an expression or a Definition
    major: str | None = None  # command: the major word
    args: list = field(default_factory=list)  # command: the arguments
    prefix: list[Token] = field(default_factory=list)  # command: TLLFT, ... before it
    text: str | None = None  # PARTNO/PPRINT/... free text
    has_slash: bool = False


def check_name(tok: Token, file: str) -> None:
    """The 6-character rules for a name being defined."""
    if tok.kind == "NUMBER":
        raise CamError(
            f"invalid name {tok.value!r}: a name must start with a letter", tok.line, tok.col, file
        )
    if tok.kind != "NAME":
        raise CamError(f"expected a name, found {tok.value!r}", tok.line, tok.col, file)
    if len(tok.value) > NAME_MAX:
        raise CamError(
            f"invalid name {tok.value!r}: at most {NAME_MAX} characters", tok.line, tok.col, file
        )
    if tok.value in KEYWORDS:
        raise CamError(f"invalid name {tok.value!r}: it is an APT keyword", tok.line, tok.col, file)


class _Parser:
    def __init__(self, toks: list[Token], file: str) -> None:
        self.toks = toks
        self.i = 0
        self.file = file

    def err(self, msg: str, tok: Token | None = None) -> CamError:
        t = tok or (self.toks[self.i] if self.i < len(self.toks) else self.toks[-1])
        col = t.col if tok or self.i < len(self.toks) else t.col + len(t.value)
        return CamError(msg, t.line, col, self.file)

    def peek(self) -> Token | None:
        return self.toks[self.i] if self.i < len(self.toks) else None

    def at_op(self, v: str) -> bool:
        t = self.peek()
        return t is not None and t.kind == "OP" and t.value == v

    def take(self) -> Token:
        t = self.peek()
        if t is None:
            raise self.err("unexpected end of statement")
        self.i += 1
        return t

    def expect_op(self, v: str) -> Token:
        t = self.peek()
        if t is None or t.kind != "OP" or t.value != v:
            raise self.err(f"expected '{v}'" + (f", found {t.value!r}" if t else " at the end"))
        return self.take()

    # statements
    def statement(self) -> Statement:
        first = self.toks[0]
        # label)
        if len(self.toks) > 2 and first.kind == "NAME" and self.toks[1].value == ")":
            self.i = 2
            if self.peek() is None:
                raise self.err("a label needs a statement after it", first)
        t0 = self.peek()
        assert t0 is not None
        nxt = self.toks[self.i + 1] if self.i + 1 < len(self.toks) else None
        if nxt is not None and nxt.kind == "OP" and nxt.value == "=":
            check_name(t0, self.file)
            self.i += 2
            value = self.rhs()
            if self.peek() is not None:
                raise self.err(f"unexpected {self.peek().value!r} after the definition")  # type: ignore[union-attr]
            return Statement("assign", t0, name=t0.value, value=value)
        if t0.kind != "NAME":
            raise self.err(f"a statement starts with a word or a name, not {t0.value!r}", t0)
        prefix: list[Token] = []
        major = self.take()
        while self.at_op(","):
            self.take()
            prefix.append(major)
            major = self.take()
            if major.kind != "NAME":
                raise self.err(f"expected a word, found {major.value!r}", major)
        for p in prefix:
            if p.value not in ("TLLFT", "TLRGT", "TLON", "TLOFPS", "TLONPS"):
                raise self.err(
                    f"{p.value!r} cannot precede {major.value} (only TLLFT, TLRGT, TLON, TLOFPS, TLONPS)",
                    p,
                )
        if major.value not in MAJORS:
            if len(major.value) > NAME_MAX:
                raise self.err(
                    f"unknown word {major.value!r} (words are at most {NAME_MAX} characters)", major
                )
            raise self.err(f"unknown statement word {major.value!r}", major)
        st = Statement("command", major, major=major.value, prefix=prefix)
        t = self.peek()
        if t is not None and t.kind == "TEXT":
            st.text = self.take().value
            return st
        if self.at_op("/"):
            self.take()
            st.has_slash = True
            st.args = self.arglist()
        if self.peek() is not None:
            raise self.err(f"unexpected {self.peek().value!r}")  # type: ignore[union-attr]
        return st

    def rhs(self) -> object:
        t = self.peek()
        nxt = self.toks[self.i + 1] if self.i + 1 < len(self.toks) else None
        if t is not None and t.kind == "NAME" and t.value in MAJORS:
            if t.value not in GEOMETRY and t.value not in ("MACRO",):
                raise self.err(f"{t.value} is a statement, not something a name can be given to", t)
            self.take()
            if nxt is None or nxt.value != "/":
                raise self.err(f"expected '/' after {t.value}")
            self.take()
            return Definition(t.value, self.arglist(), t)
        return self.expr()

    def arglist(self) -> list:
        args = [self.arg()]
        while self.at_op(","):
            self.take()
            args.append(self.arg())
        return args

    def arg(self) -> object:
        t = self.peek()
        if t is None:
            raise self.err("missing argument at the end of the statement")
        if t.kind == "OP" and t.value == ",":
            raise self.err("empty argument")
        if t.kind == "NAME" and t.value in MINORS:
            self.take()
            return Minor(t.value, t)
        return self.expr()

    def expr(self) -> object:
        left = self.term()
        while self.at_op("+") or self.at_op("-"):
            op = self.take()
            left = BinOp(op.value, left, self.term(), op)
        return left

    def term(self) -> object:
        left = self.factor()
        while self.at_op("*") or self.at_op("/"):
            op = self.take()
            left = BinOp(op.value, left, self.factor(), op)
        return left

    def factor(self) -> object:
        base = self.unary()
        if self.at_op("**"):
            op = self.take()
            return BinOp("**", base, self.factor(), op)
        return base

    def unary(self) -> object:
        if self.at_op("-"):
            op = self.take()
            return Neg(self.unary(), op)
        if self.at_op("+"):
            self.take()
            return self.unary()
        return self.primary()

    def primary(self) -> object:
        t = self.take()
        if t.kind == "NUMBER":
            return Num(float(t.value), t)
        if t.kind == "OP" and t.value == "(":
            inner = self.peek()
            nxt = self.toks[self.i + 1] if self.i + 1 < len(self.toks) else None
            if (
                inner is not None
                and inner.value in GEOMETRY
                and nxt is not None
                and nxt.value == "/"
            ):
                self.i += 2
                d = Definition(inner.value, self.arglist(), inner)
                self.expect_op(")")
                return d
            e = self.expr()
            self.expect_op(")")
            return e
        if t.kind == "NAME":
            if t.value in FUNCTIONS:
                self.expect_op("(")
                args = [self.expr()]
                while self.at_op(","):
                    self.take()
                    args.append(self.expr())
                self.expect_op(")")
                return Call(t.value, args, t)
            if t.value in MAJORS:
                raise self.err(f"{t.value} is a statement word, not a value", t)
            if t.value in MINORS:
                raise self.err(f"{t.value} is a modifier, not a value", t)
            if len(t.value) > NAME_MAX:
                raise self.err(f"invalid name {t.value!r}: at most {NAME_MAX} characters", t)
            return Ref(t.value, t)
        raise self.err(f"expected a value, found {t.value!r}", t)


def parse(text: str, file: str = "<apt>") -> Iterator[Statement]:
    """The statements of APT source, parsed one at a time."""
    for toks in statements(text, file):
        yield _Parser(toks, file).statement()

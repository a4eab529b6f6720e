"""Fanuc Macro B syntax: tokens, statements and expressions of one block.

The lexer (cnc.gcode.lexer) hands a line here only when its fast word match failed, so a
plain G-code block never pays for any of this. A macro line becomes a `MacroBlock`: one
statement (assignment, IF ... GOTO, IF ... THEN, WHILE ... DO, DO, END, GOTO) or a block of
NC words whose values are variables or `[ ]` expressions (`G1 X#1 Y[#2*2] F#9`).
Expressions are compiled once into Python closures over a variable environment (`env`,
see cnc.interp.macro.MacroVariables: `env.loc` the current local variables, `env.get(n)`,
`env.set(n, v)`), so a loop body is parsed once and then only evaluated.

Values are floats, or None for a vacant variable (`#0`, or a variable never assigned).
Fanuc's rules for vacant (<vacant> is None here):

* a plain reference keeps it: `#2=#1` leaves #2 vacant, `X#1` omits the X word;
* arithmetic and functions read it as 0: `#2=#1*5` gives 0, `#2=#1+#1` gives 0;
* EQ and NE tell vacant from 0 (`#1 EQ #0` is true only while #1 is vacant); GT GE LT LE
  read it as 0.

Columns are 1-based positions in the source line (comments are blanked to spaces before,
so columns stay true). Errors are `MacroAlarm`s carrying the Fanuc alarm number.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable

from cnc.errors import NcError
from cnc.gcode.lexer import Block, MarkedBlock

Value = float | None
Expr = Callable[[object], Value]

MAX_BRACKET_NESTING = 5  # Fanuc: "[ ]" nesting, function brackets included (PS0118)
LOOP_IDS = (1, 2, 3)  # DO/END identification numbers (PS0126 outside)

# Fanuc alarm numbers (0i-F "PS" program alarms) used by the macro executor.
PS_PROGRAM_NOT_FOUND = "PS0076"
PS_NESTING = "PS0077"  # too many subprogram/macro call levels
PS_SEQUENCE_NOT_FOUND = "PS0078"  # M99 P / M98 Q sequence number not found
PS_OVERFLOW = "PS0111"
PS_ZERO_DIVIDE = "PS0112"
PS_EXPRESSION = "PS0114"  # illegal expression format
PS_VARIABLE_NUMBER = "PS0115"  # variable number out of range
PS_WRITE_PROTECTED = "PS0116"
PS_BRACKETS = "PS0118"  # more than 5 levels of [ ]
PS_ARGUMENT = "PS0119"  # function argument out of range (SQRT[-1], ASIN[2], LN[0] ...)
PS_MACRO_NESTING = "PS0122"  # too many G65/G66 macro levels
PS_DNC_JUMP = "PS0123"  # GOTO / WHILE in a streamed (DNC) program
PS_MISSING_END = "PS0124"
PS_STATEMENT = "PS0125"  # macro statement format error
PS_LOOP_NUMBER = "PS0126"  # DO/END number not 1..3, or not matching
PS_NC_AND_MACRO = "PS0127"  # NC words and a macro statement in one block
PS_GOTO_NOT_FOUND = "PS0128"  # GOTO target sequence number not found


class MacroAlarm(NcError):
    """A Macro B alarm: `alarm` is the Fanuc alarm number ("PS0128", "3015") or "".

    `fatal`: the program cannot go on after it (an alarm of the program itself, a jump or
    loop that cannot be made, the block budget): `check` records it and ends there, as the
    control would stop. Other alarms (an expression's) let `check` carry on with the next
    block, to list every error of the program.
    """

    fatal = False

    def __init__(
        self, alarm: str, message: str, line: int = 0, col: int = 0, file: str = "<program>"
    ) -> None:
        super().__init__(f"{alarm} {message}" if alarm else message, line, col, file)
        self.alarm = alarm
        self.fatal = alarm in _FATAL or alarm.isdigit() or not alarm


_FATAL = frozenset(("PS0076", "PS0077", "PS0078", "PS0122", "PS0123", "PS0124", "PS0126",
                    "PS0128"))  # fmt: skip


# --- statements ----------------------------------------------------------------------------

ASSIGN = 1  # args: ((target, expr, col), ...)  target: int or Expr (for #[...])
IF_GOTO = 2  # args: (cond, target_expr)
IF_THEN = 3  # args: (cond, assignments)
WHILE = 4  # args: (cond, loop_id)
DO = 5  # args: (loop_id,)
END = 6  # args: (loop_id,)
GOTO = 7  # args: (target_expr,)
WORDS = 8  # args: ((letter, value, col, literal_text_or_None), ...)

KIND_NAMES = {
    ASSIGN: "assignment",
    IF_GOTO: "IF GOTO",
    IF_THEN: "IF THEN",
    WHILE: "WHILE",
    DO: "DO",
    END: "END",
    GOTO: "GOTO",
    WORDS: "words",
}


class MacroBlock(MarkedBlock):
    """A block with a Macro B statement or with variables/expressions in its words.

    `kind` is one of the statement constants above, `args` its parts, `cols` the column of
    each part worth pointing at, `seq` its N number (or None), `comment` the text of the
    block's first comment (the message of `#3000=n (MESSAGE)` and `#3006=1 (MESSAGE)`).
    """

    __slots__ = ("kind", "args", "seq", "comment", "col0")

    def __init__(self, line: int, text: str) -> None:
        super().__init__(line, text)
        self.kind = 0
        self.args: tuple = ()
        self.seq: int | None = None
        self.comment = ""
        self.col0 = 1


# --- tokens -----------------------------------------------------------------------------------

_TOKEN = re.compile(
    r"\s*(?:(?P<num>(?:\d+\.?\d*|\.\d+))|(?P<name>[A-Za-z]+)|(?P<op>[#\[\]=+\-*/,:]))"
)
_FUNCS1 = {"SIN", "COS", "TAN", "ASIN", "ACOS", "ATAN", "SQRT", "ABS", "ROUND", "FIX",
           "FUP", "LN", "EXP", "BIN", "BCD"}  # fmt: skip
_MUL_OPS = {"*", "/", "AND", "MOD"}
_ADD_OPS = {"+", "-", "OR", "XOR"}
_CMP_OPS = {"EQ", "NE", "GT", "GE", "LT", "LE"}
_KEYWORDS = {"IF", "GOTO", "WHILE", "DO", "END", "THEN"}
_UNSUPPORTED = {"DPRNT", "BPRNT", "POPEN", "PCLOS", "SETVN", "ADP", "BPRINT"}


class _Tok:
    __slots__ = ("kind", "val", "col", "text")

    def __init__(self, kind: str, val, col: int, text: str) -> None:
        self.kind = kind  # "num" | "name" | "op" | "end"
        self.val = val
        self.col = col
        self.text = text


def tokenize(text: str, line: int, file: str) -> list[_Tok]:
    out: list[_Tok] = []
    pos = 0
    n = len(text)
    match = _TOKEN.match
    while pos < n:
        m = match(text, pos)
        if m is None:
            rest = text[pos:]
            stripped = rest.lstrip()
            if not stripped:
                break
            col = pos + len(rest) - len(stripped) + 1
            raise MacroAlarm(
                PS_EXPRESSION, f"unexpected character {stripped[0]!r}", line, col, file
            )
        kind = m.lastgroup
        raw = m.group(kind)
        col = m.start(kind) + 1
        if kind == "num":
            if raw.count(".") > 1:
                raise MacroAlarm(PS_EXPRESSION, f"malformed number '{raw}'", line, col, file)
            out.append(_Tok("num", float(raw), col, raw))
        elif kind == "name":
            out.append(_Tok("name", raw.upper(), col, raw))
        else:
            out.append(_Tok("op", raw, col, raw))
        pos = m.end()
    end_col = len(text.rstrip()) + 1
    out.append(_Tok("end", None, end_col, ""))
    return out


# --- values -----------------------------------------------------------------------------------


def _n(v: Value) -> float:
    return 0.0 if v is None else v


def _check(v: float, col: int) -> float:
    if math.isfinite(v):
        return v
    raise MacroAlarm(PS_OVERFLOW, "calculated value overflows (inf or NaN)", 0, col)


def _int(v: float) -> int:
    """Fanuc rounds a value used as an integer (variable number, bit operand)."""
    return int(math.floor(abs(v) + 0.5)) * (1 if v >= 0 else -1)


def fanuc_round(v: float) -> float:
    """ROUND: to the nearest integer, halves away from zero."""
    return float(_int(v))


def fix(v: float) -> float:
    """FIX: the fraction is discarded (toward zero: FIX[-1.2] = -1)."""
    return float(math.trunc(v))


def fup(v: float) -> float:
    """FUP: any fraction raises the magnitude (away from zero: FUP[-1.2] = -2)."""
    t = math.trunc(v)
    return float(t if t == v else t + (1 if v > 0 else -1))


def _arg_error(name: str, v: float, col: int) -> MacroAlarm:
    return MacroAlarm(PS_ARGUMENT, f"{name}[{v:g}]: argument out of range", 0, col)


def _bin(v: float, col: int) -> float:
    """BIN: a BCD value to binary (BIN[4660] = 1234: 4660 = 0x1234)."""
    i = _int(v)
    if i < 0:
        raise _arg_error("BIN", v, col)
    digits = f"{i:x}"
    if any(c not in "0123456789" for c in digits):
        raise _arg_error("BIN", v, col)
    return float(int(digits))


def _bcd(v: float, col: int) -> float:
    """BCD: a binary value to BCD (BCD[1234] = 4660 = 0x1234)."""
    i = _int(v)
    if i < 0:
        raise _arg_error("BCD", v, col)
    return float(int(str(i), 16))


def _func1(name: str, v: float, col: int) -> float:
    if name == "SIN":
        return math.sin(math.radians(v))
    if name == "COS":
        return math.cos(math.radians(v))
    if name == "TAN":
        c = math.cos(math.radians(v))
        if abs(c) < 1e-15:
            raise MacroAlarm(PS_OVERFLOW, f"TAN[{v:g}] is infinite", 0, col)
        return math.sin(math.radians(v)) / c
    if name == "ASIN":
        if not -1.0 <= v <= 1.0:
            raise _arg_error(name, v, col)
        return math.degrees(math.asin(v))
    if name == "ACOS":
        if not -1.0 <= v <= 1.0:
            raise _arg_error(name, v, col)
        return math.degrees(math.acos(v))
    if name == "ATAN":
        return math.degrees(math.atan(v))
    if name == "SQRT":
        if v < 0:
            raise _arg_error(name, v, col)
        return math.sqrt(v)
    if name == "ABS":
        return abs(v)
    if name == "ROUND":
        return fanuc_round(v)
    if name == "FIX":
        return fix(v)
    if name == "FUP":
        return fup(v)
    if name == "LN":
        if v <= 0:
            raise _arg_error(name, v, col)
        return math.log(v)
    if name == "EXP":
        try:
            return math.exp(v)
        except OverflowError:
            raise MacroAlarm(PS_OVERFLOW, f"EXP[{v:g}] overflows", 0, col) from None
    if name == "BIN":
        return _bin(v, col)
    if name == "BCD":
        return _bcd(v, col)
    raise AssertionError(name)


def atan2_deg(a: float, b: float) -> float:
    """ATAN[a]/[b] (and ATAN[a,b]): the angle of the point (b, a), 0 <= result < 360."""
    if a == 0.0 and b == 0.0:
        return 0.0
    d = math.degrees(math.atan2(a, b))
    return d + 360.0 if d < 0.0 else d


def power(a: float, b: float, col: int) -> float:
    if a == 0.0 and b < 0.0 or a < 0.0 and b != int(b):
        raise MacroAlarm(PS_ARGUMENT, f"POW[{a:g},{b:g}]: argument out of range", 0, col)
    try:
        return _check(math.pow(a, b), col)
    except OverflowError:
        raise MacroAlarm(PS_OVERFLOW, f"POW[{a:g},{b:g}] overflows", 0, col) from None


def binary(op: str, a: Value, b: Value, col: int) -> float:
    """One arithmetic, bit or comparison operator (also the table tests' reference)."""
    if op == "EQ":
        return 1.0 if a == b else 0.0
    if op == "NE":
        return 0.0 if a == b else 1.0
    x, y = _n(a), _n(b)
    if op == "+":
        return _check(x + y, col)
    if op == "-":
        return _check(x - y, col)
    if op == "*":
        return _check(x * y, col)
    if op == "/":
        if y == 0.0:
            raise MacroAlarm(PS_ZERO_DIVIDE, "division by zero", 0, col)
        return _check(x / y, col)
    if op == "MOD":
        i, j = _int(x), _int(y)
        if j == 0:
            raise MacroAlarm(PS_ZERO_DIVIDE, "MOD by zero", 0, col)
        return float(math.fmod(i, j))
    if op == "AND":
        return float(_int(x) & _int(y))
    if op == "OR":
        return float(_int(x) | _int(y))
    if op == "XOR":
        return float(_int(x) ^ _int(y))
    if op == "GT":
        return 1.0 if x > y else 0.0
    if op == "GE":
        return 1.0 if x >= y else 0.0
    if op == "LT":
        return 1.0 if x < y else 0.0
    if op == "LE":
        return 1.0 if x <= y else 0.0
    raise AssertionError(op)


# --- expressions: parse straight to closures --------------------------------------------------


class _Parser:
    def __init__(self, toks: list[_Tok], line: int, file: str) -> None:
        self.toks = toks
        self.i = 0
        self.line = line
        self.file = file
        self.depth = 0

    @property
    def tok(self) -> _Tok:
        return self.toks[self.i]

    def next(self) -> _Tok:
        t = self.toks[self.i]
        self.i += 1
        return t

    def fail(self, msg: str, tok: _Tok | None = None, alarm: str = PS_EXPRESSION) -> MacroAlarm:
        t = tok or self.tok
        return MacroAlarm(alarm, msg, self.line, t.col, self.file)

    def expect_op(self, op: str) -> _Tok:
        t = self.tok
        if t.kind != "op" or t.val != op:
            found = "the end of the block" if t.kind == "end" else repr(t.text)
            raise self.fail(f"'{op}' expected, found {found}")
        self.i += 1
        return t

    def is_op(self, op: str) -> bool:
        t = self.tok
        return t.kind == "op" and t.val == op

    def is_name(self, *names: str) -> bool:
        t = self.tok
        return t.kind == "name" and t.val in names

    # expr := add [cmp add]
    def expr(self) -> tuple[Expr, bool]:
        left, plain = self.add()
        t = self.tok
        if t.kind == "name" and t.val in _CMP_OPS:
            self.i += 1
            right, _ = self.add()
            return _bin_closure(t.val, left, right, t.col), False
        return left, plain

    def add(self) -> tuple[Expr, bool]:
        left, plain = self.mul()
        while True:
            t = self.tok
            if (t.kind == "op" and t.val in "+-") or (t.kind == "name" and t.val in _ADD_OPS):
                self.i += 1
                right, _ = self.mul()
                left, plain = _bin_closure(t.val, left, right, t.col), False
            else:
                return left, plain

    def mul(self) -> tuple[Expr, bool]:
        left, plain = self.unary()
        while True:
            t = self.tok
            if (t.kind == "op" and t.val in "*/") or (t.kind == "name" and t.val in _MUL_OPS):
                self.i += 1
                right, _ = self.unary()
                left, plain = _bin_closure(t.val, left, right, t.col), False
            else:
                return left, plain

    def unary(self) -> tuple[Expr, bool]:
        t = self.tok
        if t.kind == "op" and t.val in "+-":
            self.i += 1
            inner, _ = self.unary()
            if t.val == "+":
                return (lambda env, f=inner: _n(f(env))), False
            return (lambda env, f=inner: -_n(f(env))), False
        return self.primary()

    def open_bracket(self) -> None:
        t = self.expect_op("[")
        self.depth += 1
        if self.depth > MAX_BRACKET_NESTING:
            raise self.fail(
                f"more than {MAX_BRACKET_NESTING} levels of [ ] nesting", t, PS_BRACKETS
            )

    def close_bracket(self) -> None:
        self.expect_op("]")
        self.depth -= 1

    def bracketed(self) -> tuple[Expr, bool]:
        self.open_bracket()
        e, plain = self.expr()
        self.close_bracket()
        return e, plain

    def primary(self) -> tuple[Expr, bool]:
        t = self.tok
        if t.kind == "num":
            self.i += 1
            v = t.val
            return (lambda env: v), False
        if t.kind == "op" and t.val == "#":
            return self.variable(), True
        if t.kind == "op" and t.val == "[":
            return self.bracketed()
        if t.kind == "name":
            name = t.val
            if name in _FUNCS1:
                self.i += 1
                col = t.col
                arg, _ = self.bracketed_args(name)
                if name == "ATAN" and isinstance(arg, tuple):
                    a, b = arg
                    return (lambda env: atan2_deg(_n(a(env)), _n(b(env)))), False
                if isinstance(arg, tuple):
                    raise self.fail(f"{name} takes one argument", t)
                if name == "ATAN" and self.is_op("/") and self.toks[self.i + 1].val == "[":
                    self.i += 1  # ATAN[a]/[b]: the two-argument form
                    b, _ = self.bracketed()
                    a = arg
                    return (lambda env: atan2_deg(_n(a(env)), _n(b(env)))), False
                f = arg
                return (lambda env: _check(_func1(name, _n(f(env)), col), col)), False
            if name == "POW":
                self.i += 1
                col = t.col
                arg, _ = self.bracketed_args(name)
                if not isinstance(arg, tuple):
                    raise self.fail("POW takes two arguments: POW[base,exponent]", t)
                a, b = arg
                return (lambda env: power(_n(a(env)), _n(b(env)), col)), False
            if name in _UNSUPPORTED:
                raise self.fail(f"unsupported: {name} (external output)", t, PS_STATEMENT)
            raise self.fail(f"unknown function or operand {t.text!r}", t)
        if t.kind == "end":
            raise self.fail("expression expected, found the end of the block")
        raise self.fail(f"expression expected, found {t.text!r}")

    def bracketed_args(self, name: str):
        self.open_bracket()
        a, _ = self.expr()
        if self.is_op(","):
            self.i += 1
            b, _ = self.expr()
            self.close_bracket()
            return (a, b), False
        self.close_bracket()
        return a, False

    def variable(self) -> Expr:
        """`#n`, `#[expr]` (also `##n`): a closure reading the variable."""
        hash_tok = self.expect_op("#")
        t = self.tok
        col = hash_tok.col
        if t.kind == "num":
            self.i += 1
            if t.val != int(t.val):
                raise self.fail(f"variable number #{t.text} is not an integer", t)
            n = int(t.val)
            if 1 <= n <= 33:
                return lambda env: env.loc.get(n)
            if n == 0:
                return lambda env: None
            return lambda env: env.get(n, col)
        if t.kind == "op" and t.val in "[#":
            idx, _ = self.bracketed() if t.val == "[" else (self.variable(), True)
            return lambda env: env.get(var_number(idx(env), col), col)
        raise self.fail("'#' needs a variable number or [expression]", hash_tok)

    def target(self) -> tuple[int | Expr, int]:
        """The left side of an assignment: a number, or a closure giving it (#[...])."""
        hash_tok = self.expect_op("#")
        t = self.tok
        if t.kind == "num":
            self.i += 1
            if t.val != int(t.val):
                raise self.fail(f"variable number #{t.text} is not an integer", t)
            return int(t.val), hash_tok.col
        if t.kind == "op" and t.val in "[#":
            idx, _ = self.bracketed() if t.val == "[" else (self.variable(), True)
            col = hash_tok.col
            return (lambda env: var_number(idx(env), col)), col
        raise self.fail("'#' needs a variable number or [expression]", hash_tok)


def var_number(v: Value, col: int) -> int:
    """The variable number an index expression gives (rounded; vacant reads as #0)."""
    if v is None:
        return 0
    i = _int(v)
    if i < 0 or abs(v - i) > 1e-6 and abs(v) < 1e9:
        # Fanuc rounds; a clearly fractional number is more likely a program error
        raise MacroAlarm(PS_VARIABLE_NUMBER, f"variable number #{v:g} is not valid", 0, col)
    return i


def _bin_closure(op: str, a: Expr, b: Expr, col: int) -> Expr:
    # the commonest operators get closures of their own (the loop benchmark's path)
    if op == "+":
        return lambda env: _check(_n(a(env)) + _n(b(env)), col)
    if op == "-":
        return lambda env: _check(_n(a(env)) - _n(b(env)), col)
    if op == "*":
        return lambda env: _check(_n(a(env)) * _n(b(env)), col)
    if op == "LT":
        return lambda env: 1.0 if _n(a(env)) < _n(b(env)) else 0.0
    return lambda env: binary(op, a(env), b(env), col)


# --- statements -------------------------------------------------------------------------------


def _combined(p: _Parser, cond: Expr) -> Expr:
    """IF [c1] AND [c2] ... / IF [c1] OR [c2] ...: conditions joined outside the brackets
    (Fanuc 0i-F / 30i); inside brackets AND/OR stay the bit operators."""
    while p.is_name("AND", "OR") and p.toks[p.i + 1].val == "[":
        op = p.next().val
        right, _ = p.bracketed()
        left = cond
        if op == "AND":
            cond = lambda env, a=left, b=right: 1.0 if a(env) and b(env) else 0.0  # noqa: E731
        else:
            cond = lambda env, a=left, b=right: 1.0 if a(env) or b(env) else 0.0  # noqa: E731
    return cond


def _loop_id(p: _Parser) -> int:
    t = p.tok
    if t.kind != "num":
        raise p.fail("DO/END needs its loop number 1, 2 or 3", alarm=PS_LOOP_NUMBER)
    p.i += 1
    if t.val not in LOOP_IDS:
        raise p.fail(f"loop number {t.text} is not 1, 2 or 3", t, PS_LOOP_NUMBER)
    return int(t.val)


def _assignments(p: _Parser) -> tuple:
    out = []
    while p.is_op("#"):
        target, col = p.target()
        p.expect_op("=")
        if p.tok.kind == "end":
            out.append((target, lambda env: None, col))  # `#1=` makes #1 vacant
            break
        e, _ = p.expr()
        out.append((target, e, col))
    if p.tok.kind != "end":
        t = p.tok
        if t.kind == "name" and len(t.val) == 1:
            raise p.fail("NC words and a macro statement in one block", t, PS_NC_AND_MACRO)
        raise p.fail(f"unexpected {t.text!r} after the assignment", t)
    return tuple(out)


def _end_of_statement(p: _Parser) -> None:
    t = p.tok
    if t.kind != "end":
        if t.kind == "name" and len(t.val) == 1:
            raise p.fail("NC words and a macro statement in one block", t, PS_NC_AND_MACRO)
        raise p.fail(f"unexpected {t.text!r} at the end of the statement", t, PS_STATEMENT)


def _word_value(p: _Parser, letter: str):
    """The value of one address: a literal number (kept as text), `#...`, or `[...]`."""
    t = p.tok
    sign = 1.0
    if t.kind == "op" and t.val in "+-":
        sign = -1.0 if t.val == "-" else 1.0
        p.i += 1
        t = p.tok
    if t.kind == "num":
        p.i += 1
        v = sign * t.val
        return v, ("-" if sign < 0 else "") + t.text
    if t.kind == "op" and t.val == "#":
        f = p.variable()
    elif t.kind == "op" and t.val == "[":
        f, _ = p.bracketed()
    else:
        raise p.fail(f"address {letter} without a value", t)
    if sign < 0:
        g = f
        return (lambda env: None if g(env) is None else -g(env)), None
    return f, None


def parse_macro(
    text: str, raw: str, line: int, file: str, marked: MarkedBlock | None = None
) -> MacroBlock:
    """Parse one macro line (comments already blanked in `text`; `raw` the line as read)."""
    toks = tokenize(text, line, file)
    blk = MacroBlock(line, text)
    if marked is not None:
        blk.delete = marked.delete
        blk.program = marked.program
    if "(" in raw:
        i = raw.index("(")
        j = raw.find(")", i)
        blk.comment = raw[i + 1 : j].strip() if j > i else ""
    p = _Parser(toks, line, file)
    # skip what the marked-block prefix already consumed ('/', O number)
    stripped = text.lstrip()
    if marked is not None:
        while p.tok.kind != "end" and p.tok.col <= _prefix_end(text, marked):
            p.i += 1
    if p.is_name("N") and p.toks[p.i + 1].kind == "num":
        p.i += 1
        blk.seq = int(p.next().val)
    first = p.tok
    blk.col0 = first.col if first.kind != "end" else len(text) - len(stripped) + 1
    if first.kind == "name" and first.val in _KEYWORDS:
        p.i += 1
        kw = first.val
        if kw == "IF":
            if not p.is_op("["):
                raise p.fail("IF needs a [condition]", alarm=PS_STATEMENT)
            cond, _ = p.bracketed()
            cond = _combined(p, cond)
            if p.is_name("GOTO"):
                p.i += 1
                target, _ = p.expr()
                _end_of_statement(p)
                blk.kind, blk.args = IF_GOTO, (cond, target)
            elif p.is_name("THEN"):
                p.i += 1
                if not p.is_op("#"):
                    raise p.fail("THEN needs an assignment (#i=...)", alarm=PS_STATEMENT)
                blk.kind, blk.args = IF_THEN, (cond, _assignments(p))
            else:
                raise p.fail("IF [...] needs GOTO n or THEN #i=...", alarm=PS_STATEMENT)
        elif kw == "WHILE":
            if not p.is_op("["):
                raise p.fail("WHILE needs a [condition]", alarm=PS_STATEMENT)
            cond, _ = p.bracketed()
            if not p.is_name("DO"):
                raise p.fail("WHILE [...] needs DO m", alarm=PS_STATEMENT)
            p.i += 1
            blk.kind, blk.args = WHILE, (cond, _loop_id(p))
            _end_of_statement(p)
        elif kw in ("DO", "END"):
            blk.kind, blk.args = (DO if kw == "DO" else END), (_loop_id(p),)
            _end_of_statement(p)
        elif kw == "GOTO":
            target, _ = p.expr()
            _end_of_statement(p)
            blk.kind, blk.args = GOTO, (target,)
        else:
            raise p.fail(f"{kw} without IF", first, PS_STATEMENT)
        return blk
    if first.kind == "op" and first.val == "#":
        blk.kind, blk.args = ASSIGN, _assignments(p)
        return blk
    blk.kind, blk.args = WORDS, _words(p)
    return blk


def _prefix_end(text: str, marked: MarkedBlock) -> int:
    """Column of the last character of the '/' and O-number prefix of a marked block."""
    m = re.match(r"\s*(?:/\d?)?\s*(?:[Oo:]\s*\d+)?", text)
    return m.end() if m else 0


def _words(p: _Parser) -> tuple:
    items = []
    while p.tok.kind != "end":
        t = p.tok
        if t.kind == "name":
            if len(t.val) != 1:
                if t.val in _KEYWORDS:
                    raise p.fail(
                        f"NC words and a macro statement ({t.val}) in one block",
                        t,
                        PS_NC_AND_MACRO,
                    )
                if t.val in _UNSUPPORTED:
                    raise p.fail(f"unsupported: {t.val} (external output)", t, PS_STATEMENT)
                raise p.fail(f"unknown address or word {t.text!r}", t)
            p.i += 1
            letter = t.val
            if letter == "O":
                raise NcError("program number O must start the block", p.line, t.col, p.file)
            value, literal = _word_value(p, letter)
            if letter == "N" and literal is None:
                raise p.fail("N (sequence number) cannot be a variable", t)
            items.append((letter, value, t.col, literal))
        elif t.kind == "op" and t.val == "#":
            raise p.fail("NC words and an assignment in one block", t, PS_NC_AND_MACRO)
        elif t.kind == "num":
            raise NcError("number without an address letter", p.line, t.col, p.file)
        else:
            raise p.fail(f"unexpected {t.text!r}", t)
    return tuple(items)


# --- a words block, evaluated ----------------------------------------------------------------

_G_MACRO_CALL = (650, 660, 661)  # G65, G66, G66.1: M is an argument there


def build_block(mb: MacroBlock, env, file: str, least_increment: bool) -> Block | None:
    """The plain Block a WORDS macro block stands for, with every value evaluated.

    A word whose value is vacant is left out (Fanuc: `G0 X#0` is `G0`). G values are
    G codes (G#1 with #1 = 1 is G1), M values M codes; None when nothing is left.
    """
    blk = Block(mb.line, mb.text)
    words = blk.words
    nopoint = None
    call = False
    for letter, value, col, literal in mb.args:
        if literal is not None:
            v = value
            if least_increment and "." not in literal and letter not in "GMN":
                nopoint = nopoint or set()
                nopoint.add(letter)
        else:
            try:
                v = value(env)
            except MacroAlarm as err:
                err.line, err.col, err.file = mb.line, err.col or col, file
                raise
            if v is None:
                continue
        if letter == "G":
            code = round(v * 10.0)
            if abs(v * 10.0 - code) > 1e-6 or not 0 <= code < 10000:
                raise NcError(f"G{v:g} is not a G code", mb.line, col, file)
            blk.g.append(code)
            if code in _G_MACRO_CALL:
                call = True
        elif letter == "M" and not call:
            if v != int(v) or v < 0 or v > 999_999_999:
                raise NcError(f"M{v:g} is not an M code", mb.line, col, file)
            blk.m.append(int(v))
        else:
            if letter in words:
                raise NcError(f"address {letter} appears twice in the block", mb.line, col, file)
            if not -1e9 < v < 1e9:
                raise NcError(
                    f"value {v:g} of address {letter} is out of range (|value| < 1e9)",
                    mb.line,
                    col,
                    file,
                )
            words[letter] = float(v)
    blk.nopoint = nopoint
    if not (words or blk.g or blk.m):
        return None
    return blk

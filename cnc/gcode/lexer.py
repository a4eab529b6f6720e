"""Block lexer for the ISO 6983 / DIN 66025 / Fanuc word-address format.

One call of `parse_line` turns one source line into one `Block` (or None for a blank or
comment-only line). The hot path is one precompiled regular expression over the line with
comments removed and whitespace squeezed out, matching words or any stray character; only
a line with a stray character or a number float() refuses goes through the character
scanner, whose job is to say *where* and *why* it is wrong.

Columns are 1-based positions in the original line. Comments are blanked to spaces before
scanning, so columns found later (for an error in the interpreter) still match the source.
"""

from __future__ import annotations

import re

from cnc.errors import NcError
from cnc.program_memory import MAX_PROGRAM_NUMBER

# A word is an address letter and a signed number; whitespace has no meaning inside a block
# (DIN 66025 space/TAB formats), so the fast path squeezes it out first.
# One pass: a word, or any other single character (which makes the block malformed); the
# number is checked by float(), so "1.2.3" fails there and goes to the diagnosis.
_TOKEN = re.compile(r"([A-Z])([-+]?[0-9.]+)|(.)", re.S)
_SQUEEZE = str.maketrans("", "", " \t\r\n\v\f\x00\x7f")

# G numbers are kept as int(10 * value) so G50.1 and G51.1 stay exact and dict lookups fast.
_G_CODE: dict[str, int] = {}
for _n in range(100):
    for _txt in {str(_n), f"{_n:02d}", f"{_n:03d}"}:
        _G_CODE[_txt] = _G_CODE["+" + _txt] = _n * 10
        _G_CODE[_txt + "."] = _n * 10
        _G_CODE[_txt + ".0"] = _n * 10
        for _d in range(1, 10):
            _G_CODE[f"{_txt}.{_d}"] = _n * 10 + _d


class Block:
    """One block (one line) of a part program after lexing.

    `words` maps each address letter except G and M to its value; `g` holds the G codes as
    int(10 x value) (G1 -> 10, G50.1 -> 501), `m` the M codes as ints, in source order.
    `nopoint` is the set of letters written without a decimal point, filled only when the
    machine reads such numbers in least-increment style (the interpreter scales them,
    because the increment depends on G20/G21, which may be in the same block).
    `delete` (a `/` block), `program` (the O number of a program header) and `tape` (a `%`
    mark) are rare, so they are class defaults overridden only on a `MarkedBlock`.
    """

    __slots__ = ("line", "text", "words", "g", "m", "nopoint")
    delete = False
    program: int | None = None
    tape = False

    def __init__(
        self,
        line: int,
        text: str,
        words: dict[str, float] | None = None,
        g: list[int] | None = None,
        m: list[int] | None = None,
    ) -> None:
        self.line = line
        self.text = text
        self.words: dict[str, float] = {} if words is None else words
        self.g: list[int] = [] if g is None else g
        self.m: list[int] = [] if m is None else m
        self.nopoint: set[str] | None = None

    def col(self, letter: str, nth: int = 1) -> int:
        """1-based column of the `nth` occurrence of address `letter` (1 if not found)."""
        return find_col(self.text, letter, nth)

    def __repr__(self) -> str:
        return f"Block(line={self.line}, g={self.g}, m={self.m}, words={self.words})"


class MarkedBlock(Block):
    """A block with a block-delete slash, a program number or a tape mark."""

    __slots__ = ("delete", "program", "tape")

    def __init__(self, line: int, text: str) -> None:
        super().__init__(line, text)
        self.delete = False
        self.program = None
        self.tape = False


def blank_comments(text: str, line: int, file: str) -> str:
    """Replace `( ... )` and `; ...` comments with spaces (columns keep their place).

    `(` and `)` are the tape's control-out and control-in codes (the ISO code tables of the
    Fanuc-family controls, e.g. the Yasnac LX3 manual: "( control out (comment start)",
    ") control in (comment end)", what lies between them is ignored): a `(` inside a
    comment is part of it (comments do not nest: the first `)` ends it), and a `)` outside
    a comment switches on a reader that is already on, so it is ignored too:
    `( DRILL AT (61.045, 67.745) )` is a comment, its last `)` a no-op.
    """
    out = []
    i = 0
    n = len(text)
    while i < n:
        c = text[i]
        if c == "(":
            j = text.find(")", i + 1)
            if j < 0:
                raise NcError("unterminated comment: '(' without ')'", line, i + 1, file)
            out.append(" " * (j - i + 1))
            i = j + 1
            continue
        if c == ";":
            break
        if c == ")":  # control-in with no control-out before it: nothing to end
            c = " "
        out.append(c)
        i += 1
    return "".join(out)


def find_col(text: str, letter: str, nth: int = 1) -> int:
    """Column of the nth address `letter` in `text`, skipping comments; 1 when absent."""
    letter = letter.upper()
    depth = False
    seen = 0
    for i, c in enumerate(text):
        if depth:
            if c == ")":
                depth = False
            continue
        if c == "(":
            depth = True
            continue
        if c == ";":
            break
        if c.upper() == letter:
            seen += 1
            if seen == nth:
                return i + 1
    return 1


def _diagnose(text: str, line: int, file: str) -> NcError:
    """Say where and why a line that failed the fast match is malformed."""
    i = 0
    n = len(text)
    upper = text.upper()
    while i < n:
        c = upper[i]
        if c.isspace():
            i += 1
            continue
        col = i + 1
        if c == "/":
            if i > 0 and upper[:i].rstrip()[-1:].isdigit():
                return NcError("fractions not allowed (write a decimal number)", line, col, file)
            return NcError("block delete '/' must start the block", line, col, file)
        if c == "%":
            return NcError("'%' (tape start/end) must stand alone in its block", line, col, file)
        if "A" <= c <= "Z":
            j = i + 1
            while j < n and upper[j] in " \t":
                j += 1
            if j < n and upper[j] in "+-":
                j += 1
                while j < n and upper[j] in " \t":
                    j += 1
            k = j
            while k < n and (upper[k].isdigit() or upper[k] in ". \t"):
                k += 1
            num = upper[j:k].replace(" ", "").replace("\t", "")
            if not num:
                return NcError(f"address {c} without a value", line, col, file)
            if num.count(".") > 1 or num == ".":
                return NcError(f"malformed number '{num}' after address {c}", line, col, file)
            i = k
            continue
        if c.isdigit() or c in ".+-":
            return NcError("number without an address letter", line, col, file)
        return NcError(f"unexpected character {text[i]!r}", line, col, file)
    return NcError("malformed block", line, 1, file)


def _g_code_slow(num: str) -> int | None:
    """G numbers with unusual leading zeros (G0001); None when not a valid G number."""
    if num[0] in "+-" or len(num) > 12:
        return None
    try:
        v = float(num) * 10.0
    except ValueError:
        return None
    r = round(v)
    return r if abs(v - r) < 1e-6 and r < 10000 else None


def parse_line(
    text: str, line: int, file: str = "<program>", least_increment: bool = False
) -> Block | None:
    """Lex one source line into a Block; None for a blank or comment-only line.

    Raises NcError (with line and column) for malformed words, unterminated comments,
    unknown characters and fractions. A Fanuc Macro B line (variables, expressions,
    IF/WHILE/GOTO/DO/END) comes back as a `cnc.gcode.macro.MacroBlock`.
    """
    raw = text
    if "(" in text or ";" in text or ")" in text:
        text = blank_comments(text, line, file)
    body = text.strip()
    if not body:
        return None
    first = body[0]
    if first in _MARKS:
        return _parse_marked(text, body, line, file, least_increment, raw)
    squeezed = body.replace(" ", "")
    if "\t" in squeezed:
        squeezed = squeezed.replace("\t", "")
    return _words(Block(line, text), squeezed.upper(), text, line, file, least_increment, raw)


_MARKS = frozenset("%/Oo:")


def _parse_marked(
    text: str, body: str, line: int, file: str, least_increment: bool, raw: str
) -> Block | None:
    blk = MarkedBlock(line, text)
    if body[0] == "%":
        # Fanuc reads a tape or file skipping everything between the first '%' and the next
        # LF (`%O1200(NAME)` from some posts), and nothing after the closing '%'.
        blk.tape = True
        return blk
    if body[0] == "/":
        blk.delete = True
        body = body[1:]
        if body[:1].isdigit():  # /1../9: optional block-skip switches, treated as '/'
            body = body[1:]
    squeezed = body.translate(_SQUEEZE).upper()
    if squeezed[:1] in ("O", ":"):
        m = re.match(r"[O:](\d+)", squeezed)
        if not m:
            # Fanuc alarm PS0005 (no data after address): ':' is the ISO form of the program
            # number address O, and an address needs its number before the next one or EOB.
            what = "O" if squeezed[0] == "O" else "':' (the ISO form of O)"
            raise NcError(
                f"PS0005 program number {what} needs digits",
                line,
                find_col(text, squeezed[0]),
                file,
            )
        blk.program = int(m.group(1))
        if blk.program > MAX_PROGRAM_NUMBER:  # 8 digits at most (Fanuc 8-digit O option)
            raise NcError(
                f"program number O{m.group(1)} has more than 8 digits (O1..O{MAX_PROGRAM_NUMBER})",
                line,
                find_col(text, squeezed[0]),
                file,
            )
        squeezed = squeezed[m.end() :]
    return _words(blk, squeezed, text, line, file, least_increment, raw)


def _words(
    blk: Block,
    squeezed: str,
    text: str,
    line: int,
    file: str,
    least_increment: bool,
    raw: str = "",
) -> Block:
    pairs = _TOKEN.findall(squeezed)
    if not _fill(blk, pairs, text, line, file):
        if _MACRO_HINT.search(squeezed):
            return _macro(blk, text, raw or text, line, file)
        cleaned = squeezed.translate(_SQUEEZE)  # other control characters (CR, VT, NUL...)
        if cleaned == squeezed:
            raise _diagnose(text, line, file)
        blk.words.clear()
        blk.g.clear()
        blk.m.clear()
        pairs = _TOKEN.findall(cleaned)
        if not _fill(blk, pairs, text, line, file):
            raise _diagnose(text, line, file)
    words = blk.words
    if len(words) + len(blk.g) + len(blk.m) != len(pairs):
        seen: set[str] = set()
        for letter, _, _ in pairs:
            if letter in seen and letter not in _GMO:
                raise NcError(
                    f"address {letter} appears twice in the block",
                    line,
                    find_col(text, letter, 2),
                    file,
                )
            seen.add(letter)
    if least_increment:
        nopoint = {letter for letter, num, _ in pairs if "." not in num and letter not in _GMO}
        if nopoint:
            blk.nopoint = nopoint
    return blk


# A line that failed the word match is Macro B when it has any of these (then the macro
# parser says where and why, with the Fanuc alarm number).
_MACRO_HINT = re.compile(r"[#\[\]=]|GOTO|WHILE|IF|DO\d|END\d")
_MACRO_CACHE: dict[tuple[str, int, str], Block] = {}
_MACRO_CACHE_MAX = 50_000


def _macro(blk: Block, text: str, raw: str, line: int, file: str) -> Block:
    """A Macro B line, parsed once per (text, line, file) and kept (loops re-read lines)."""
    key = (raw, line, file)
    hit = _MACRO_CACHE.get(key)
    if hit is not None:
        return hit
    from cnc.gcode.macro import parse_macro  # deferred: cycle, macro imports Block from here

    mb = parse_macro(text, raw, line, file, blk if type(blk) is MarkedBlock else None)
    if len(_MACRO_CACHE) >= _MACRO_CACHE_MAX:
        _MACRO_CACHE.clear()
    _MACRO_CACHE[key] = mb
    return mb


def _fill(blk: Block, pairs: list[tuple[str, str, str]], text: str, line: int, file: str) -> bool:
    """Store the words of one block; False when the block holds anything but words."""
    words = blk.words
    for letter, num, junk in pairs:
        if junk:
            return False
        if letter in _GMO:
            if letter == "G":
                code = _G_CODE.get(num)
                if code is None:
                    code = _g_code_slow(num)
                if code is None:
                    raise NcError(
                        f"unknown G code G{num}", line, find_col(text, "G", len(blk.g) + 1), file
                    )
                blk.g.append(code)
            elif letter == "M":
                if blk.g and (650 in blk.g or 660 in blk.g):
                    # G65/G66 macro call: M is argument #13, not an M code
                    if letter in words:
                        return False
                    words[letter] = float(num)
                    continue
                if "." in num or num[0] in "+-" or len(num) > 9:
                    raise NcError(
                        f"malformed M code M{num}", line, find_col(text, "M", len(blk.m) + 1), file
                    )
                blk.m.append(int(num))
            else:
                raise NcError(
                    "program number O must start the block", line, find_col(text, "O"), file
                )
        else:
            try:
                v = words[letter] = float(num)
            except ValueError:
                return False  # "1.2.3", ".": the diagnosis says where
            if not -1e9 < v < 1e9:
                raise NcError(
                    f"number {num} after address {letter} is out of range (|value| < 1e9)",
                    line,
                    find_col(text, letter),
                    file,
                )
    return True


_GMO = frozenset("GMO")

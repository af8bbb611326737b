# G-code parsing only: one line from the intake's buffer -> command and parameter words.
#
# Numbers are kept as an integer mantissa and a count of decimals in preallocated
# arrays, so parsing a line allocates nothing per word; handlers turn a word into a
# float only when they need one. Pure logic: imports on CPython for the host tools.
from array import array

_MAX_DIGITS = 9  # keeps every mantissa below 2**30
_POW10 = (1, 10, 100, 1000, 10000, 100000, 1000000, 10000000, 100000000, 1000000000)


class GcodeError(ValueError):
    """Bad input: the line is answered with `Error:` and the reason, then the stream goes on."""


def letter_index(ch):
    return (ord(ch) & 0x1F) - 1


class Line:
    """The parsed words of one line. Owned by the parser and reused for every line."""

    def __init__(self):
        self.mant = array("i", bytes(4 * 26))
        self.decimals = array("b", bytes(26))
        self.present = 0  # bit per letter A..Z
        self.valued = 0  # bit per letter that carried a number
        self.letter = ""  # command letter G, M or T; "" for a blank line
        self.number = 0
        self.has_line_number = False
        self.line_number = 0  # the leading N word (hosts send N-1 with M110)
        self.args_text = ""  # for raw-argument commands: the text after the command

    def has(self, ch):
        return (self.present >> letter_index(ch)) & 1

    def has_value(self, ch):
        return (self.valued >> letter_index(ch)) & 1

    def float(self, ch, default=None):
        i = letter_index(ch)
        if not (self.valued >> i) & 1:
            if (self.present >> i) & 1 and default is None:
                raise GcodeError("parameter %s needs a number" % ch)
            return default
        d = self.decimals[i]
        return self.mant[i] / _POW10[d] if d else float(self.mant[i])

    def int(self, ch, default=None, lo=None, hi=None):
        i = letter_index(ch)
        if not (self.valued >> i) & 1:
            if (self.present >> i) & 1 and default is None:
                raise GcodeError("parameter %s needs a number" % ch)
            return default
        if self.decimals[i]:
            raise GcodeError("parameter %s must be a whole number" % ch)
        v = self.mant[i]
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise GcodeError("%s%d out of range %s..%s" % (ch, v, lo, hi))
        return v

    def require(self, ch):
        if not self.has_value(ch):
            raise GcodeError("missing parameter %s" % ch)


class Parser:
    def __init__(self, raw_commands=()):
        """raw_commands: (letter, number) pairs whose arguments are text, such as file
        names (M23 name.gcode) or option names (M926 Isteps_per_mm_x V80); for those
        the words after the command are not parsed and line.args_text holds them."""
        self.line = Line()
        self.raw = set(ord(l) * 10000 + n for l, n in raw_commands)

    def parse(self, buf, n):
        """Parse buf[:n] into self.line. Raises GcodeError naming the problem."""
        ln = self.line
        ln.present = 0
        ln.valued = 0
        ln.letter = ""
        ln.number = 0
        ln.has_line_number = False
        ln.line_number = 0
        ln.args_text = ""
        mant = ln.mant
        decimals = ln.decimals
        first = True
        i = 0
        while i < n:
            c = buf[i]
            if c == 32 or c == 9 or c == 13 or c == 10:
                i += 1
                continue
            if c == 59 or c == 42:  # ';' comment, '*' checksum: rest of line is not words
                break
            if c == 40:  # '(' comment up to ')'
                while i < n and buf[i] != 41:
                    i += 1
                if i >= n:
                    raise GcodeError("unclosed ( comment")
                i += 1
                continue
            if not (65 <= c <= 90 or 97 <= c <= 122):
                raise GcodeError("unexpected character %r" % chr(c))
            letter = c & 0xDF  # upper case
            idx = letter - 65
            i += 1
            while i < n and buf[i] == 32:
                i += 1
            # number: [sign] digits [. digits]
            neg = False
            if i < n and (buf[i] == 45 or buf[i] == 43):
                neg = buf[i] == 45
                i += 1
            m = 0
            d = 0
            digits = 0
            any_digit = False
            seen_dot = False
            while i < n:
                c = buf[i]
                if 48 <= c <= 57:
                    any_digit = True
                    if digits < _MAX_DIGITS:
                        if m or c != 48 or seen_dot:
                            digits += 1
                        m = m * 10 + c - 48
                        if seen_dot:
                            d += 1
                    elif not seen_dot:
                        raise GcodeError("number too long for %s" % chr(letter))
                elif c == 46 and not seen_dot:
                    seen_dot = True
                else:
                    break
                i += 1
            has_number = any_digit
            if i < n:
                c = buf[i]
                if not (c == 32 or c == 9 or c == 13 or c == 10 or c == 59 or c == 40
                        or c == 42 or 65 <= c <= 90 or 97 <= c <= 122):
                    raise GcodeError("malformed number after %s" % chr(letter))
            if (neg or seen_dot) and not has_number:
                raise GcodeError("malformed number after %s" % chr(letter))
            if first:
                first = False
                if letter == 78 and not ln.has_line_number:  # N line number first
                    if not has_number or d:
                        raise GcodeError("malformed line number")
                    ln.has_line_number = True
                    ln.line_number = -m if neg else m
                    first = True
                    continue
                elif letter in (71, 77, 84):  # G M T
                    if not has_number:
                        raise GcodeError("%s needs a number" % chr(letter))
                    if d or neg:
                        raise GcodeError("unsupported command %s%s%s" % (
                            chr(letter), "-" if neg else "", m / _POW10[d] if d else m))
                    ln.letter = "G" if letter == 71 else ("M" if letter == 77 else "T")
                    ln.number = m
                    if letter * 10000 + m in self.raw:
                        end = i
                        while end < n and buf[end] != 59 and buf[end] != 42:
                            end += 1
                        ln.args_text = bytes(buf[i:end]).decode().strip()
                        return ln
                    continue
                else:
                    raise GcodeError("line must start with G, M or T, not %s" % chr(letter))
            if (ln.present >> idx) & 1:
                raise GcodeError("parameter %s given twice" % chr(letter))
            ln.present |= 1 << idx
            if has_number:
                ln.valued |= 1 << idx
                mant[idx] = -m if neg else m
                decimals[idx] = d
        return ln

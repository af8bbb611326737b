# G-code parsing only: one line from the intake's buffer -> command and parameter words.
#
# Numbers are kept as an integer mantissa and a count of decimals in preallocated
# arrays, so parsing a line allocates nothing per word; handlers turn a word into a
# float only when they need one. The scan over the bytes is viper, as it runs for every
# line; it reports bad input as a code, and the reason is written out here. Pure logic:
# imports on CPython for the host tools.
from array import array

_MAX_DIGITS = const(9)  # keeps every mantissa below 2**30
_POW10 = (1, 10, 100, 1000, 10000, 100000, 1000000, 10000000, 100000000, 1000000000)


class GcodeError(ValueError):
    """Bad input: the line is answered with `Error:` and the reason, then the stream goes on."""


class WordsError(GcodeError):
    """The parser's: the line's words are malformed."""


def command_key(letter, number):
    """The command table's key of G1, M163, ...; _scan works it out the same way."""
    return ord(letter) * 10000 + number


def letter_index(ch):
    return (ord(ch) & 0x1F) - 1


# What _scan leaves in its result words besides the parameter words.
_R_PRESENT = const(0)
_R_VALUED = const(1)
_R_LETTER = const(2)  # command letter's code (G, M or T), 0 for none
_R_NUMBER = const(3)
_R_KEY = const(11)  # command_key of the command, 0 for none
_R_HELD = const(12)  # 1 while the Line holds text arguments (see parse)
_R_HAS_N = const(4)
_R_N = const(5)
_R_ARGS = const(6)  # raw-argument commands: index of the text after the command; else -1
_R_AT = const(7)  # the letter or character an error is about
_R_NEG = const(8)  # an unsupported command's sign, mantissa and decimals
_R_M = const(9)
_R_D = const(10)
_R_WORDS = const(13)


class Line:
    """The parsed words of one line. Owned by the parser and reused for every line."""

    def __init__(self):
        self.mant = array("i", bytes(4 * 26))
        self.decimals = array("b", bytes(26))
        self.present = 0  # bit per letter A..Z
        self.valued = 0  # bit per letter that carried a number
        self.letter = ""  # command letter G, M or T; "" for a blank line
        self.number = 0
        self.key = 0  # command_key(letter, number); 0 for a blank line
        self.args_text = ""  # for raw-argument commands: the text after the command
        # No properties on this class, nor on any other whose attributes a line stores:
        # MicroPython then looks every store up in the class first, about 20 us each on
        # the chips.

    def has(self, ch):
        return (self.present >> letter_index(ch)) & 1

    def has_value(self, ch):
        return (self.valued >> letter_index(ch)) & 1

    def float(self, ch, default=None):
        return self.float_at(letter_index(ch), default)

    def float_at(self, i, default=None):
        """float() of the letter with letter_index i."""
        if not (self.valued >> i) & 1:
            if (self.present >> i) & 1 and default is None:
                raise GcodeError("parameter %s needs a number" % chr(65 + i))
            return default
        d = self.decimals[i]
        return self.mant[i] / _POW10[d] if d else float(self.mant[i])

    def fixed_at(self, i, decimals, default=None):
        """The number of the letter with letter_index i as an exact integer count of
        10**-decimals: kept in integers, positions add up the same on every port (a
        32-bit float would drift). Further decimals round half away from zero."""
        if not (self.valued >> i) & 1:
            if (self.present >> i) & 1 and default is None:
                raise GcodeError("parameter %s needs a number" % chr(65 + i))
            return default
        d = self.decimals[i]
        m = self.mant[i]
        if d <= decimals:
            return m * _POW10[decimals - d]
        div = _POW10[d - decimals]
        q = (2 * (m if m >= 0 else -m) + div) // (2 * div)
        return q if m >= 0 else -q

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



# _scan's verdicts on bad input.
_E_UNCLOSED = const(1)
_E_CHARACTER = const(2)
_E_TOO_LONG = const(3)
_E_MALFORMED = const(4)
_E_LINE_NUMBER = const(5)
_E_NEEDS_NUMBER = const(6)
_E_UNSUPPORTED = const(7)
_E_FIRST = const(8)
_E_TWICE = const(9)
# Not bad input: the line has text arguments, or the line before had them (parse
# stores them then).
_RARE = const(16)


@micropython.viper
def _scan(buf: ptr8, n: int, words) -> int:
    """Words of buf[:n] into mant/decimals (only those present are written) and the
    result words r, with words = (mant, decimals, raw, r). raw: a count, then the keys
    of the commands whose arguments are text. Returns 0, _RARE, or an _E_ code with
    r[_R_AT] naming the letter or character."""
    mant = ptr32(words[0])
    decimals = ptr8(words[1])
    raw = ptr32(words[2])
    r = ptr32(words[3])
    present = 0
    valued = 0
    r[_R_LETTER] = 0
    r[_R_NUMBER] = 0
    r[_R_KEY] = 0
    r[_R_HAS_N] = 0
    r[_R_N] = 0
    r[_R_ARGS] = -1
    rare = r[_R_HELD]
    first = 1
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
                return _E_UNCLOSED
            i += 1
            continue
        if not ((c >= 65 and c <= 90) or (c >= 97 and c <= 122)):
            r[_R_AT] = c
            return _E_CHARACTER
        letter = c & 0xDF  # upper case
        r[_R_AT] = letter
        i += 1
        while i < n and buf[i] == 32:
            i += 1
        # number: [sign] digits [. digits]
        neg = 0
        if i < n and (buf[i] == 45 or buf[i] == 43):
            if buf[i] == 45:
                neg = 1
            i += 1
        m = 0
        d = 0
        digits = 0
        has_number = 0
        seen_dot = 0
        # The whole digits, then the decimals: a loop each, as a check per digit costs
        # the chip about as much as the digit itself.
        while i < n:
            c = buf[i]
            if c < 48 or c > 57:
                break
            has_number = 1
            if digits >= _MAX_DIGITS:
                return _E_TOO_LONG
            if m != 0 or c != 48:  # leading zeros are no digits of the mantissa
                digits += 1
            m = m * 10 + c - 48
            i += 1
        if i < n and buf[i] == 46:
            seen_dot = 1
            i += 1
            while i < n:
                c = buf[i]
                if c < 48 or c > 57:
                    break
                has_number = 1
                if digits < _MAX_DIGITS:  # decimals past those are read and dropped
                    digits += 1
                    m = m * 10 + c - 48
                    d += 1
                i += 1
        if i < n:
            # Only a blank, a comment, a checksum or the next word's letter may follow,
            # and a letter right after the digits only in upper case (G1X10Y5, as
            # Marlin reads it): 9.999e-05 or 5x is a number not to be read in part.
            c = buf[i]
            if not (c == 32 or c == 9 or c == 13 or c == 10 or c == 59 or c == 40 or c == 42
                    or (c >= 65 and c <= 90)):
                return _E_MALFORMED
        if (neg or seen_dot) and not has_number:
            return _E_MALFORMED
        if first:
            first = 0
            if letter == 78 and r[_R_HAS_N] == 0:  # N line number first
                if not has_number or d:
                    return _E_LINE_NUMBER
                r[_R_HAS_N] = 1
                r[_R_N] = -m if neg else m
                first = 1
                continue
            elif letter == 71 or letter == 77 or letter == 84:  # G M T
                if not has_number:
                    return _E_NEEDS_NUMBER
                if d or neg:
                    r[_R_NEG] = neg
                    r[_R_M] = m
                    r[_R_D] = d
                    return _E_UNSUPPORTED
                r[_R_LETTER] = letter
                r[_R_NUMBER] = m
                key = letter * 10000 + m  # command_key
                r[_R_KEY] = key
                k = raw[0]
                while k > 0:
                    if raw[k] == key:
                        r[_R_ARGS] = i
                        rare = 1
                        break
                    k -= 1
                if k > 0:
                    break
                continue
            else:
                return _E_FIRST
        bit = 1 << (letter - 65)
        if present & bit:
            return _E_TWICE
        present |= bit
        if has_number:
            valued |= bit
            mant[letter - 65] = -m if neg else m
            decimals[letter - 65] = d
    r[_R_PRESENT] = present
    r[_R_VALUED] = valued
    if rare:
        return _RARE
    return 0


def _utf8(data):
    """A handler of its own: its words would make the frame of every numbered line's
    parse too large (see Parser.parse)."""
    try:
        return data.decode()
    except UnicodeError:
        raise GcodeError("text is not UTF-8")


class Parser:
    def __init__(self, raw_commands=()):
        """raw_commands: (letter, number) pairs whose arguments are text, such as file
        names (M23 name.gcode) or option names (M926 Isteps_per_mm_x V80); for those
        the words after the command are not parsed and line.args_text holds them."""
        self.result = array("i", bytes(4 * _R_WORDS))
        self.line = Line()
        keys = [command_key(l, n) for l, n in raw_commands]
        self.raw = array("i", [len(keys)] + keys)
        self._words = (self.line.mant, self.line.decimals, self.raw, self.result)

    def parse(self, buf, n):
        """Parse buf[:n] into self.line. Raises GcodeError naming the problem."""
        # At most 11 words of locals and stack, here and in every function a line
        # calls: MicroPython gives a bytecode function with more its frame from the
        # heap at every call, and on a chip's fragmented heap that costs up to
        # hundreds of microseconds. The rare parts are methods of their own.
        ln = self.line
        r = self.result
        err = _scan(buf, n, self._words)
        if err:
            if err != _RARE:
                raise WordsError(self._reason(err))
            self._rare_words(buf, n)
        ln.present = r[_R_PRESENT]
        ln.valued = r[_R_VALUED]
        # Mostly the command of the line before (G1), whose words then stand: each
        # store costs the chips microseconds, on every line. (A key alone may be two
        # commands': G70000 and M10000.)
        key = r[_R_KEY]
        if key != ln.key or r[_R_NUMBER] != ln.number:
            ln.letter = "G" if r[_R_LETTER] == 71 else (
                "M" if r[_R_LETTER] == 77 else ("T" if r[_R_LETTER] == 84 else ""))
            ln.number = r[_R_NUMBER]
            ln.key = key
        return ln

    def line_number(self):
        """The leading N word's number of the line parsed last (hosts send N-1 with
        M110), or None. Read from the result words when asked (only M110 asks): hosts
        number every line, and storing it would cost each one a call."""
        r = self.result
        return r[_R_N] if r[_R_HAS_N] == 1 else None

    def _rare_words(self, buf, n):
        """The text arguments, which are rare: stored only where a line has them or
        the line before had them (_scan answers _RARE then)."""
        r = self.result
        r[_R_HELD] = 1  # stays so if the text is refused: the next line clears it
        self.args_text(buf, n)
        r[_R_HELD] = 1 if self.line.args_text else 0

    def args_text(self, buf, n):
        """The text after a raw-argument command, up to a comment or checksum."""
        ln = self.line
        start = self.result[_R_ARGS]
        if start < 0:
            ln.args_text = ""
            return
        end = start
        while end < n and buf[end] != 59 and buf[end] != 42:
            end += 1
        ln.args_text = ""
        ln.args_text = _utf8(bytes(buf[start:end])).strip()

    def command_of_failed(self):
        """After parse() raised: the command_key of the line's command, if its command
        word was read before the error (0 if not). A command we don't know is answered
        as unknown, not as bad words: its arguments may be text (M0 Click me)."""
        return self.result[_R_KEY]

    def failed_command(self):
        """After parse() raised, with command_of_failed() not 0: the command as text
        (G70000 and M10000 share a key, so it is not taken apart)."""
        r = self.result
        return "%s%d" % (chr(r[_R_LETTER]), r[_R_NUMBER])

    def _reason(self, err):
        r = self.result
        at = chr(r[_R_AT])
        if err == _E_UNCLOSED:
            return "unclosed ( comment"
        if err == _E_CHARACTER:
            if r[_R_AT] > 126:  # part of a UTF-8 character, in a word
                return "unexpected byte 0x%02x" % r[_R_AT]
            return "unexpected character %r" % at
        if err == _E_TOO_LONG:
            return "number too long for %s" % at
        if err == _E_MALFORMED:
            return "malformed number after %s" % at
        if err == _E_LINE_NUMBER:
            return "malformed line number"
        if err == _E_NEEDS_NUMBER:
            return "%s needs a number" % at
        if err == _E_UNSUPPORTED:
            m, d = r[_R_M], r[_R_D]
            return "unsupported command %s%s%s" % (at, "-" if r[_R_NEG] else "",
                                                   m / _POW10[d] if d else m)
        if err == _E_FIRST:
            return "line must start with G, M or T, not %s" % at
        return "parameter %s given twice" % at

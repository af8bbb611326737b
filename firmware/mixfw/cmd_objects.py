# M486: the objects of a print, as slicers label them, and cancelling one of them while
# the others go on (Marlin's CANCEL_OBJECTS). Motion skips a cancelled object's moves
# (Motion.skip): travel runs, so the position stays true; extrusion is counted, not fed.
from mixfw.gcode import GcodeError

# Object numbers M486 takes: -1 is "no object" (travel and purges between objects).
_MAX_OBJECT = const(999)


def m486_words(text):
    """M486's words: {letter: number} for T S P U, {"C": None} for C, and the name after
    A (the rest of the line, its quotes taken off: PrusaSlicer writes `M486 AName`,
    RepRapFirmware's slicers `M486 S0 A"Name"`)."""
    words = {}
    name = None
    at = 0
    n = len(text)
    while at < n:
        if text[at] in " \t":
            at += 1
            continue
        letter = text[at].upper()
        if letter == "A":
            name = text[at + 1:].strip()
            if len(name) > 1 and name[0] == name[-1] == '"':
                name = name[1:-1]
            break
        end = at + 1
        while end < n and text[end] not in " \t":
            end += 1
        value = text[at + 1:end]
        if letter == "C" and not value:
            words["C"] = None
        elif letter in "TSPU" and letter not in words:
            try:
                words[letter] = int(value)
            except ValueError:
                raise GcodeError("M486 %s needs a whole number, got %r" % (letter, value))
        else:
            raise GcodeError("M486 takes T S P U C and A<name>, not %r" % text[at:end])
        at = end
    return words, name


class Objects:
    def __init__(self, motion, reply):
        self.motion = motion
        self.reply = reply
        self._reset(0)

    def _reset(self, count):
        self.count = count  # as M486 T said, or the highest number seen, plus one
        self.current = -1
        self.cancelled = set()
        self.names = {}
        self.motion.skip(False)

    def _number(self, words, letter, lo=0):
        i = words[letter]
        if not lo <= i <= _MAX_OBJECT:
            raise GcodeError("M486 %s%d: objects are %d..%d" % (letter, i, lo, _MAX_OBJECT))
        return i

    def _start(self, i):
        """Object i's moves follow (-1: no object's)."""
        self.current = i
        if i >= self.count:
            self.count = i + 1
        self.motion.skip(i in self.cancelled)

    # M486 T<count> | S<object> [A<name>] | A<name> | P<object> | U<object> | C: the
    # objects of a print. T: a new print of so many objects, none cancelled; S: the
    # moves that follow are that object's (S-1: none's); A names the current object
    # (or S's); P cancels an object, U brings it back, C cancels the current one: a
    # cancelled object's moves are skipped, its travel kept. No words: report.
    # Example: M486 P2
    def m486(self, line):
        words, name = m486_words(line.args_text)
        if "T" in words:
            self._reset(self._number(words, "T"))
        if "S" in words:
            self._start(self._number(words, "S", -1))
        if name is not None:
            if self.current < 0:
                raise GcodeError("M486 A names the current object, and none is (M486 S)")
            self.names[self.current] = name
        if "P" in words:
            i = self._number(words, "P")
            self.cancelled.add(i)
            self.reply("echo:object %d cancelled" % i)
            if i == self.current:
                self.motion.skip(True)
        if "U" in words:
            i = self._number(words, "U")
            self.cancelled.discard(i)
            if i == self.current:
                self.motion.skip(False)
        if "C" in words:
            if self.current < 0:
                raise GcodeError("M486 C cancels the current object, and none is")
            self.cancelled.add(self.current)
            self.reply("echo:object %d cancelled" % self.current)
            self.motion.skip(True)
        if not words and name is None:
            self.report()

    def report(self):
        for i in range(self.count):
            self.reply("echo:object %d%s%s%s" % (
                i, " " + self.names[i] if i in self.names else "",
                " (printing)" if i == self.current else "",
                " cancelled" if i in self.cancelled else ""))
        self.reply("echo:objects:%d current:%d cancelled:%s" % (
            self.count, self.current,
            ",".join(str(i) for i in sorted(self.cancelled)) or "none"))

# On-board trace capture: the step loop keeps every STEP/DIR write (tick since the
# start, set mask, clear mask) in a ring preallocated at start-up (trace_records), and
# M7301 hands them to the host, which turns them into a VCD (`mixstep trace pull`).
# Masks are in step-loop bit space: bit g is GPIO g, except ESP32's GPIO 32/33 on
# bits 28/29. Loaded at the first M7300 or M7301 (Printer.add_lazy_command): one Trace
# for each, whose state is the step loop's words.
from mixfw import stepper as st
from mixfw.gcode import GcodeError


class Trace:
    def __init__(self, mem, settings, reply):
        self.mem = mem
        self.tick_us = settings["tick_us"]
        self.reply = reply

    def _need_ring(self):
        if self.mem[st.S_CAP_SIZE] < 2:
            raise GcodeError("no trace ring: set trace_records (M926), M500 and restart")

    # M7300 S1 | S0: start recording step events from an empty ring, or stop. No S:
    # report. Example: M7300 S1
    def m7300(self, line):
        m = self.mem
        if not line.has("S"):
            self.reply("echo:trace %s records=%d overrun=%d" % (
                "recording" if m[st.S_CAP_ON] else "stopped", self._count(), m[st.S_CAP_LOST]))
            return
        if line.int("S") not in (0, 1):
            raise GcodeError("M7300 S must be 0 (stop) or 1 (start)")
        if line.int("S") == 0:
            m[st.S_CAP_ON] = 0
            return
        self._need_ring()
        m[st.S_CAP_ON] = 0
        m[st.S_CAP_HEAD] = 0
        m[st.S_CAP_TAIL] = 0
        m[st.S_CAP_LOST] = 0
        m[st.S_CAP_T0] = m[st.S_TICKS]
        m[st.S_CAP_ON] = 1

    def _count(self):
        m = self.mem
        n = m[st.S_CAP_HEAD] - m[st.S_CAP_TAIL]
        return n + m[st.S_CAP_SIZE] if n < 0 else n

    # M7301: send the recorded events and empty the ring; recording goes on if it
    # was on. Lines: trace:begin ..., trace:<tick>,<set>,<clr> each, trace:end.
    def m7301(self, line):
        self._need_ring()
        m = self.mem
        head = m[st.S_CAP_HEAD]
        tail = m[st.S_CAP_TAIL]
        size = m[st.S_CAP_SIZE]
        base = m[st.S_CAP_BASE]
        n = head - tail
        if n < 0:
            n += size
        reply = self.reply
        reply("trace:begin tick_us=%d records=%d overrun=%d" % (self.tick_us, n, m[st.S_CAP_LOST]))
        while tail != head:
            r = base + tail * st.CAP_WORDS
            reply("trace:%d,%d,%d" % (m[r], m[r + 1], m[r + 2]))
            tail = tail + 1 if tail + 1 < size else 0
            m[st.S_CAP_TAIL] = tail
        reply("trace:end")

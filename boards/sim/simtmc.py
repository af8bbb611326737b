# The board's TMC2209 drivers on their shared single-wire UART, as machine.UART sees
# them: bytes written come back at once as the one-wire echo; whole datagrams are
# CRC-checked and go to the driver at their address, which keeps its registers,
# counts the writes it takes in IFCNT and answers reads (after the echo), as the
# datasheet's UART interface describes. A datagram with a bad CRC is ignored, as a
# driver ignores it.
#
# A driver without motor power doesn't answer at all. Which ones start so:
# MIXSTEP_SIM_TMC_OFF=x,e0 in the environment. Sim-only command:
#   M7106                    one `//tmc` line per driver: powered, registers, and
#                            where its motor was (steps) when CHOPCONF was last
#                            written: a change of microsteps must wait for the moves
#   M7106 P<address> S<0|1>  motor power off or on; on, the driver starts again from
#                            its reset values (GSTAT's reset flag set)
import os
from mixfw import tmc

# The simulated chip (simmachine.py), which binds itself here when it loads this module.
simmachine = None


def bind(machine):
    global simmachine
    simmachine = machine


# Power-on values (TMC2209 datasheet): GCONF I_scale_analog and pdn_disable, GSTAT
# reset, CHOPCONF 0x10000053 (MRES 0: 256 microsteps, but the MS1/MS2 pins count
# until mstep_reg_select is set), IHOLD_IRUN IRUN 31 IHOLD 16 IHOLDDELAY 1.
_RESET = {tmc.GCONF: 0x00000041, tmc.GSTAT: 0x00000001, tmc.IFCNT: 0,
          tmc.IHOLD_IRUN: 0x00011F10, tmc.CHOPCONF: 0x10000053}
_WRITE_ONLY = (tmc.IHOLD_IRUN,)

drivers = {}  # address -> SimTMC2209 of the board's bus, once the firmware opens it


class SimTMC2209:
    def __init__(self, name, address, powered=True):
        self.name = name
        self.address = address
        self.powered = powered
        self.regs = dict(_RESET)
        self.steps_at_chopconf = 0

    def power(self, on):
        if on and not self.powered:
            self.regs = dict(_RESET)
        self.powered = on

    def datagram(self, d):
        """The answer to one whole datagram addressed to it (b"" for none)."""
        if not self.powered:
            return b""
        register = d[2] & 0x7F
        if d[2] & 0x80:
            value = (d[3] << 24) | (d[4] << 16) | (d[5] << 8) | d[6]
            if register == tmc.GSTAT:  # flags clear where a 1 is written
                value = self.regs[tmc.GSTAT] & ~value
            self.regs[register] = value
            if register == tmc.CHOPCONF and self.name in simmachine.step_names:
                self.steps_at_chopconf = simmachine.positions[
                    simmachine.step_names.index(self.name)]
            self.regs[tmc.IFCNT] = (self.regs[tmc.IFCNT] + 1) & 0xFF
            return b""
        value = 0 if register in _WRITE_ONLY else self.regs.get(register, 0)
        a = bytearray((0x05, 0xFF, register, (value >> 24) & 0xFF, (value >> 16) & 0xFF,
                       (value >> 8) & 0xFF, value & 0xFF, 0))
        a[7] = tmc.crc8(a, 7)
        return bytes(a)

    def describe(self):
        return "//tmc %s address=%d powered=%d steps_at_chopconf=%d %s" % (
            self.name, self.address, self.powered, self.steps_at_chopconf, " ".join(
                "%s=0x%08x" % (tmc.REGISTER_NAMES[r], self.regs[r]) for r in sorted(self.regs)))


class UART:
    """machine.UART on the board's TMC_UART pins: the drivers' bus."""

    def __init__(self, id, baudrate=9600, tx=None, rx=None, timeout=0, timeout_char=0,
                 **kw):
        import board
        bus = getattr(board, "TMC_UART", None)
        pins = (getattr(tx, "gpio", tx), getattr(rx, "gpio", rx))
        if not bus or pins != (bus["tx"], bus["rx"]) or id != bus.get("uart"):
            raise ValueError("the simulated chip has no device on UART %r tx=%r rx=%r"
                             % (id, pins[0], pins[1]))
        off = [n for n in os.getenv("MIXSTEP_SIM_TMC_OFF", "").split(",") if n]
        drivers.clear()
        for name, address in bus["addresses"].items():
            drivers[address] = SimTMC2209(name, address, name not in off)
        self._rx = bytearray()
        self._pending = bytearray()

    def any(self):
        return len(self._rx)

    def read(self, n=None):
        if not self._rx:
            return None  # nothing within the timeout
        n = len(self._rx) if n is None else min(n, len(self._rx))
        got = bytes(self._rx[:n])
        self._rx = bytearray(self._rx[n:])
        return got

    def write(self, data):
        self._rx.extend(data)  # the one-wire echo
        p = bytes(self._pending) + bytes(data)
        while p:
            if p[0] & 0x0F != 0x05:  # not a sync nibble: a driver waits for one
                p = p[1:]
                continue
            size = 8 if len(p) > 2 and p[2] & 0x80 else 4
            if len(p) < size:
                break
            d = p[:size]
            p = p[size:]
            driver = drivers.get(d[1])
            if tmc.crc8(d, size - 1) == d[size - 1] and driver is not None:
                self._rx.extend(driver.datagram(d))
        self._pending = bytearray(p)
        return len(data)


# M7106 [P<address> S<0|1>]: the TMC drivers' registers, or power one off or on.
# Simulation only. Example: M7106 P0 S0
def m7106(printer, line):
    if line.has("P"):
        line.require("S")
        address = line.int("P", lo=0, hi=3)
        if address not in drivers:
            raise ValueError("no simulated TMC2209 at address %d" % address)
        drivers[address].power(bool(line.int("S", lo=0, hi=1)))
        return
    for address in sorted(drivers):
        printer.reply(drivers[address].describe())


def install(printer):
    printer.register("M7106", lambda line: m7106(printer, line))  # simulation: TMC drivers

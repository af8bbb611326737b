# TMC2209 stepper drivers on one single-wire UART, as on boards whose driver sockets
# share PDN_UART: the register values that settings give, the UART datagrams, and a
# driver that writes through a UART object passed in and confirms every write.
#
# Without UART writes a TMC2209 takes its microsteps from the MS1/MS2 pins, which on
# a shared bus are also its address (MS2 MS1: 00 8, 01 32, 10 64, 11 16 microsteps):
# the axes of one board would step differently. So every driver gets GCONF with
# mstep_reg_select (CHOPCONF's MRES counts, not the pins), pdn_disable (the pin is the
# UART, not power-down) and I_scale_analog clear (current from IRUN alone, not VREF).
#
# Datagrams (TMC2209 datasheet, UART interface): sync+reserved 0x05, node address
# 0..3, register (bit 7 set to write), 4 data bytes MSB first, CRC8. A read request
# has no data; the driver answers with 0x05, 0xFF, register, data, CRC. TX and RX are
# joined through a resistor, so every byte written comes back on RX first: a read
# skips its own echo. IFCNT counts the writes a driver took, which confirms each one.
#
# Runs in the main loop only (at start and when the options change), never from an
# interrupt. Pure logic: imports on CPython.

GCONF = const(0x00)
GSTAT = const(0x01)
IFCNT = const(0x02)
IHOLD_IRUN = const(0x10)
CHOPCONF = const(0x6C)

REGISTER_NAMES = {GCONF: "GCONF", GSTAT: "GSTAT", IFCNT: "IFCNT",
                  IHOLD_IRUN: "IHOLD_IRUN", CHOPCONF: "CHOPCONF"}

_SYNC = const(0x05)
_MASTER = const(0xFF)  # the address an answer carries
_WRITE = const(0x80)

# GCONF bits
I_SCALE_ANALOG = const(1 << 0)
EN_SPREADCYCLE = const(1 << 2)
PDN_DISABLE = const(1 << 6)
MSTEP_REG_SELECT = const(1 << 7)
MULTISTEP_FILT = const(1 << 8)
# GSTAT: set when the driver was reset (its registers are back at their defaults),
# cleared by writing 1
GSTAT_RESET = const(1 << 0)
# CHOPCONF fields: Klipper's TMC2209 chopper defaults (toff 3, hstrt 5, hend 0,
# TBL 2) with step interpolation to 256 microsteps.
_CHOP_BASE = const(3 | (5 << 4) | (0 << 7) | (2 << 15) | (1 << 28))
VSENSE = const(1 << 17)
MRES_SHIFT = const(24)
# IHOLD_IRUN: IHOLDDELAY 8, the gentle step down to the hold current Klipper uses.
_IHOLDDELAY = const(8 << 16)

# Full-scale sense voltages (mV) for vsense 0 and 1, and the TMC2209's 20 mOhm of
# internal resistance in series with the sense resistor.
_VFS_MV = (325, 180)
_RSENSE_EXTRA_MOHM = const(20)

_ATTEMPTS = const(3)
# The settings' axis (X Y Z E) of each driver a board may put on the UART; E is the
# board's E socket.
AXIS_OF = {"x": 0, "y": 1, "z": 2, "e0": 3}


class TmcError(ValueError):
    """A driver that doesn't answer or doesn't take a write, or a setting it can't
    have: answered with `Error:` and the reason."""


def crc8(data, n=None):
    """The datagram CRC: polynomial 0x07, initial 0, each byte fed LSB first (the
    order the UART sends its bits)."""
    crc = 0
    for i in range(len(data) if n is None else n):
        b = data[i]
        for _ in range(8):
            if (crc >> 7) ^ (b & 1):
                crc = ((crc << 1) ^ 0x07) & 0xFF
            else:
                crc = (crc << 1) & 0xFF
            b >>= 1
    return crc


def write_datagram(address, register, value):
    d = bytearray((_SYNC, address, register | _WRITE, (value >> 24) & 0xFF,
                   (value >> 16) & 0xFF, (value >> 8) & 0xFF, value & 0xFF, 0))
    d[7] = crc8(d, 7)
    return bytes(d)


def read_datagram(address, register):
    d = bytearray((_SYNC, address, register, 0))
    d[3] = crc8(d, 3)
    return bytes(d)


def parse_reply(data, register):
    """The value in an 8-byte answer to a read of register, None if it isn't one."""
    if (data is None or len(data) != 8 or data[0] != _SYNC or data[1] != _MASTER
            or data[2] != register or crc8(data, 7) != data[7]):
        return None
    return (data[3] << 24) | (data[4] << 16) | (data[5] << 8) | data[6]


def mres(microsteps):
    """CHOPCONF's MRES for a microstep count: 256 -> 0 .. 1 (full steps) -> 8."""
    for m in range(9):
        if 256 >> m == microsteps:
            return m
    raise TmcError("%r microsteps: a TMC2209 takes 1, 2, 4, 8, 16, 32, 64, 128 or 256"
                   % (microsteps,))


def microsteps_of(mres_value):
    return 256 >> mres_value if mres_value <= 8 else 0


def strap_microsteps(address):
    """What a driver steps on when no write reached it: its MS1/MS2 straps, which are
    its address (MS1 bit 0, MS2 bit 1)."""
    return (8, 32, 64, 16)[address]


def _bits(current_ma, sense_mohm, vsense):
    """Current scale CS (0..31) nearest current_ma, from the datasheet's
    I_rms = (CS + 1) / 32 * V_fs / (R_sense + 20 mOhm) / sqrt(2), in integers (sqrt(2)
    to 8 digits), so every port rounds alike."""
    num = 32 * 141421356 * (sense_mohm + _RSENSE_EXTRA_MOHM) * current_ma
    den = 100000000 * 1000 * _VFS_MV[vsense]
    return (2 * num + den) // (2 * den) - 1


def current_ma(cs, sense_mohm, vsense):
    """The RMS current CS gives, in mA (rounded down)."""
    return (cs + 1) * _VFS_MV[vsense] * 1000 * 100000000 // (
        32 * 141421356 * (sense_mohm + _RSENSE_EXTRA_MOHM))


def max_current_ma(sense_mohm):
    return current_ma(31, sense_mohm, 0)


def current_fields(run_ma, sense_mohm):
    """(vsense, irun, ihold) for a run current: vsense 1 (the finer scale) when it
    reaches run_ma, and a hold current of half the run current, as Marlin holds."""
    top = max_current_ma(sense_mohm)
    if run_ma > top:
        raise TmcError("run current %d mA is above the %d mA a %d mOhm sense resistor "
                       "allows" % (run_ma, top, sense_mohm))
    vsense = 1 if _bits(run_ma, sense_mohm, 1) <= 31 else 0
    irun = max(0, min(31, _bits(run_ma, sense_mohm, vsense)))
    ihold = max(0, min(31, _bits(run_ma // 2, sense_mohm, vsense)))
    return vsense, irun, ihold


def registers(microsteps, run_ma, spreadcycle, sense_mohm):
    """(GCONF, IHOLD_IRUN, CHOPCONF) for one driver's settings."""
    vsense, irun, ihold = current_fields(run_ma, sense_mohm)
    gconf = PDN_DISABLE | MSTEP_REG_SELECT | MULTISTEP_FILT
    if spreadcycle:
        gconf |= EN_SPREADCYCLE
    chop = _CHOP_BASE | (mres(microsteps) << MRES_SHIFT) | (VSENSE if vsense else 0)
    return gconf, ihold | (irun << 8) | _IHOLDDELAY, chop


class Driver:
    """One TMC2209 on the shared UART, at its address. uart: write(bytes), read(n)
    returning what arrived within the UART's timeout (None if nothing), any()."""

    def __init__(self, uart, name, address):
        self.uart = uart
        self.name = name
        self.address = address
        self.written = {}  # register -> value the driver confirmed
        self._ifcnt = -1  # its write counter as last read; -1: not yet

    def __str__(self):
        return "%s driver (TMC2209 address %d)" % (self.name, self.address)

    def _exchange(self, request, answer_bytes):
        uart = self.uart
        stale = uart.any()
        if stale:  # an answer that came too late for an earlier request
            uart.read(stale)
        uart.write(request)
        got = uart.read(len(request) + answer_bytes)
        if got is None or len(got) < len(request) or got[:len(request)] != request:
            # Without its own echo the bus itself is broken: TX not joined to RX.
            raise TmcError("%s: the UART did not echo what was sent: check the TX/RX "
                           "pins and their resistor" % self)
        return got[len(request):]

    def read(self, register):
        for _ in range(_ATTEMPTS):
            value = parse_reply(self._exchange(read_datagram(self.address, register), 8),
                                register)
            if value is not None:
                return value
        raise TmcError("%s does not answer on the UART (is the motor power on?)" % self)

    def write(self, register, value):
        """Write one register and confirm it by the driver's write counter."""
        if self._ifcnt < 0:
            self._ifcnt = self.read(IFCNT) & 0xFF
        for _ in range(_ATTEMPTS):
            self._exchange(write_datagram(self.address, register, value), 0)
            count = self.read(IFCNT) & 0xFF
            took = count == (self._ifcnt + 1) & 0xFF
            self._ifcnt = count
            if took:
                self.written[register] = value
                return
        raise TmcError("%s did not take the write of %s" % (
            self, REGISTER_NAMES.get(register, "register 0x%02x" % register)))

    def configure(self, wanted):
        """wanted: ((register, value), ...). Writes the registers whose value the driver
        hasn't confirmed; raises TmcError naming the driver if one doesn't take."""
        for register, value in wanted:
            if self.written.get(register) != value:
                self.write(register, value)

    def was_reset(self):
        """True if the driver lost its registers (a power cycle of the motor supply)
        since they were written; it forgets what it confirmed then."""
        if self.read(GSTAT) & GSTAT_RESET or not self.written:
            self.written = {}
            self._ifcnt = -1
            return True
        return False


class Drivers:
    """Every TMC2209 on the board's UART, configured from the settings."""

    def __init__(self, uart, tmc_uart):
        """tmc_uart: the board's TMC_UART."""
        self.sense_mohm = tmc_uart["sense_mohm"]
        # The settings' axis index of each driver: X Y Z and the E socket (e0).
        self.drivers = [(Driver(uart, name, address), AXIS_OF[name])
                        for name, address in sorted(tmc_uart["addresses"].items(),
                                                    key=lambda item: item[1])]

    def wanted(self, settings, axis):
        gconf, ihold_irun, chop = registers(
            settings["driver_microsteps"][axis], settings["driver_current_ma"][axis],
            settings["driver_spreadcycle"][axis], self.sense_mohm)
        # GSTAT first: writing its reset flag clears it, so a later reset shows.
        return ((GSTAT, GSTAT_RESET), (GCONF, gconf), (IHOLD_IRUN, ihold_irun),
                (CHOPCONF, chop))

    def check(self, settings):
        """Raise TmcError for a setting no driver can take, before anything is written."""
        for driver, axis in self.drivers:
            try:
                self.wanted(settings, axis)
            except TmcError as e:
                raise TmcError("%s: %s" % (driver.name, e))

    def apply(self, settings):
        """Configure every driver; returns the problems (one text per driver that
        failed), after trying them all. A change of microsteps comes through M930,
        whose first applier drains the queue: no move is under way when it lands."""
        self.check(settings)
        problems = []
        for driver, axis in self.drivers:
            try:
                driver.configure(self.wanted(settings, axis))
            except TmcError as e:
                problems.append(str(e))
        return problems

    def status(self, settings):
        """One line per driver for M122, configuring first any driver that was reset
        or never answered."""
        lines = []
        for driver, axis in self.drivers:
            try:
                if driver.was_reset():
                    driver.configure(self.wanted(settings, axis))
                chop = driver.read(CHOPCONF)
                gconf = driver.read(GCONF)
                irun = driver.written[IHOLD_IRUN] >> 8 & 31
                lines.append("%s: %d microsteps, run %d mA, %s" % (
                    driver, microsteps_of(chop >> MRES_SHIFT & 15),
                    current_ma(irun, self.sense_mohm, 1 if chop & VSENSE else 0),
                    "spreadCycle" if gconf & EN_SPREADCYCLE else "stealthChop"))
            except TmcError as e:
                lines.append("%s; without UART set-up it steps %d microsteps" % (
                    e, strap_microsteps(driver.address)))
        return lines

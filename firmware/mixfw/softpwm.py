# A heater's PWM made in software, for frequencies below what the chip's PWM makes
# (pwm.heater_output).
#
# Pure logic: imports on CPython too.
import time


class SoftPwm:
    """A heater switched from the main loop's background tasks: one pulse a period (a
    relay switches twice a period, no more), as long as the duty asks. A lower duty
    ends the pulse at once, a higher one waits for the next period; duty 0 turns the
    pin off before duty_u16 returns. The edges are as exact as the main loop's turns
    (a few ms, 10 at most while busy). A main loop that stalls leaves the pin as it
    was, on or off, until the watchdog resets the board (which releases the pin)."""

    def __init__(self, pin, hz):
        self.pin = pin
        self.period_ms = 1000 // hz
        self.on_ms = 0  # what the duty asks for
        self.pulse_ms = 0  # this period's pulse; 0 once it has ended
        self.start_ms = time.ticks_ms()
        self.level = 0

    def duty_u16(self, d):
        self.on_ms = d * self.period_ms // 65535  # below 2**26: a small int anywhere
        if d == 0:
            self._set(0)  # at once: a halt turns the heaters off first, then reports

    def update(self, now_ms):
        elapsed_ms = time.ticks_diff(now_ms, self.start_ms)
        if elapsed_ms >= self.period_ms:
            # Periods keep their length while the loop keeps up; after a long turn
            # the next one starts now.
            if elapsed_ms < 2 * self.period_ms:
                self.start_ms = time.ticks_add(self.start_ms, self.period_ms)
                elapsed_ms -= self.period_ms
            else:
                self.start_ms = now_ms
                elapsed_ms = 0
            self.pulse_ms = self.on_ms
        if elapsed_ms < self.pulse_ms and elapsed_ms < self.on_ms:
            self._set(1)
        else:
            self.pulse_ms = 0
            self._set(0)

    def _set(self, level):
        if level != self.level:
            self.level = level
            self.pin.value(level)

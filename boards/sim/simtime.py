# The simulated chip's clock, standing in for `time` so that every timeout, PID period
# and busy message in the firmware runs on virtual time. Sleeping advances it.
import simmachine


def ticks_us():
    return simmachine.now_us


def ticks_ms():
    return simmachine.now_us // 1000


def ticks_diff(a, b):
    return a - b


def ticks_add(t, delta):
    return t + delta


def sleep_ms(ms):
    sleep_us(ms * 1000)


def sleep_us(us):
    end = simmachine.now_us + us
    while simmachine.now_us < end:
        simmachine.idle()


def sleep(s):
    sleep_us(int(s * 1000000))


def time():
    return simmachine.now_us // 1000000

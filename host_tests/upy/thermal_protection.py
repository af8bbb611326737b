# A hot end's Heater driven by hand every control period (100 ms) through temperature
# profiles, its readings from a fake ADC: for each profile, when protection fired (ms),
# why, and the heater's duty then.
import json
import math

from mixfw.thermal import Heater


class Adc:
    temp_c = 22.0

    def read_u16(self):
        if self.temp_c is None:
            return 65535
        r = 100000.0 * math.exp(3950.0 * (1 / (self.temp_c + 273.15) - 1 / 298.15))
        return int(65535 * r / (r + 4700.0) + 0.5)


class Pwm:
    def freq(self, hz):
        pass

    def duty_u16(self, d):
        self.d = d


settings = {}
for k, v in (("beta", 3950.0), ("r25_ohm", 100000.0), ("pullup_ohm", 4700.0),
             ("sh_a", 0.0), ("sh_b", 0.0), ("sh_c", 0.0), ("kp", 0.1), ("ki", 0.0),
             ("kd", 0.0), ("pwm_hz", 10), ("min_c", 5.0), ("max_c", 285.0),
             ("watch_s", 20.0), ("watch_rise_c", 2.0), ("runaway_c", 10.0),
             ("runaway_s", 20.0)):
    settings["hotend_" + k] = v


def run(profile, target_c=200.0, until_ms=150000):
    adc, pwm = Adc(), Pwm()
    h = Heater("hotend", adc, pwm)
    h.configure(settings)
    h.set_target(target_c, 0)
    now = 0
    while now < until_ms:
        now += 100
        adc.temp_c = profile(now)
        reason = h.control(now, 0.1)
        if reason:
            return [now, reason, pwm.d]
    return [None, None, pwm.d]


# Heats 3 C/s to 200 C (at 59.3 s) and holds; faults begin at 70 s.
def heat(now):
    return min(22.0 + 3.0 * now / 1000, 200.0)


out = {
    "ok": run(heat),
    "open": run(lambda now: None if now >= 70000 else heat(now)),
    "short": run(lambda now: 400.0 if now >= 70000 else heat(now)),
    # stalls at 30 s, half way to the target
    "stall": run(lambda now: heat(min(now, 30000))),
    # drops 11 C below the target at 70 s and stays there
    "runaway": run(lambda now: 189.0 if now >= 70000 else heat(now)),
    # drops 9 C: inside runaway_c, not a fault
    "dip": run(lambda now: 191.0 if now >= 70000 else heat(now)),
    # slow, but just over 2 C every 19.9 s is enough
    "slow": run(lambda now: 22.0 + 2.05 * (now // 19900), until_ms=200000),
}
print(json.dumps(out))

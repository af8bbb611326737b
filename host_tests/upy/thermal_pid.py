# The PID's output and integral through a long heat-up far below the target, just past
# it, and far above it.
import json

from mixfw.thermal import Pid

pid = Pid()
pid.kp, pid.ki, pid.kd = 0.05, 0.01, 0.0
# A long heat-up far below the target: saturated at full power.
outs = [pid.update(200.0, 25.0, 0.1) for _ in range(5000)]
i_saturated = pid.i_term
# Just past the target: without windup the output drops at once.
past = pid.update(200.0, 201.0, 0.1)
# Far above the target: saturated at 0, integral does not go below 0.
for _ in range(5000):
    low = pid.update(100.0, 200.0, 0.1)
print(json.dumps([max(outs), min(outs), i_saturated, past, low, pid.i_term]))

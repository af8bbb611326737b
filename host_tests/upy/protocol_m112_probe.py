# The simulated printer (boards/sim/sim_main.py, argv[2]) recording its STEP/DIR edges
# to argv[1], with one probe: when the receive path calls emergency_stop(), the virtual
# time is printed ("//m112 seen_us="). That is the moment M112 was seen; the trace
# says when the last STEP edge came.
import sys

import simmachine
import simtime

sys.modules['machine'] = simmachine
sys.modules['time'] = simtime
from mixfw import printer as P  # noqa: E402

_stop = P.Printer.emergency_stop


def _probe(self):
    sys.stdout.write('//m112 seen_us=%d\n' % simmachine.now_us)
    _stop(self)


P.Printer.emergency_stop = _probe
edges, sim_main = sys.argv[1:3]
sys.argv[:] = ['sim_main.py', '--edges', edges]
exec(open(sim_main).read())

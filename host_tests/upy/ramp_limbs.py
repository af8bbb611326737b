# ramp.py's helpers on two 30-bit limbs, for the cases on stdin (JSON); argv[1] names
# which: isqrt (each value's isqrt_limbs), div (each [value, divisor]'s div_limbs:
# the quotient's limbs and the remainder) or product (each [a, b, c, s, how]'s
# product(): what it returns and the limbs it leaves).
import json
import sys
from array import array

from uctypes import addressof

from mixfw import ramp

w = array("i", bytes(4 * ramp.IO_WORDS))
w4 = addressof(w) >> 2  # the helpers take the array as its address over 4
out = []
which = sys.argv[1]
for case in json.loads(sys.stdin.read()):
    if which == "isqrt":
        v = case
        w[ramp.IO_HI] = v >> 30
        w[ramp.IO_LO] = v & 0x3FFFFFFF
        out.append(ramp.isqrt_limbs(w4))
    elif which == "div":
        v, c = case
        w[ramp.IO_HI] = v >> 30
        w[ramp.IO_LO] = v & 0x3FFFFFFF
        ramp.div_limbs(w4, c)
        out.append([w[ramp.IO_HI], w[ramp.IO_LO], w[ramp.IO_HI + 2]])
    else:
        for k, v in enumerate(case):  # product()'s operands: w's last five
            w[ramp.IO_WORDS - 5 + k] = v
        x = ramp.product(w4)
        out.append([x, w[ramp.IO_HI], w[ramp.IO_LO]])
print(json.dumps(out))

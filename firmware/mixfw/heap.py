# The heap's big blocks. On a chip without the firmware frozen in, every module's code
# loads into the heap and leaves small gaps between its pieces, and the step loop's
# arrays each need one whole block: a reserve held while the modules load keeps a
# region whole for them, and each array takes one block, not two.
import gc
from array import array

# Blocks held for builds to come, the one for the next build last.
_reserves = []


def reserve(nbytes):
    """Hold nbytes of the heap in one block, for a build to come, while the modules
    load."""
    gc.collect()
    _reserves.append(bytearray(nbytes))


def release():
    """Give the next build's reserve back, just before it takes its arrays."""
    if _reserves:
        _reserves.pop()
        gc.collect()


@micropython.viper
def _clear(buf, n: int):
    p = ptr32(buf)
    for i in range(n):
        p[i] = 0


def zeros(words):
    """An array('i') of zeros in one block: array('i', bytes(4 * words)) takes the bytes
    as well, twice the heap for a moment. A range has a length, so array() takes the
    whole block at once."""
    a = array("i", range(words))
    _clear(a, words)
    return a

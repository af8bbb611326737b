"""Whether a call takes anything from the heap, even what it gives back at once: a
bytecode function whose locals and stack pass 11 words gets its frame from the heap
at every call, and frees it on return, so gc.mem_alloc() never shows it, and
micropython.heap_lock() makes the VM take the frame from the C stack instead. With
gc.threshold(1) any allocation collects first, and the garbage left before the call
is then gone. On a chip's fragmented heap one such allocation costs up to hundreds
of microseconds."""
import gc


def _garbage():
    bytearray(8000)


def allocates(fn, a, b):
    gc.collect()
    _garbage()
    before = gc.mem_alloc()
    gc.threshold(1)
    fn(a, b)
    gc.threshold(-1)
    return gc.mem_alloc() < before - 4000


def _small(a, b):
    return a


def _wide(a, b):  # a frame of more than 11 words
    c = d = e = f = g = h = i = j = k = l = a  # noqa: E741
    return c


for _ in range(3):  # the probe's own first calls
    allocates(_small, 7, 2)
assert not allocates(_small, 7, 2) and allocates(_wide, 7, 2)

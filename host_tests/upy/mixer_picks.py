"""The drive the step loop's mixer picks for each E step: the mixer is run by the
step loop itself (stepper.run_mix) on E-only blocks of the given moves (signed; a
move [steps, weights] changes the mix). Run as a script: cases from stdin (JSON, a
list of [weights, moves] or [weights, moves, ring_steps]), each case's picks as a line
of drive digits."""
import json
import sys

from mixfw import mixer, stepper


def picks(weights, moves, normalize=True, ring_steps=2048):
    seq = []

    def out(set_mask, clr_mask):
        d = 0
        while set_mask >> d != 1:
            d += 1
        seq.append(d)

    if normalize:
        weights = mixer.normalize(weights, len(weights))
    stepper.run_mix(weights, moves, out, ring_steps)
    return seq


if __name__ == "__main__":
    for case in json.loads(sys.stdin.read()):
        moves = [m if isinstance(m, int) else tuple(m) for m in case[1]]
        ring = case[2] if len(case) > 2 else 2048  # the firmware's
        print("".join(str(d) for d in picks(case[0], moves, False, ring)))

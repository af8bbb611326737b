"""The drive the step loop's mixer picks for each E step: the mixer is run by the
step loop itself (stepper.run_mix) on E-only blocks of the given moves (signed; a
move [steps, weights] changes the mix). Run as a script: cases from stdin (JSON, a
list of [weights, moves]), each case's picks as a line of drive digits."""
import json
import sys

from mixfw import mixer, stepper


def picks(weights, moves, normalize=True):
    seq = []

    def out(set_mask, clr_mask):
        d = 0
        while set_mask >> d != 1:
            d += 1
        seq.append(d)

    if normalize:
        weights = mixer.normalize(weights, len(weights))
    stepper.run_mix(weights, moves, out)
    return seq


if __name__ == "__main__":
    for weights, moves in json.loads(sys.stdin.read()):
        moves = [m if isinstance(m, int) else tuple(m) for m in moves]
        print("".join(str(d) for d in picks(weights, moves, False)))

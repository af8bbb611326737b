"""The drive the step loop's mixer picks for each E step: the schedule is run by the
step loop itself (stepper.run_mix) on E-only blocks of the given moves (signed)."""
from mixfw import mixer, stepper


def picks(weights, moves):
    seq = []

    def out(set_mask, clr_mask):
        d = 0
        while set_mask >> d != 1:
            d += 1
        seq.append(d)

    stepper.run_mix(mixer.normalize(weights, len(weights)), moves, out)
    return seq

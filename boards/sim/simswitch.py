# The printer's switches, set by a sim-only command:
#   M7105 S<us>  every min endstop bounces for S us after the step that reaches it and
#                after the one that leaves it: its level flips six times at irregular
#                points before it settles, as a mechanical switch's contacts do
#                (simmachine.set_bounce). S0, the default: clean edges.
import simmachine


# M7105 S<us>: bounce the endstops for S us (S0: no bounce). Simulation only.
# Example: M7105 S5000
def m7105(line):
    line.require("S")
    simmachine.set_bounce(line.int("S", lo=0, hi=1000000))


def install(printer):
    printer.register("M7105", m7105)  # simulation: endstops bounce for S<us>

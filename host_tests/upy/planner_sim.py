"""The simulated board's printer for the planner scripts, with its planner (pl) and
two stand-ins for filament.plan_e_words, the viper call that plans each drive's
filament: viper calls it and counts the lines it planned (fast[0]); python plans none
(returns 0 after its counts), so that every plan is filament.plan_e's in Python. whole
is the real one; use(fn) puts fn where the planner and plan_e call it."""
import simbuild
from mixfw import filament, planner

printer = simbuild.printer()
pl = printer.planner
whole = filament.plan_e_words
fast = [0]


def use(fn):
    planner.plan_e_words = fn
    filament.plan_e_words = fn


def python(words, e_nm, nm, rem):
    return whole(words, 0, nm, rem) and 0  # counts only


def viper(words, e_nm, nm, rem):
    done = whole(words, e_nm, nm, rem)
    fast[0] += done
    return done

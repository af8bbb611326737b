"""`mixstep esteps`: steps per mm of filament worked out from the drive geometry, and
the M-codes that set it.

The filament moves as fast as the surface of the drive gear (no slip, no squash), so
one turn of the gear feeds pi x drive diameter of filament, and one turn of the gear
takes motor_steps x microsteps x gear_ratio steps.

mixstep's E axis is millimetres of *filament* (as Marlin and RepRapFirmware), so that
is the value the M-codes set. The older steps-per-mm-of-*extrudate* value (early
RepRap firmware's E_STEPS_PER_MM) is also given for a nozzle: by conserving volume,
with the extrudate taken as a cylinder of the nozzle's diameter, 1 mm of extrudate
is (nozzle/filament)^2 mm of filament.
"""
import math

from mixfw.mixer import MAX_DRIVES


def filament_steps_per_mm(motor_steps, microsteps, gear_ratio, drive_diameter_mm):
    """Steps that feed 1 mm of filament. gear_ratio is motor turns per drive-gear turn."""
    for name, value in (("motor_steps", motor_steps), ("microsteps", microsteps),
                        ("gear_ratio", gear_ratio), ("drive_diameter_mm", drive_diameter_mm)):
        if not value > 0:
            raise ValueError("%s must be > 0, got %r" % (name, value))
    steps_per_gear_turn = motor_steps * microsteps * gear_ratio
    filament_per_gear_turn_mm = math.pi * drive_diameter_mm
    return steps_per_gear_turn / filament_per_gear_turn_mm


def step_volume_mm3(filament_steps_per_mm_value, filament_mm):
    """Volume of filament one step feeds."""
    return filament_area_mm2(filament_mm) / filament_steps_per_mm_value


def filament_area_mm2(diameter_mm):
    if not diameter_mm > 0:
        raise ValueError("diameter must be > 0, got %r" % diameter_mm)
    return math.pi * (diameter_mm / 2.0) ** 2


def extrudate_steps_per_mm(filament_steps_per_mm_value, filament_mm, nozzle_mm):
    """Steps per mm of a nozzle-diameter cylinder of extrudate (volume conserved)."""
    filament_mm_per_extrudate_mm = filament_area_mm2(nozzle_mm) / filament_area_mm2(filament_mm)
    return filament_steps_per_mm_value * filament_mm_per_extrudate_mm


def mcodes(steps_per_mm, drive=None):
    """The lines that set the value: every drive at once (M92 applies at once; the
    M926 form only changes the setting, so M930 follows it), or one drive's option."""
    value = "%.3f" % steps_per_mm
    if drive is None:
        return ["M92 E" + value, "M926 Isteps_per_mm_e V%s ; or this, then M930" % value]
    if not 0 <= drive < MAX_DRIVES:
        raise ValueError("--drive %d: the firmware's drives are 0 to %d"
                         % (drive, MAX_DRIVES - 1))
    return ["M926 Idrive_steps_per_mm_%d V%s" % (drive, value), "M930"]


def report(motor_steps, microsteps, gear_ratio, drive_diameter_mm, filament_mm,
           nozzle_mm=None, drive=None):
    """What the command prints, as lines."""
    spm = filament_steps_per_mm(motor_steps, microsteps, gear_ratio, drive_diameter_mm)
    lines = [
        "filament steps/mm: %.3f  (%g steps x %g microsteps x %g gear / (pi x %g mm drive))"
        % (spm, motor_steps, microsteps, gear_ratio, drive_diameter_mm),
        "filament fed per step: %.6f mm, %.6f mm^3 of %g mm filament"
        % (1.0 / spm, step_volume_mm3(spm, filament_mm), filament_mm),
    ]
    if nozzle_mm is not None:
        lines.append(
            "extrudate steps/mm: %.4f  (older convention: per mm of a %g mm-diameter "
            "extrudate cylinder, = filament steps/mm x (%g/%g)^2; mixstep does not use it)"
            % (extrudate_steps_per_mm(spm, filament_mm, nozzle_mm), nozzle_mm, nozzle_mm,
               filament_mm))
    lines.append("; set it (then M500 to keep it):")
    lines.extend(mcodes(spm, drive))
    return lines


def add_parser(sub):
    p = sub.add_parser("esteps", help="steps/mm of filament from the drive geometry, and its M-codes")
    p.add_argument("--motor-steps", type=float, required=True, help="full steps per motor turn")
    p.add_argument("--microsteps", type=float, required=True)
    p.add_argument("--gear-ratio", type=float, default=1.0, help="motor turns per drive-gear turn")
    p.add_argument("--drive-diameter-mm", type=float, required=True,
                   help="effective diameter of the drive gear where it grips the filament")
    p.add_argument("--filament-mm", type=float, required=True, help="filament diameter")
    p.add_argument("--nozzle-mm", type=float, help="also give steps per mm of extrudate")
    p.add_argument("--drive", type=int, help="print the M926 line for this drive only")
    p.set_defaults(run=_run)


def _run(args):
    for line in report(args.motor_steps, args.microsteps, args.gear_ratio,
                       args.drive_diameter_mm, args.filament_mm, args.nozzle_mm, args.drive):
        print(line)
    return 0

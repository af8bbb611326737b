"""`mixstep esteps`: steps/mm from drive geometry, checked against the worked examples
of the RepRap extruder document (a RepRap 3 mm extruder, early firmware's steps per mm of extrudate)."""
import math

import pytest

from mixstep import cli, esteps


def test_common_geared_extruder_filament_steps_per_mm():
    # 200-step motor, 1/16 microstepping, 3:1 gears, 7.3 mm hobbed gear.
    spm = esteps.filament_steps_per_mm(200, 16, 3, 7.3)
    assert spm == pytest.approx(9600 / (math.pi * 7.3))
    assert spm == pytest.approx(418.599, abs=5e-4)


@pytest.mark.parametrize("drive_mm, gear, step_volume_mm3, extrudate_spm", [
    # The document: 5 mm splined shaft, direct: 0.278 mm^3 per half step, E_STEPS_PER_MM 0.705.
    (5.0, 1, 0.278, 0.705),
    # The document: 8 mm brass insert, 5:1 gears: 0.0885 mm^3 per half step, 2.21.
    (8.0, 5, 0.0885, 2.21),
])
def test_the_documents_worked_examples(drive_mm, gear, step_volume_mm3, extrudate_spm):
    # 200 steps driven in half steps = 400 per turn, 3 mm filament, 0.5 mm nozzle.
    spm = esteps.filament_steps_per_mm(200, 2, gear, drive_mm)
    # The document rounds its intermediate values to 3 figures, hence 0.5 %.
    assert esteps.step_volume_mm3(spm, 3.0) == pytest.approx(step_volume_mm3, rel=5e-3)
    assert esteps.extrudate_steps_per_mm(spm, 3.0, 0.5) == pytest.approx(extrudate_spm, rel=5e-3)


def test_extrudate_value_conserves_volume():
    spm = esteps.filament_steps_per_mm(200, 16, 3, 7.3)
    e_spm = esteps.extrudate_steps_per_mm(spm, 1.75, 0.4)
    # The steps for 1 mm of extrudate feed exactly its volume of filament.
    fed_volume_mm3 = e_spm * esteps.step_volume_mm3(spm, 1.75)
    assert fed_volume_mm3 == pytest.approx(math.pi * 0.2 ** 2)


def test_bad_geometry_is_refused_by_name():
    with pytest.raises(ValueError, match="drive_diameter_mm"):
        esteps.filament_steps_per_mm(200, 16, 3, 0)


def test_cli_prints_the_mcodes(capsys):
    assert cli.main(["esteps", "--motor-steps", "200", "--microsteps", "16", "--gear-ratio", "3",
                     "--drive-diameter-mm", "7.3", "--filament-mm", "1.75",
                     "--nozzle-mm", "0.4"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert "M92 E418.599" in out
    assert any(l.startswith("M926 Isteps_per_mm_e V418.599") for l in out)
    assert any(l.startswith("extrudate steps/mm: 21.8") for l in out)  # 418.599 x (0.4/1.75)^2


def test_cli_per_drive_form(capsys):
    cli.main(["esteps", "--motor-steps", "200", "--microsteps", "16", "--gear-ratio", "3",
              "--drive-diameter-mm", "7.3", "--filament-mm", "1.75", "--drive", "2"])
    out = capsys.readouterr().out.splitlines()
    assert "M926 Idrive_steps_per_mm_2 V418.599" in out
    assert "M930" in out
    assert not any(l.startswith("M92 ") for l in out)

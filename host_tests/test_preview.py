"""`mixstep preview`: the moving-average mixture model against hand-worked cases, and
the picture of the example print."""
import numpy as np
import pytest

from mixstep import cli, paths, preview

EXAMPLE = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"
CURA = paths.ROOT / "testdata" / "cura_part_3tool.gcode"
A, B = [1.0, 0.0], [0.0, 1.0]


def test_step_change_gives_linear_ramp_of_length_l2_starting_l1_later():
    l1, l2 = 1.0, 1.5
    x = np.array([-3.0, 0.0, 5.0, 5.9999, 6.0, 6.375, 6.75, 7.5, 7.9, 20.0])
    r = preview.moving_average(x, [(0.0, A), (5.0, B)], l1, l2)
    # Fraction of B: 0 until 5 + L1, then (x - 6) / 1.5 until 5 + L1 + L2, then 1.
    want_b = [0, 0, 0, 0, 0, 0.25, 0.5, 1, 1, 1]
    assert r[:, 1] == pytest.approx(want_b, abs=1e-9)
    assert r.sum(axis=1) == pytest.approx(np.ones(len(x)))  # stays stochastic
    # The outgoing mix is half and half at L0 = L1 + L2/2 after the change.
    assert preview.moving_average([5.0 + l1 + l2 / 2], [(0.0, A), (5.0, B)], l1, l2)[0] \
        == pytest.approx([0.5, 0.5])


def test_pulse_shorter_than_l2_never_comes_out_pure():
    # 0.5 mm of B between A: at most 0.5/1.5 of B reaches the nozzle, as a trapezoid.
    changes = [(0.0, A), (10.0, B), (10.5, A)]
    # The window [x - 2.5, x - 1] meets B's [10, 10.5] from x = 11 to x = 13.
    x = np.array([11.0, 11.25, 11.5, 12.0, 12.5, 12.75, 13.0, 13.25])
    r = preview.moving_average(x, changes, 1.0, 1.5)
    assert r[:, 1] == pytest.approx([0, 1 / 6, 1 / 3, 1 / 3, 1 / 3, 1 / 6, 0, 0], abs=1e-9)


def test_zero_l2_is_a_pure_delay_and_history_before_zero_is_the_first_mix():
    r = preview.moving_average([0.5, 2.9, 3.1], [(0.0, A), (2.0, B)], 1.0, 0.0)
    assert r.tolist() == [A, A, B]
    r = preview.moving_average([0.0, 2.0], [(0.0, B)], 1.0, 1.5)
    assert r.tolist() == [B, B]  # the nozzle starts primed with the first mix


def test_history_forgets_only_what_cannot_be_asked_again():
    h = preview.MixHistory(A)
    for i in range(1, 50):
        h.change(float(i), B if i % 2 else A)
    before = h.outgoing([40.0, 45.0], 1.0, 1.5)
    h.forget_before(40.0 - 2.5)
    assert len(h.starts_mm) < 15
    assert h.outgoing([40.0, 45.0], 1.0, 1.5) == pytest.approx(before)


def test_gcode_outflow_ignores_retraction_and_travel(tmp_path):
    # T0 prints 10 mm of filament along X, retracts, travels, primes, T1 prints 10 mm
    # more. The change is at outflow 10 mm: red until 11, ramp to 12.5, blue after.
    g = tmp_path / "two.gcode"
    g.write_text("M83\nT0\nG1 Z0.2\nG1 X100 E10 ; ten 10 mm moves would do too\n"
                 "G1 E-2\nG1 X0 Y10\nG1 E2\nT1\nG1 X100 E10\n")
    tp = preview.Toolpath(3, 1.0, 1.5)
    pieces = list(tp.pieces(g))
    assert [p[0] for p in pieces] == [0, 0]  # one layer
    _, _, xy, mix, out = pieces[1]
    assert mix.tolist() == [0, 1, 0]
    x_along_mm = 10.0 + (xy[:-1, 0] + xy[1:, 0]) / 2 / 100 * 10  # move 2 runs x = 0..100
    want_b = np.clip((x_along_mm - 11.0) / 1.5, 0, 1)
    assert out[:, 1] == pytest.approx(want_b, abs=1e-9)
    blend = preview.blend_mask(out, tp.used_mixes)
    assert blend.any() and not blend[0] and not blend[-1]
    assert tp.tool_changes == [(0, 0.0, 10.0, 0.2, "T1")]


def test_matrix_tools_and_mcodes_in_the_file(tmp_path):
    g = tmp_path / "m.gcode"
    g.write_text("M163 S0 P1\nM163 S1 P3\nM164 S1\nT1\nG1 X10 E1\n")
    tp = preview.Toolpath(3, 1.0, 1.5, matrix=[[1, 0, 0], [0, 0, 1]])
    out = list(tp.pieces(g))[0][4]
    assert out[0] == pytest.approx([0.25, 0.75, 0])  # the file's M164 wins


def test_r_arcs_are_drawn_on_their_circle(tmp_path):
    g = tmp_path / "arc.gcode"
    g.write_text("M83\nT0\nG1 X10 Y0 Z0.2\nG2 X0 Y-10 R10 E2\n")
    (_, _, xy, _, _), = preview.Toolpath(3, 1.0, 1.5).pieces(g)
    assert len(xy) > 10
    assert np.hypot(xy[:, 0], xy[:, 1]) == pytest.approx(10.0, abs=1e-6)


def test_cura_file_layers_and_changes():
    """Cura's output: every layer drawn, two changes in each layer after the first."""
    tp = preview.Toolpath(3, 1.0, 1.5)
    layers = {piece[0] for piece in tp.pieces(CURA)}
    assert layers == set(range(20))
    assert len(tp.tool_changes) == 40
    assert {c[4] for c in tp.tool_changes} == {"T0", "T1", "T2"}
    assert all(sum(c[0] == n for c in tp.tool_changes) == 2 for n in range(20))


def _png_colours(path):
    import matplotlib.image
    img = matplotlib.image.imread(path)
    return img, {tuple(c) for c in (img[::3, ::3, :3] * 255).astype(int).reshape(-1, 3)}


def test_cli_draws_the_first_layer_that_blends(tmp_path, capsys):
    png = tmp_path / "p.png"
    assert cli.main(["preview", str(EXAMPLE), "-o", str(png)]) == 0
    assert "layer 0" in capsys.readouterr().out  # T0 -> T2 on the first layer
    img, colours = _png_colours(png)
    assert img.shape[0] > 500 and img.shape[1] > 500
    assert (224, 48, 48) in colours and (240, 208, 32) in colours  # red and yellow drawn
    assert len(colours) > 50  # blended shades, not just a few flat colours


def test_compare_and_3d_views_write_pngs(tmp_path):
    png = tmp_path / "cmp.png"
    drawn = preview.render([EXAMPLE, EXAMPLE], png, layer=3)
    assert [d.layer for d in drawn] == [3, 3]
    assert [len(np.concatenate(d.outgoing)) for d in drawn][0] > 100
    assert {c[4] for c in drawn[0].tool_changes} == {"T0", "T1"}
    img, _ = _png_colours(png)
    assert img.shape[1] > 1.6 * img.shape[0]  # two views side by side
    png3 = tmp_path / "3d.png"
    drawn = preview.render([EXAMPLE], png3, all_layers_3d=True)
    assert drawn[0].layer is None and len(drawn[0].segments) > 1000
    _, colours = _png_colours(png3)
    assert len(colours) > 50


def test_compare_with_advance_shows_the_blend_centred_on_the_designed_boundary(tmp_path):
    """Where the slicer changes colour, the plain print still gives the old colour pure
    (the nozzle's delay L1); after `mixstep advance` by L0 = L1 + L2/2 the colour there
    is half way between the two, which is what advance is for."""
    from mixstep import advance
    l1_mm, l2_mm = 1.0, 1.5
    advanced = tmp_path / "advanced.gcode"
    advance.advance_file(EXAMPLE, advanced, l1_mm + l2_mm / 2)
    plain, moved = preview.render([EXAMPLE, advanced], tmp_path / "cmp.png", l1_mm=l1_mm,
                                  l2_mm=l2_mm, layer=3)

    def outgoing_where_a_piece_starts(drawn, x, y):
        for seg, out in zip(drawn.segments, drawn.outgoing):
            hit = np.flatnonzero((np.abs(seg[:, 0, 0] - x) < 1e-6) & (np.abs(seg[:, 0, 1] - y) < 1e-6))
            if len(hit):
                return out[hit[0]]
        raise AssertionError("no piece starts at %g, %g" % (x, y))

    assert len(plain.tool_changes) >= 2
    for _, x, y, _, label in plain.tool_changes:
        new = int(label[1:])
        before = outgoing_where_a_piece_starts(plain, x, y)
        after = outgoing_where_a_piece_starts(moved, x, y)
        assert before[new] < 0.01, (label, before)
        assert abs(after[new] - 0.5) < 0.1, (label, after)

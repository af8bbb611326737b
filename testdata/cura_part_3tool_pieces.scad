// The example part (part.scad) cut along X into three pieces, one per extruder, so
// that Cura changes tools within every layer:
//   openscad -D piece=0 -o piece0.stl testdata/cura_part_3tool_pieces.scad
piece = 0;
cuts_mm = [0, 14, 27, 40];
intersection() {
    include <part.scad>
    translate([cuts_mm[piece], -1, -1]) cube([cuts_mm[piece + 1] - cuts_mm[piece], 32, 6]);
}

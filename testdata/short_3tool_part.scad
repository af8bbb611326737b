// A short part for host tests (test_octoprint.py): 12 x 12 x 1.2 mm with a hole,
// six 0.2 mm layers. How it was sliced: short_3tool_m117_prusaslicer.txt.
difference() {
    cube([12, 12, 1.2]);
    translate([6, 6, -1]) cylinder(r=2.5, h=4, $fn=32);
}

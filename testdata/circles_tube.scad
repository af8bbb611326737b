// A thin tube for the chip bench (bench/chip.py, chip_underruns): its walls are
// circles of 0.2 mm facets, so PrusaSlicer's perimeters are about 0.2 mm segments.
// How it was sliced: circles_tube_prusaslicer.txt.
difference() {
    cylinder(r=10, h=3, $fn=314);
    translate([0, 0, -1]) cylinder(r=8.5, h=5, $fn=268);
}

// A vase for the chip bench: its wall is a circle of 500 facets that widens from
// r 12 mm to r 24 mm and twists as it rises, so PrusaSlicer's spiral (vase mode) is
// segments of 0.15 to 0.32 mm. How it was sliced: vase_3mix_prusaslicer.txt.
linear_extrude(height=30, twist=30, scale=2, slices=60) circle(r=12, $fn=500);

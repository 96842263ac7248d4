"""mesh stage."""

#: contour tiling between slices: "dp" (minimum area, dynamic programming) or "greedy"
CONTOUR_TILINGS = ("dp", "greedy")

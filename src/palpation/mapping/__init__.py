"""Top-view vessel maps (SPEC §12): per-marker predictions reprojected onto a 1 mm/px world grid,
the operating-point rule, per-pixel statistics and d-bar (Fig. 7, Table 4 lower half)."""

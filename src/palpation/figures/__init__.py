"""Every figure of the project, one module per figure family; drawing functions take `ax` first.

calibration (Fig. 4, search history), markers_overlay (detected markers on photos), loop (residual
quivers, mode shares, rounds), pr_curves (Fig. 6), maps (Fig. 7 confusion maps, threshold selection),
realdata (Meat and Silicone set overviews), twin_render (the twin's marker figure and one video per
simulated trajectory).
"""

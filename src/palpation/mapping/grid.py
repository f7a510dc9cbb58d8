"""Top-view grids at 1 mm per pixel and their world -> pixel rules (SPEC §12).

Each dataset has its own rule, spelled out per axis so the three read as in the SPEC table:
* Silicone: fixed workspace x in [-425, -245], y in [-54, 46] mm; col = 179 - floor(x - x0),
  row = floor(y - y0); 100 x 180, one map for all 10 sweeps.
* Meat: data bounds (floor/ceil) +- 3 px; row = floor(x - x_lo), col = floor(y_hi - y); one map per trial.
* Sim: data bounds +- 3 px; rows +x, cols +y; one map per slide.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MODES = ("up", "down", "mirror")
MARGIN_PX = 3  # SPEC §12: data-bounded grids get 3 px of border
DEFAULT_MAX_GRID_PX = 20_000_000  # ~20 M px of float32 + 2 bool layers is ~120 MB


@dataclass(frozen=True)
class Axis:
    """One grid axis: world coordinate `world` (0 = x, 1 = y) in mm over [lo, lo + size).

    mode "up": index = floor(w - lo); "down": floor(hi - w); "mirror": size - 1 - floor(w - lo).
    """

    world: int
    lo: float
    size: int
    mode: str = "up"

    def __post_init__(self):
        if self.mode not in MODES:
            raise ValueError(f"grid axis mode {self.mode!r} unknown; use one of {MODES}")
        if self.size < 1:
            raise ValueError(f"grid axis size must be >= 1 px, got {self.size}")

    @property
    def hi(self) -> float:
        return self.lo + self.size

    def index(self, w: np.ndarray) -> np.ndarray:
        w = np.asarray(w, np.float64)
        if self.mode == "up":
            return np.floor(w - self.lo).astype(np.int64)
        if self.mode == "down":
            return np.floor(self.hi - w).astype(np.int64)
        return self.size - 1 - np.floor(w - self.lo).astype(np.int64)

    def centre_mm(self, i: np.ndarray) -> np.ndarray:
        """World coordinate of pixel centres `i` (inverse of `index` at half-pixels)."""
        i = np.asarray(i, np.float64)
        if self.mode == "up":
            return self.lo + i + 0.5
        if self.mode == "down":
            return self.hi - i - 0.5
        return self.lo + (self.size - 1 - i) + 0.5


@dataclass(frozen=True)
class Grid:
    rows: Axis
    cols: Axis

    @property
    def shape(self) -> tuple[int, int]:
        return (self.rows.size, self.cols.size)

    @property
    def n_px(self) -> int:
        return self.rows.size * self.cols.size

    def indices(self, world_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(..., 2) world mm -> row, col and whether the point lies on the grid."""
        w = np.asarray(world_xy, np.float64)
        r, c = self.rows.index(w[..., self.rows.world]), self.cols.index(w[..., self.cols.world])
        inside = (r >= 0) & (r < self.rows.size) & (c >= 0) & (c < self.cols.size)
        return r, c, inside

    def to_dict(self) -> dict:
        return {name: {"world": "xy"[a.world], "lo_mm": a.lo, "size_px": a.size, "mode": a.mode}
                for name, a in (("rows", self.rows), ("cols", self.cols))}


def silicone_grid() -> Grid:
    """The fixed Silicone workspace, 100 rows (y) x 180 cols (x, mirrored)."""
    return Grid(rows=Axis(1, -54.0, 100, "up"), cols=Axis(0, -425.0, 180, "mirror"))


def _bounds(values: np.ndarray, margin: int) -> tuple[float, int]:
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        raise ValueError("cannot size a grid from no finite world points; is the prediction set empty?")
    lo, hi = math.floor(v.min()) - margin, math.ceil(v.max()) + margin
    return float(lo), int(hi - lo)


def meat_grid(world_xy: np.ndarray, margin: int = MARGIN_PX) -> Grid:
    """Shared Meat grid from all trials' points: rows +x from x_lo, cols -y from y_hi."""
    x_lo, nx = _bounds(world_xy[..., 0], margin)
    y_lo, ny = _bounds(world_xy[..., 1], margin)
    return Grid(rows=Axis(0, x_lo, nx, "up"), cols=Axis(1, y_lo, ny, "down"))


def sim_grid(world_xy: np.ndarray, margin: int = MARGIN_PX) -> Grid:
    """Shared Sim grid: rows +x, cols +y, data bounds +- `margin`."""
    x_lo, nx = _bounds(world_xy[..., 0], margin)
    y_lo, ny = _bounds(world_xy[..., 1], margin)
    return Grid(rows=Axis(0, x_lo, nx, "up"), cols=Axis(1, y_lo, ny, "up"))


def check_grid_size(grid: Grid, n_maps: int, max_grid_px: int, what: str) -> None:
    """Refuse a map stack larger than `max_grid_px` pixels (a pose in the wrong unit makes km grids)."""
    total = grid.n_px * n_maps
    if total > max_grid_px:
        raise ValueError(f"{what}: {n_maps} map(s) of {grid.shape[0]} x {grid.shape[1]} px = {total:,} px exceed "
                         f"max_grid_px = {max_grid_px:,}; check the pose units (mm expected; T_BA in metres) or "
                         f"raise max_grid_px")

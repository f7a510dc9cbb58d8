"""One configuration's vessel maps end to end: scores -> samples -> world -> grid -> threshold -> stats."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from palpation.mapping.grid import DEFAULT_MAX_GRID_PX, check_grid_size, meat_grid, silicone_grid, sim_grid
from palpation.mapping.lift import MapStack, rasterise, to_world
from palpation.mapping.photo import photo_truth
from palpation.mapping.samples import Samples, align
from palpation.mapping.sources import MapSource
from palpation.mapping.stats import all_radii
from palpation.mapping.threshold import OperatingPoint, choose_threshold

TEST_DATASET = {"A-to-A": "sim", "A-to-B": "silicone", "A-to-C": "meat", "C-to-B": "silicone"}


@dataclass(frozen=True)
class MapSettings:
    tolerance_mm: float = 3.0
    min_precision: float = 0.9
    min_pixels: int = 20
    max_grid_px: int = DEFAULT_MAX_GRID_PX
    sim_max_maps: int | None = 10  # the paper's "10 test slides"; None = all
    sim_vessel_only: bool = True  # Sim maps only of slides with a positive central-frame label


@dataclass
class ConfigMaps:
    config: str
    dataset: str
    stack: MapStack
    op: OperatingPoint
    curve: dict
    stats: dict
    n_samples: int
    photo: dict | None = None  # Silicone: photo truth, its operating point and statistics
    meta: dict = field(default_factory=dict)


def select_sim_maps(samples: Samples, source: MapSource, settings: MapSettings) -> tuple[Samples, list]:
    """Slides to draw: those with a positive label (if vessel_only), the first sim_max_maps by name."""
    seqs = np.unique(samples.seq)
    if settings.sim_vessel_only:
        seqs = np.array([s for s in seqs if samples.labels[samples.seq == s].any()], np.int64)
    if settings.sim_max_maps is not None:
        seqs = seqs[: settings.sim_max_maps]
    if len(seqs) == 0:
        raise ValueError(f"Sim {source.meta.get('split', '')}: no slide with a positive central-frame label to map; "
                         f"set sim_vessel_only=false or check the scores")
    return samples.subset(np.isin(samples.seq, seqs)), list(seqs)


def build_stack(source: MapSource, samples: Samples, settings: MapSettings, what: str) -> MapStack:
    """Lift the samples with their frames' poses and draw them on the dataset's grid."""
    if len(samples) == 0:
        raise ValueError(f"{what}: empty prediction set; nothing to map")
    poses = np.stack([source.poses[s][f] for s, f in zip(samples.seq, samples.frame)])
    world = to_world(source.dataset, samples.pixels, poses)
    if source.dataset == "silicone":
        map_id, names = np.zeros(len(samples), np.int64), list(source.map_names)
        grid = silicone_grid()
    else:
        used = np.unique(samples.seq)  # one map per sequence that has samples, in sequence order
        map_id = np.searchsorted(used, samples.seq)
        names = [source.map_names[source.map_of_seq[s]] for s in used]
        _check_extent(world, settings.max_grid_px, what)
        grid = meat_grid(world) if source.dataset == "meat" else sim_grid(world)
    check_grid_size(grid, len(names), settings.max_grid_px, what)
    return rasterise(grid, world, samples.probs, samples.labels, map_id, len(names), names)


def _check_extent(world: np.ndarray, max_grid_px: int, what: str) -> None:
    """Refuse data bounds whose grid would not fit before allocating it (a pose in the wrong unit)."""
    span = np.nanmax(world.reshape(-1, 2), 0) - np.nanmin(world.reshape(-1, 2), 0) + 7
    if float(span[0]) * float(span[1]) > max_grid_px:
        raise ValueError(f"{what}: the lifted points span {span[0]:.0f} x {span[1]:.0f} mm, a grid over "
                         f"max_grid_px = {max_grid_px:,}; check the pose units (mm; T_BA in metres) or raise "
                         f"max_grid_px")


def evaluate(stack: MapStack, truth: np.ndarray, settings: MapSettings) -> tuple[OperatingPoint, dict, dict]:
    op, curve = choose_threshold(stack.score, stack.visited, truth, settings.tolerance_mm,
                                 settings.min_precision, settings.min_pixels)
    return op, curve, all_radii(stack.score, stack.visited, truth, op.threshold)


def config_maps(config: str, source: MapSource, probs: np.ndarray, labels: np.ndarray, sequence: np.ndarray,
                frame: np.ndarray, settings: MapSettings = MapSettings(), polygons=None) -> ConfigMaps:
    """Maps, operating point and statistics of one configuration from its pooled test scores and their
    (sequence, frame) ids (palpation.metrics.scores; the dense Sim slide: mapping.rescore)."""
    what = f"{config} ({source.dataset})"
    samples = align(probs, labels, sequence, frame, source.markers, source.labels, what)
    meta = {"n_sequences": len(source.ids), **source.meta}
    if source.dataset == "sim":
        samples, kept = select_sim_maps(samples, source, settings)
        meta["slides"] = [source.ids[s] for s in kept]
    stack = build_stack(source, samples, settings, what)
    op, curve, stats = evaluate(stack, stack.truth, settings)
    result = ConfigMaps(config, source.dataset, stack, op, curve, stats, len(samples), meta=meta)
    if source.dataset == "silicone":
        photo = photo_truth(stack.visited[0], polygons)[None]
        p_op, p_curve, p_stats = evaluate(stack, photo, settings)
        inter, union = (photo & stack.truth).sum(), (photo | stack.truth).sum()
        result.photo = {"truth": photo, "op": p_op, "curve": p_curve, "stats": p_stats,
                        "iou_video_photo": float(inter / union) if union else float("nan")}
    return result

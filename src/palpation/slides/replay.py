"""The twin replayed along measured slides (issue 12): scene, pose schedule, markers per measured frame.

* Scene: the sequence set's world mm are mapped onto the twin's world metres by a shift that puts the
  mean pose over the twin's centre (CENTRE_XY_M); the axes are kept (robot x, y = twin x, y, an
  assumption: the reconstructed Silicone poses carry no orientation). The vessels become the compliant
  phantom's inclusion segments (twin.contact, phantom_model = foundation); the rigid vessel is off.
* Schedule: the reference controller (SPEC §4.2: v = 100 e, |v| <= 100 mm/s, a waypoint is reached within
  1 mm) drives the tip, translation only, through: 1 mm above the first pose, the surface, the first
  pose at depth, then every measured pose in order. Frame k of the slide is the frame that reaches its
  waypoint, so the twin's markers are read where the real sensor was photographed.
* Metrics: per-frame marker motion MAE (px, over the markers found in the real frame): the markers about
  each trial's per-marker median, in real and sim alike, so a static offset (rest pose, camera, mount)
  does not dominate (docs/slides.md); the absolute MAE is kept beside it (frame_mae_abs). And the
  over-vessel / off-vessel ratio of that motion (SPEC §13.6's quantity: real 1.55 / 1.45 px), both over
  the real labels.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from palpation.loop.residual import MODES, decompose
from palpation.measured_sequences import SequenceSet
from palpation.twin.config import TwinConfig
from palpation.twin.markers import MarkerBinding, project_markers_np
from palpation.twin.mesh import SensorMesh
from palpation.twin.parameters import PARAMETERS
from palpation.twin.runner import EnvRequest, ScheduledBatch, tip_node_B
from palpation.twin.trajectory import (APPROACH_Z_M, BASE_ROTATION, CENTRE_XY_M, FRAME_DT_S, GAIN_PER_S, MAX_FRAMES,
                                       PHANTOM_TOP_M, REACH_TOL_M, SPEED_CAP_M_S, Trajectory, padded_schedule,
                                       pose_matrix)



@dataclass(frozen=True)
class SceneParameter:
    """A parameter of the real scene, not of the twin: the replay applies it; a Sim set never sees it."""
    name: str
    unit: str
    low: float
    high: float
    log: bool
    why: str


# The phantom's surface slope (depth change per mm of world x / y about the slides' mean pose): not recorded.
# With friction a slope drags the skin more as the press deepens: the slow drift of the whole marker field
# along the real slides (docs/slides.md, diagnosis). Without friction it moves nearly nothing.
SCENE_PARAMETERS = {p.name: p for p in (
    SceneParameter("tilt_x", "mm/mm", -0.03, 0.03, False, "phantom slope along world x; +-1.7 deg: levelled by eye"),
    SceneParameter("tilt_y", "mm/mm", -0.03, 0.03, False, "phantom slope along world y; +-1.7 deg: levelled by eye"),
)}
# parameters the replay applies outside the kernels: registry ones to the poses (mount dz) or to the projected
# markers (anchor: that fraction of the rest offset template - bound rest, as twin.config.MarkerConfig), and the
# scene's slope to the poses
SCHEDULE_KEYS = ("mount_dz_mm", "marker_anchor", *SCENE_PARAMETERS)
REACH_M = 0.030  # dome footprint radius (19 mm) + the widest inclusion spread (8 mm) + margin


@dataclass(frozen=True)
class Scene:
    origin_mm: np.ndarray  # world x, y mm that lands on the twin's CENTRE_XY_M
    segments_m: np.ndarray  # (S, 2, 2) vessel centreline segments, twin world metres

    def to_twin(self, xy_mm: np.ndarray) -> np.ndarray:
        return (np.asarray(xy_mm, np.float64) - self.origin_mm) * 1e-3 + CENTRE_XY_M

    def near(self, tips_m: np.ndarray, reach_m: float = REACH_M) -> "Scene":
        """Only the segments within `reach_m` of some tip position: the kernel loops over every segment."""
        if not len(self.segments_m):
            return self
        a, b = self.segments_m[:, 0][:, None], self.segments_m[:, 1][:, None]
        # a batch's envs share most positions (the same trial under several candidates): each once
        q = np.unique(np.asarray(tips_m, np.float64).reshape(-1, 2), axis=0)[None]
        ab = b - a
        u = np.clip(((q - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-18), 0.0, 1.0)
        dist = np.linalg.norm(q - (a + u[..., None] * ab), axis=-1).min(axis=1)
        return Scene(self.origin_mm, self.segments_m[dist < reach_m])


def make_scene(sset: SequenceSet) -> Scene:
    origin = sset.pose_mm[..., :2].reshape(-1, 2).mean(axis=0)
    scene = Scene(origin, np.zeros((0, 2, 2)))
    segs = [np.stack([scene.to_twin(c[:-1]), scene.to_twin(c[1:])], axis=1) for c in sset.centrelines()]
    return Scene(origin, np.concatenate(segs) if segs else np.zeros((0, 2, 2)))


def scene_config(cfg: TwinConfig, scene: Scene) -> TwinConfig:
    """The twin of the real scene: compliant phantom with the vessels as inclusions, no rigid vessel."""
    contact = dataclasses.replace(cfg.contact, phantom_contact=True, phantom_model="foundation", vessel=False)
    sc = dataclasses.replace(cfg.scene, inclusions=[list(map(float, s.ravel())) for s in scene.segments_m])
    return dataclasses.replace(cfg, contact=contact, scene=sc).validate()


def plan_replay(pose_mm: np.ndarray, scene: Scene, tip_B_m: np.ndarray, dz_mm: float = 0.0,
                frame_dt_s: float = FRAME_DT_S, lead_in_mm: float = 0.0,
                tilt: tuple[float, float] = (0.0, 0.0)) -> tuple[Trajectory, np.ndarray]:
    """The pose schedule through one trial's measured poses (F, 3) and the frame that reaches each.
    `lead_in_mm` > 0: press that far back along the first step and slide in at depth, so the first measured
    frame is already in steady sliding, as the real one is (the recordings are trimmed mid-sweep, SPEC §13.4).
    `tilt` (mm/mm along world x, y): the phantom's slope; the press deepens by tilt . (xy - scene origin)."""
    pose = np.asarray(pose_mm, np.float64)
    xy = scene.to_twin(pose[:, :2])
    slope = np.asarray(tilt, np.float64)

    def depth_z(xy_m: np.ndarray, depth_mm: np.ndarray) -> np.ndarray:  # twin xy (m) -> tip z (m)
        extra = ((np.atleast_2d(xy_m) - CENTRE_XY_M) * 1e3) @ slope if slope.any() else 0.0
        return PHANTOM_TOP_M - (depth_mm + dz_mm + extra) * 1e-3

    z = depth_z(xy, pose[:, 2])
    start = [*xy[0]]
    lead = []
    if lead_in_mm > 0:
        step = xy[1] - xy[0] if len(xy) > 1 else np.zeros(2)
        if not np.linalg.norm(step) > 0:
            raise ValueError("replay: lead_in_mm needs the first two measured poses apart (the slide's direction)")
        start = xy[0] - step / np.linalg.norm(step) * lead_in_mm * 1e-3
        lead = [[*start, float(depth_z(start, pose[:1, 2])[0])]]
    table = np.concatenate([[[*start, APPROACH_Z_M[0]], [*start, APPROACH_Z_M[1]]], *([lead] if lead else []),
                            np.column_stack([xy, z])])
    R = BASE_ROTATION.as_matrix()
    offset = R @ np.asarray(tip_B_m, np.float64)
    tip = table[0].copy()
    target, tips, reached_at = 0, [], []
    # the controller steps one frame at a time; sqrt(x.dot(x)) is np.linalg.norm's own formula, without its
    # per-call checks (this loop runs ~500 times a trial, for every trial of every candidate)
    while True:
        if len(tips) >= MAX_FRAMES * 4:
            raise ValueError(f"replay: waypoint {target} not reached within {len(tips)} frames; check pose_mm units (mm)")
        error = table[target] - tip
        if math.sqrt(error.dot(error)) < REACH_TOL_M:  # reached: this frame applies no motion (SPEC §4.2)
            reached_at.append(len(tips))
            tips.append(tip)
            if target == len(table) - 1:
                break
            target += 1
            continue
        v = GAIN_PER_S * error
        speed = math.sqrt(v.dot(v))
        if speed > SPEED_CAP_M_S:
            v *= SPEED_CAP_M_S / speed
        tip = tip + v * frame_dt_s
        tips.append(tip)
    poses = np.broadcast_to(pose_matrix(BASE_ROTATION, np.zeros(3)), (len(tips), 4, 4)).copy()
    poses[:, :3, 3] = np.array(tips) - offset
    traj = Trajectory(kind="slide", T_BA0=pose_matrix(BASE_ROTATION, table[0] - offset), T_BA=poses,
                      record_from=0, frame_dt_s=frame_dt_s)
    return traj, np.array(reached_at[2 + len(lead):])  # the measured frames (after approach and lead-in)


def split_params(params: dict) -> tuple[dict, dict]:
    """(kernel per-env values, schedule values) of one candidate; names are registry names."""
    env_names = {p.name: p.field for p in PARAMETERS.values() if p.per_env}
    unknown = sorted(set(params) - set(env_names) - set(SCHEDULE_KEYS))
    if unknown:
        raise ValueError(f"slide loop: unknown parameter(s) {unknown}; use per-env twin parameters "
                         f"{sorted(env_names)} or {list(SCHEDULE_KEYS)} (palpation.twin.parameters, "
                         "slides.replay.SCENE_PARAMETERS)")
    env = {env_names[k]: float(v) for k, v in params.items() if k in env_names}
    return env, {k: float(v) for k, v in params.items() if k in SCHEDULE_KEYS}


def replay(mesh: SensorMesh, cfg: TwinConfig, binding: MarkerBinding, sset: SequenceSet, scene: Scene,
           candidates: list[dict], device: str | None = None,
           lead_in_mm: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Every candidate on every trial of `sset`, one batch: markers (C, T, F, 127, 2) px and failed (C, T).
    `cfg` is the base twin; the scene (compliant phantom, the vessels near these slides) is added here;
    `lead_in_mm`: plan_replay's slide-in before the first measured pose."""
    return replay_many(mesh, cfg, binding, [(sset, candidates)], scene, device, lead_in_mm)[0]


def replay_many(mesh: SensorMesh, cfg: TwinConfig, binding: MarkerBinding,
                jobs: list[tuple[SequenceSet, list[dict]]], scene: Scene, device: str | None = None,
                lead_in_mm: float = 0.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """`replay` of several (sequence set, candidates) jobs in one twin batch (the slide loop's folds together):
    each job's (markers, failed) as its own replay gives them. An env's result does not depend on its batch: its
    phantom keeps every vessel near its own path (Scene.near over the whole batch only adds far ones), and the
    kernels never mix envs; on CUDA `kernel: auto` may pick the resident kernel for the larger batch (float order)."""
    if len({sset.n_frames for sset, _ in jobs}) != 1:
        raise ValueError("replay_many: the jobs' sequence sets need one frame count (the same measured frames)")
    tip_B = tip_node_B(mesh)
    reqs, trajs, samples, anchors = [], [], [], []
    plans = {}  # candidates that differ only inside the kernels share a trial's plan
    for j, (sset, candidates) in enumerate(jobs):
        for params in candidates:
            env, sched = split_params(params)
            geometry = (sched.get("mount_dz_mm", 0.0), (sched.get("tilt_x", 0.0), sched.get("tilt_y", 0.0)))
            for t in range(sset.n_trials):
                reqs.append(EnvRequest("slide", vessel=False, name=f"{sset.trials[t]['name']}", **env))
                key = (j, t, geometry)
                if key not in plans:
                    plans[key] = plan_replay(sset.pose_mm[t], scene, tip_B, geometry[0], cfg.frame_dt, lead_in_mm,
                                             geometry[1])
                traj, frames = plans[key]
                trajs.append(traj)
                samples.append(frames)
                anchors.append(sched.get("marker_anchor", 0.0))
    schedule, _ = padded_schedule(trajs)
    cfg = scene_config(cfg, scene.near(schedule[:, :, :2, 3]))
    reqs = [r.resolved(cfg) for r in reqs]
    samples = np.stack(samples)  # (envs, F)
    batch = ScheduledBatch(mesh, cfg, reqs, trajs, schedule, device or cfg.device)
    out = np.full((len(reqs), jobs[0][0].n_frames, len(binding.node_ix), 2), np.nan)
    wanted = set(samples.ravel().tolist())
    for f in batch.frames():
        if f in wanted:
            env_ix, frame_ix = np.nonzero(samples == f)
            nodes = batch.sim.positions_world()[env_ix]
            out[env_ix, frame_ix] = project_markers_np(binding, nodes, schedule[f, env_ix])
        if f >= samples.max():
            break
    out += np.array(anchors)[:, None, None, None] * (binding.template_px - binding.rest_px)
    failed = batch.sim.failed() | ~np.all(np.isfinite(out), axis=(1, 2, 3))
    parts, start = [], 0
    for sset, candidates in jobs:
        shape, end = (len(candidates), sset.n_trials), start + len(candidates) * sset.n_trials
        parts.append((out[start:end].reshape(*shape, *out.shape[1:]), failed[start:end].reshape(shape)))
        start = end
    return parts


def motion(markers: np.ndarray) -> np.ndarray:
    """Markers (..., T, F, 127, 2) about each trial's per-marker median over its frames: the motion a slide
    causes, without the static offset (rest pose, camera, mount) that a replay cannot fit from motion."""
    m = np.asarray(markers, np.float64)
    return m - np.median(m, axis=-3, keepdims=True)


def _found_mean(err: np.ndarray, sset: SequenceSet) -> np.ndarray:
    found = np.broadcast_to(sset.found, err.shape)
    return np.where(found, err, 0.0).sum(axis=(-1, -2)) / found.sum(axis=(-1, -2))


def frame_mae(sim: np.ndarray, sset: SequenceSet) -> np.ndarray:
    """(..., T) per-trial mean over frames and found markers of the motion error px, |motion(sim) -
    motion(real)|; sim (..., T, F, 127, 2). The slide loop's residual (docs/slides.md: why motion)."""
    return _found_mean(np.linalg.norm(motion(sim) - motion(sset.markers), axis=-1), sset)


def frame_mae_abs(sim: np.ndarray, sset: SequenceSet) -> np.ndarray:
    """(..., T) per-trial mean of the absolute marker error |sim - real| px (static offset included)."""
    return _found_mean(np.linalg.norm(np.asarray(sim, np.float64) - sset.markers, axis=-1), sset)


def vessel_ratio(markers: np.ndarray, labels: np.ndarray | None) -> float:
    """Mean marker motion about each trial's median position over vessel-labelled markers / off them."""
    if labels is None:
        raise ValueError("the over-vessel / off-vessel split needs per-frame labels in the sequence set "
                         "(key `labels`, docs/measured_format.md)")
    moved = np.linalg.norm(motion(markers), axis=-1)  # (T, F, 127)
    on, off = labels == 1, labels == 0
    if not on.any() or not off.any():
        return float("nan")
    return float(moved[on].mean() / moved[off].mean())


def slide_modes(sim: np.ndarray, sset: SequenceSet) -> dict:
    """The residual of every frame split into the photo loop's modes (loop.residual), averaged over the
    frames of `sset`, plus the MAE over the vessel-labelled markers and off them (the detector's split)."""
    rows = [decompose(sim[t, f], sset.markers[t, f]).row() for t in range(sset.n_trials) for f in range(sset.n_frames)]
    out = {f"share_{m}": float(np.mean([r[f"share_{m}"] for r in rows])) for m in MODES}
    for key in ("rotation_deg", "scale_pct", "stretch_pct"):
        out[key] = float(np.mean([r[key] for r in rows]))
    out["translation_px"] = np.mean([r["translation_px"] for r in rows], axis=0).tolist()
    if sset.labels is not None:
        err = np.linalg.norm(motion(sim) - motion(sset.markers), axis=-1)
        on, off = (sset.labels == 1) & sset.found, (sset.labels == 0) & sset.found
        out["mae_over_vessel_px"] = float(err[on].mean()) if on.any() else float("nan")
        out["mae_off_vessel_px"] = float(err[off].mean()) if off.any() else float("nan")
    return out

"""Canonical interactions and the per-frame pose controller (SPEC §4, errata §17), in metres.

The controller only ever reads the kinematic (undeformed) copy of the sensor, which moves rigidly
with the commanded pose. The deformed solid never feeds back, so the whole pose schedule can be
planned in numpy before any simulation, and every environment of a batch can replay its own.

Per frame, in the reference's order: orientation command from the frame-start rotation, then the
position command on the undeformed tip node with the reach test, then the incremental rigid map
x -> R_A (x - t0) + t0 + v dt about the pivot t0 = the first waypoint.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

M_PER_SIM = 0.2  # SPEC sim units: 1 sim = 200 mm
FRAME_DT_S = 124 * 1e-5  # 124 substeps of 1e-5 s
GAIN_PER_S = 100.0  # v = 100 e (k_i = k_d = 0)
SPEED_CAP_M_S = 0.5 * M_PER_SIM
RATE_CAP_DEG_S = 200.0
REACH_TOL_M = 0.005 * M_PER_SIM
REACH_TOL_DEG = 1.0
MAX_FRAMES = 2000  # guard against a waypoint table the controller can never reach

CENTRE_XY_M = np.array([0.195, 0.195]) * M_PER_SIM  # over the vessel apex
TWIST_X_XY_M = np.array([0.195, 0.1617]) * M_PER_SIM  # 6.7 mm in -y
PHANTOM_TOP_M = 0.075 * M_PER_SIM
SLIDE_START_M, SLIDE_END_M = 0.15 * M_PER_SIM, 0.10 * M_PER_SIM  # from the centre, 50 mm in all
SLIDE_RECORD_AFTER = 80  # slides record frames with index > 80
KINDS = ("press", "twist_z", "twist_x", "slide")
# SPEC §4.1 canonical geometry: depth below the phantom top (mm) and twist angle (deg). twist_z is
# the reference's 30 deg although its photo's name says 90 (quirk 5); press and slide have no angle.
CANONICAL_DEPTH_MM = {"press": 4.0, "twist_z": 4.0, "twist_x": 2.0, "slide": 3.0}
CANONICAL_ANGLE_DEG = {"twist_z": 30.0, "twist_x": 20.0}
MAX_DEPTH_MM = 10.0  # deeper would drive the fixed flange into the phantom (the dome is 5 mm tall)
APPROACH_Z_M = (0.080 * M_PER_SIM, PHANTOM_TOP_M)  # 1 mm above, then on the surface

# Dome faces down; the body yaw matches the real camera (SPEC §13.3).
BASE_ROTATION = Rotation.from_euler("y", 180, degrees=True) * Rotation.from_euler("z", -10.37, degrees=True)


@dataclass(frozen=True)
class Waypoint:
    """A target pose of the sensor tip: world position (metres) and body orientation."""

    position_m: np.ndarray
    rotation: Rotation


@dataclass
class Trajectory:
    """A planned pose schedule: `T_BA[f]` is the pose at the end of frame f (markers use it)."""

    kind: str
    T_BA0: np.ndarray  # (4, 4) start pose, before frame 0
    T_BA: np.ndarray  # (F, 4, 4) metres
    record_from: int  # first recorded frame index
    heading_deg: float = float("nan")  # slides only
    waypoints: list[Waypoint] = field(default_factory=list, repr=False)
    frame_dt_s: float = FRAME_DT_S

    @property
    def n_frames(self) -> int:
        return len(self.T_BA)

    @property
    def n_recorded(self) -> int:
        return self.n_frames - self.record_from


def geometry(kind: str, depth_mm: float | None = None, angle_deg: float | None = None) -> tuple[float, float]:
    """(depth mm, angle deg) of one interaction: None takes SPEC's canonical value; checked."""
    if kind not in KINDS:
        raise ValueError(f"unknown trajectory kind '{kind}'; expected one of {KINDS}")
    depth = CANONICAL_DEPTH_MM[kind] if depth_mm is None else float(depth_mm)
    if not 0.0 <= depth <= MAX_DEPTH_MM:
        raise ValueError(f"{kind}: depth_mm={depth_mm} must lie in [0, {MAX_DEPTH_MM}] mm below the "
                         "phantom top")
    if kind not in CANONICAL_ANGLE_DEG:
        if angle_deg is not None:
            raise ValueError(f"{kind}: has no twist angle, got angle_deg={angle_deg}; pass None")
        return depth, 0.0
    angle = CANONICAL_ANGLE_DEG[kind] if angle_deg is None else float(angle_deg)
    if not np.isfinite(angle) or abs(angle) > 180.0:
        raise ValueError(f"{kind}: angle_deg={angle_deg} must be a finite angle in [-180, 180] deg")
    return depth, angle


def waypoints(kind: str, heading_offset_deg: float = 0.0, depth_mm: float | None = None,
              angle_deg: float | None = None) -> list[Waypoint]:
    """The waypoint table of one interaction (SPEC §4.1), tip poses in metres.

    `depth_mm` is the final tip depth below the phantom top and `angle_deg` the twist; None = SPEC.
    twist_z turns by -angle about body z (the reference's R_z(-30 deg)), twist_x by +angle about x.
    """
    depth, angle = geometry(kind, depth_mm, angle_deg)
    z_deep = PHANTOM_TOP_M - depth * 1e-3
    r0 = BASE_ROTATION
    if kind in ("press", "twist_z", "twist_x"):
        xy = TWIST_X_XY_M if kind == "twist_x" else CENTRE_XY_M
        table = [Waypoint(np.array([*xy, z]), r0) for z in (*APPROACH_Z_M, z_deep)]
        if kind == "twist_z":
            table.append(Waypoint(table[-1].position_m, r0 * Rotation.from_euler("z", -angle, degrees=True)))
        elif kind == "twist_x":
            table.append(Waypoint(table[-1].position_m, r0 * Rotation.from_euler("x", angle, degrees=True)))
        return table
    theta = np.radians(-90.0 + heading_offset_deg)  # slide: starts already at depth
    direction = np.array([np.cos(theta), np.sin(theta)])
    start = CENTRE_XY_M + SLIDE_START_M * direction
    end = CENTRE_XY_M - SLIDE_END_M * direction
    return [Waypoint(np.array([*xy, z_deep]), r0) for xy in (start, end)]


def pose_matrix(rotation: Rotation, translation_m: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rotation.as_matrix()
    T[:3, 3] = translation_m
    return T


def plan_trajectory(kind: str, heading_offset_deg: float = 0.0, tip_B_m: np.ndarray | None = None,
                    frame_dt_s: float = FRAME_DT_S, depth_mm: float | None = None,
                    angle_deg: float | None = None) -> Trajectory:
    """Replay the reference controller kinematically and return the per-frame pose schedule.

    `tip_B_m` is the undeformed tip node in the body frame (the mesh's highest node, ~origin). The
    run stops on the frame that reaches the last waypoint; that frame still applies its command.
    `depth_mm` / `angle_deg` (None = SPEC's canonical values) come from a photo's file name.
    """
    return plan_trajectories([(kind, heading_offset_deg, depth_mm, angle_deg)], tip_B_m, frame_dt_s)[0]


def plan_trajectories(specs: list[tuple], tip_B_m: np.ndarray | None = None,
                      frame_dt_s: float = FRAME_DT_S) -> list[Trajectory]:
    """`plan_trajectory` for many (kind, heading_offset_deg, depth_mm, angle_deg) at once.

    The controllers run in lockstep on stacked rotations, one numpy/scipy call per step for all of
    them (a per-trajectory loop cost ~30 ms per slide in scipy call overhead). Each env's result is
    the same as planning it alone: every operation is row-wise.
    """
    tables = [waypoints(kind, heading, depth, angle) for kind, heading, depth, angle in specs]
    n = len(tables)
    tip_B = np.zeros(3) if tip_B_m is None else np.asarray(tip_B_m, dtype=np.float64)
    tips = np.tile(tip_B, (n, 1))  # scipy wants a writable array
    count = np.array([len(t) for t in tables])
    base = np.concatenate([[0], np.cumsum(count)[:-1]])  # first row of each env's table
    table_pos = np.array([w.position_m for t in tables for w in t])
    table_rot = Rotation.concatenate([w.rotation for t in tables for w in t])
    pivot = table_pos[base]
    rotation = table_rot[base]
    translation = pivot - _apply(rotation, tips)
    T_BA0 = _pose_matrices(rotation, translation)
    max_step_rad = np.radians(RATE_CAP_DEG_S) * frame_dt_s
    target = np.zeros(n, int)
    active = np.ones(n, bool)  # still planning (its last frame not yet reached)
    n_frames = np.zeros(n, int)
    poses = []
    while active.any():
        if len(poses) >= MAX_FRAMES:
            i = int(np.flatnonzero(active)[0])
            raise ValueError(f"{specs[i][0]}: waypoint {target[i]} not reached within {MAX_FRAMES} frames of "
                             f"{frame_dt_s:g} s; a frame time far above the reference {FRAME_DT_S:g} s makes the "
                             "controller overshoot: lower twin.integrator.dt x twin.integrator.substeps "
                             "(else check the waypoint table and controller limits)")
        row = base + target
        rotvec = (table_rot[row] * rotation.inv()).as_rotvec()
        angle = np.linalg.norm(rotvec, axis=1)
        scale = np.minimum(1.0, np.divide(max_step_rad, angle, out=np.zeros(n), where=angle > 0))
        step_vec = np.where((angle > 0)[:, None], rotvec * scale[:, None], 0.0)
        error = table_pos[row] - (_apply(rotation, tips) + translation)
        velocity = GAIN_PER_S * error
        speed = np.linalg.norm(velocity, axis=1)
        capped = speed > SPEED_CAP_M_S
        velocity[capped] *= (SPEED_CAP_M_S / speed[capped])[:, None]
        reached = (np.linalg.norm(error, axis=1) < REACH_TOL_M) & (np.degrees(angle) < REACH_TOL_DEG)
        advance = reached & (target < count - 1)  # intermediate waypoint: advance, no motion this frame
        target[advance] += 1
        step_vec[advance], velocity[advance] = 0.0, 0.0
        step = Rotation.from_rotvec(step_vec)
        rotation = step * rotation
        translation = _apply(step, translation - pivot) + pivot + velocity * frame_dt_s
        poses.append(_pose_matrices(rotation, translation))
        n_frames[active] += 1
        active &= ~(reached & ~advance)  # errata: the last waypoint's reaching frame still moves
    poses = np.stack(poses, axis=1) if poses else np.zeros((n, 0, 4, 4))
    out = []
    for i, ((kind, heading, _, _), table) in enumerate(zip(specs, tables)):
        out.append(Trajectory(kind=kind, T_BA0=T_BA0[i], T_BA=poses[i, : n_frames[i]].copy(),
                              record_from=SLIDE_RECORD_AFTER + 1 if kind == "slide" else 0,
                              heading_deg=-90.0 + heading if kind == "slide" else float("nan"),
                              waypoints=table, frame_dt_s=frame_dt_s))
    return out


def _apply(rotation: Rotation, vectors: np.ndarray) -> np.ndarray:
    """R v row by row; scipy's stacked apply rounds differently for 1 and n rows."""
    m = rotation.as_matrix()
    return (m[:, :, 0] * vectors[:, None, 0] + m[:, :, 1] * vectors[:, None, 1]
            + m[:, :, 2] * vectors[:, None, 2])


def _pose_matrices(rotation: Rotation, translation_m: np.ndarray) -> np.ndarray:
    T = np.zeros((len(translation_m), 4, 4))
    T[:, :3, :3] = rotation.as_matrix()
    T[:, :3, 3] = translation_m
    T[:, 3, 3] = 1.0
    return T


def tip_positions(traj: Trajectory, tip_B_m: np.ndarray | None = None) -> np.ndarray:
    """(F, 3) world positions of the undeformed tip at the end of each frame."""
    tip_B = np.zeros(3) if tip_B_m is None else np.asarray(tip_B_m, dtype=np.float64)
    return traj.T_BA[:, :3, :3] @ tip_B + traj.T_BA[:, :3, 3]


def rotation_from_start_deg(traj: Trajectory) -> np.ndarray:
    """(F,) angle (degrees) between each frame's orientation and the start orientation."""
    rel = Rotation.from_matrix(traj.T_BA[:, :3, :3]) * Rotation.from_matrix(traj.T_BA0[:3, :3]).inv()
    return np.degrees(rel.magnitude())


def padded_schedule(trajs: list[Trajectory]) -> tuple[np.ndarray, np.ndarray]:
    """Stack per-env schedules to the longest one: (F_max, n, 4, 4) poses and (n,) lengths.

    An env that has finished holds its last pose, so it rides along without moving.
    """
    lengths = np.array([t.n_frames for t in trajs])
    out = np.empty((lengths.max(), len(trajs), 4, 4))
    for i, t in enumerate(trajs):
        out[: t.n_frames, i] = t.T_BA
        out[t.n_frames:, i] = t.T_BA[-1]
    return out, lengths


def mount_offset(dz_m: float = 0.0, tilt_x_deg: float = 0.0, tilt_y_deg: float = 0.0) -> np.ndarray:
    """(4, 4) body-frame offset of the real sensor from the commanded one (twin.config.MountConfig).

    Tilts turn about the tip (the body origin); dz > 0 moves the sensor along +z_B, out of the dome,
    i.e. deeper into the phantom than commanded.
    """
    return pose_matrix(Rotation.from_euler("xy", [tilt_x_deg, tilt_y_deg], degrees=True),
                       np.array([0.0, 0.0, dz_m]))


def with_mount(traj: Trajectory, T_mount: np.ndarray) -> Trajectory:
    """The schedule the sensor really follows: every commanded pose composed with the mount offset.

    The controller only sees the commanded (kinematic) pose, so the offset is applied after planning.
    """
    return replace(traj, T_BA0=traj.T_BA0 @ T_mount, T_BA=traj.T_BA @ T_mount)

"""Typed configuration of the Warp twin (Hydra structured configs, SI units throughout).

Every length is in metres, every force in newtons, in the world frame A of SPEC §1.3 scaled to
physical size (a reference "sim" length is 5x the physical one, see `REF_LENGTH_SCALE`).

The reference (DiffTactile-based) simulator ran at 5x length with E, rho, k_n, c_n unscaled. That is
exactly the physical model with every lumped mass multiplied by 25 (`mass_scale=25`) and these
coefficient maps (docs/twin.md derives them; `from_reference_units` applies them):
    damping alpha: alpha_ref / 5      contact k_n, k_t: k_ref / 5      c_n, mu, beta: unchanged.
The defaults are those reference-equivalent values; `conf/twin/physical.yaml` is true dynamics.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hydra.core.config_store import ConfigStore

from palpation import paper
from palpation.config_ranges import Choice, Int, ListOf, Num, Text, ranged

RESIDENT_VARIANTS = ("tiles", "onesync", "packed", "atomic", "compact", "compact_atomic")  # twin/resident_sync.py
RESIDENT_COLORINGS = ("mesh_order", "largest_first")  # resident.color_tets
LAYERED_VARIANTS = ("packed", "atomic", "compact", "compact_atomic")  # resident variants with the layered kernel
KERNELS = ("streamed", "resident", "auto")  # twin.integrator.kernel
REF_LENGTH_SCALE = paper.LENGTH_SCALE  # reference sim length / physical length (SPEC §1.2)


def from_reference_units(*, k_n: float | None = None, c_n: float | None = None,
                         k_t: float | None = None, alpha: float | None = None) -> dict[str, float]:
    """Map reference (x5 length) coefficients to the physical model with mass_scale=25."""
    s = REF_LENGTH_SCALE
    out = {"k_n": k_n / s if k_n is not None else None, "c_n": c_n,
           "k_t": k_t / s if k_t is not None else None, "alpha": alpha / s if alpha is not None else None}
    return {k: v for k, v in out.items() if v is not None}


@dataclass
class MeshConfig:
    resolution: str = ranged("coarse", Text())  # name of the cached mesh: results/twin/mesh_{resolution}.npz
    length_factor: float = ranged(0.7, Num(gt=0))  # gmsh Mesh.CharacteristicLengthFactor (reference 0.3)


@dataclass
class MaterialConfig:
    E: float = ranged(paper.E, Num(gt=0))  # Pa (SPEC §2.3, calibrated)
    nu: float = ranged(paper.NU, Num(gt=0, lt=0.5))
    rho: float = ranged(paper.RHO, Num(gt=0))  # kg/m^3
    # "standard": mu, lambda from E, nu as the reference does (small-strain modulus then ~0.75 E
    # at nu=0.497, docs/twin.md); "smith": Smith et al. 2018 re-parametrisation, small-strain E exact.
    lame: str = ranged("standard", Choice("standard", "smith"))
    # layered skin (residual loop): tets within shell_thickness of the outer skin get the modulus
    # E * shell_ratio. 0 m = one homogeneous material (the reference; the paper notes the real sensor
    # has two, SPEC gives no values). Any thickness > 0 selects the layered elastic kernel.
    shell_thickness: float = ranged(0.0, Num(ge=0))  # m
    shell_ratio: float = ranged(1.0, Num(gt=0))  # E_shell / E_core; per env as "shell_ratio"


@dataclass
class DampingConfig:
    # N s/m per tet edge pair (reference 0.1 at x5 scale)
    alpha: float = ranged(paper.ALPHA_REF / REF_LENGTH_SCALE, Num(ge=0))
    beta: float = ranged(paper.BETA, Num(ge=0, lt=1))  # fraction removed from the elastic force (SPEC §2.3)
    per_env: bool = False  # alpha per env ("alpha" env parameter; selects the layered elastic kernel)


@dataclass
class IntegratorConfig:
    dt: float = ranged(1e-5, Num(gt=0))  # s, substep
    substeps: int = ranged(124, Int(ge=1))  # per frame; frame = dt * substeps = 1.24 ms
    mass_scale: float = ranged(25.0, Num(gt=0))  # 25 = reference-equivalent; 1 = physical (needs dt <= stable_dt)
    zero_velocity_each_frame: bool = True  # reference quirk 10
    # how tets' nodal forces are summed: "scatter" (float atomics), "gather" (each node sums its own
    # slots: no atomics, deterministic on GPUs; SDF contact only), "auto" (gather on CUDA, scatter on
    # the CPU, where both give the same bits). docs/twin.md compares them.
    force_sum: str = ranged("auto", Choice("auto", "scatter", "gather"))
    # "streamed": one launch per pass per substep, state in global memory (the reference path, and
    # the CPU path); "resident": one launch per frame, each env's x, v, f in one block's shared
    # memory (twin/resident.py, issue 17; SDF contact; the layered elastic kernel in LAYERED_VARIANTS);
    # "auto": resident on CUDA where the config and the block's shared memory allow it; on the CPU resident with one
    # lane in mesh order (SDF contact), the same bits as "streamed"; else streamed (resident.runs_resident)
    kernel: str = ranged("streamed", Choice(*KERNELS))
    # "auto" runs the streamed kernels for batches of fewer envs: a resident env is one block on one SM whatever the
    # batch, so few envs leave most SMs idle. The crossover depends on the scene (H100, docs/twin.md): 40 envs for a
    # press off the phantom, above 60 for the slide loop's replays in contact (no gain at 50-60); 100 keeps every
    # measured case on its faster side (a Sim set's 500: resident, 3.3x; the loops' calls of 5-60: streamed)
    auto_min_envs: int = ranged(100, Int(ge=1))
    # threads per env block of the resident kernel (<= 512: 106 registers a thread; compact <= 384, two blocks an SM).
    # 320 with compact: the fastest point of the H200 variant run, 12.63 s for 500 reference envs (docs/twin.md)
    block_dim: int = ranged(320, Int(ge=1, le=512))
    # the resident kernel's variant (twin/resident_sync.py): "tiles" (a barrier per tile write, the
    # first version), "onesync" / "packed" (one barrier per colour chunk; packed, prefetched mesh
    # constants: the same bits as "tiles"), "atomic" (shared atomics, full chunks; GPU sums unordered),
    # "compact" ("packed" with a force tile over the force nodes only: 111 KB, two blocks of <= 384 an SM),
    # "compact_atomic" (both)
    resident_variant: str = ranged("compact", Choice(*RESIDENT_VARIANTS))
    # or "largest_first": 41 colour chunks at reference, not 44
    resident_coloring: str = ranged("mesh_order", Choice(*RESIDENT_COLORINGS))


@dataclass
class ContactConfig:
    k_n: float = ranged(paper.K_N_REF / REF_LENGTH_SCALE, Num(ge=0))  # N/m, sensor-vessel normal stiffness
    # N s/m^2, multiplies the closing speed AND the depth (reference form)
    c_n: float = ranged(paper.C_N_REF, Num(ge=0))
    k_t: float = ranged(0.0, Num(ge=0))  # N s/m, tangential (viscous) stiffness
    mu: float = ranged(0.0, Num(ge=0))  # Coulomb friction coefficient
    vessel: bool = True  # default for the per-env vessel switch
    phantom_contact: bool = False  # sensor-phantom half-space contact (off in the reference)
    k_s: float = ranged(2.0e4, Num(ge=0))  # N/m per node, phantom surface stiffness (only if phantom_contact)
    c_s: float = ranged(0.0, Num(ge=0))  # N s/m^2, phantom surface damping (same form as c_n)
    slip_eps: float = ranged(1e-6, Num(gt=0))  # m/s, no tangential force below this slip speed (reference 5e-6 sim)
    # "sdf": node vs analytic vessel SDF; "centroid": reference triangle rule
    rule: str = ranged("sdf", Choice("sdf", "centroid"))
    # compliant phantom (issue 12; twin.contact): "node" = k_s per surface node (above); "foundation" =
    # a Winkler foundation k_f (pressure per penetration) stiffened over the scene's vessel inclusions.
    # Acts only with phantom_contact; the values are modelling choices bounded in twin.parameters.
    phantom_model: str = ranged("node", Choice("node", "foundation"))
    k_f: float = ranged(1.0e7, Num(gt=0))  # N/m^3: E ~ 200 kPa silicone over a ~20 mm column
    incl_ratio: float = ranged(5.0, Num(gt=0))  # E_vessel / E_phantom
    incl_depth: float = ranged(0.003, Num(ge=0))  # m, vessel axis below the phantom top (SPEC §3.1's 3 mm)
    incl_diameter: float = ranged(0.0046, Num(gt=0))  # m, the median of the phantom photo's vessel widths


@dataclass
class SceneConfig:
    phantom_top_z: float = ranged(0.015, Num())  # m, world z of the phantom surface (SPEC §3.2: 0.075 sim)
    vessel_radius: float = ranged(0.002, Num(gt=0))
    vessel_length: float = ranged(0.040, Num(gt=0))
    vessel_depth: float = ranged(0.003, Num(ge=0))  # axis below the phantom top
    vessel_center_x: float = ranged(0.039, Num())  # m, centre of the axis (SPEC §3.1: 0.195 sim)
    vessel_center_y: float = ranged(0.039, Num())
    # m, effective column height of the Winkler foundation (contact.phantom_model): a half-space loaded over
    # a contact of radius a is stressed to a depth ~a (~10 mm here), not through the whole phantom
    phantom_thickness: float = ranged(0.008, Num(gt=0))
    # vessel centreline segments of the compliant phantom, [x0, y0, x1, y1] world metres each (issue 12)
    inclusions: list[list[float]] = ranged(rule=ListOf(ListOf(Num(), 4, 4), 0), factory=list)


@dataclass
class CameraConfig:
    """Image-space error of the real camera against the nominal fisheye (SPEC §5.1), residual loop.

    The true projection is S(nominal projection) with S a similarity about the principal point:
    u -> c + f_scale R(rotation) (u - c) + (dx, dy). Because the equidistant projection is linear in
    f and c, this is exactly a camera with focal length f*f_scale, principal point c + (dx, dy) and
    the image rotated about it. The markers stay bound to the rest template (the real rest photo
    fixes where they are), so the error changes displacements, not the rest image.
    """

    f_scale: float = ranged(1.0, Num(gt=0))
    rotation_deg: float = ranged(0.0, Num(ge=-180, le=180))
    dx_px: float = ranged(0.0, Num())
    dy_px: float = ranged(0.0, Num())

    @property
    def is_identity(self) -> bool:
        return (self.f_scale, self.rotation_deg, self.dx_px, self.dy_px) == (1.0, 0.0, 0.0, 0.0)


@dataclass
class MountConfig:
    """Rigid offset of the real sensor from the commanded pose (body frame, about the tip)."""

    dz: float = ranged(0.0, Num())  # m along the sensor axis; > 0 = deeper into the phantom than commanded
    tilt_x_deg: float = ranged(0.0, Num(ge=-90, le=90))
    tilt_y_deg: float = ranged(0.0, Num(ge=-90, le=90))

    @property
    def is_identity(self) -> bool:
        return (self.dz, self.tilt_x_deg, self.tilt_y_deg) == (0.0, 0.0, 0.0)


@dataclass
class MarkerConfig:
    """Simulated markers (SPEC §5.2: an inverse-distance mean of 5 projected dome nodes, residual loop).

    The inverse-distance mean does not reproduce the template it was bound to: at rest the bound
    markers sit 6.5 px (coarse mesh) or 2.8 px (reference mesh) from the template on average.
    `anchor` adds that fraction of the rest offset (template - bound rest) to every marker; 1 puts
    the rest markers exactly where the real rest photo has them. 0 = the reference.
    """

    anchor: float = ranged(0.0, Num())


@dataclass
class HealthConfig:
    max_abs_position: float = ranged(2.0, Num(gt=0))  # m (reference: |x| > 10 sim)
    check_every: int = ranged(1, Int(ge=1))  # frames between health checks (reference: 20 in calibration)


@dataclass
class TwinConfig:
    mesh: MeshConfig = field(default_factory=MeshConfig)
    material: MaterialConfig = field(default_factory=MaterialConfig)
    damping: DampingConfig = field(default_factory=DampingConfig)
    integrator: IntegratorConfig = field(default_factory=IntegratorConfig)
    contact: ContactConfig = field(default_factory=ContactConfig)
    scene: SceneConfig = field(default_factory=SceneConfig)
    health: HealthConfig = field(default_factory=HealthConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    mount: MountConfig = field(default_factory=MountConfig)
    markers: MarkerConfig = field(default_factory=MarkerConfig)
    device: str = ranged("cpu", Text())

    @property
    def layered(self) -> bool:
        """Whether the layered elastic kernel (per-tet shell, per-env alpha) runs."""
        return self.material.shell_thickness > 0 or self.damping.per_env

    @property
    def frame_dt(self) -> float:
        return self.integrator.dt * self.integrator.substeps

    def validate(self) -> "TwinConfig":
        if self.integrator.substeps < 1 or self.integrator.dt <= 0:
            raise ValueError(f"twin.integrator: need dt > 0 and substeps >= 1, got {self.integrator}")
        if not 0.0 < self.material.nu < 0.5:
            raise ValueError(f"twin.material.nu={self.material.nu}: must lie in (0, 0.5)")
        if self.material.lame not in ("standard", "smith"):
            raise ValueError(f"twin.material.lame={self.material.lame!r}: use 'standard' or 'smith'")
        if self.contact.phantom_model not in ("node", "foundation"):
            raise ValueError(f"twin.contact.phantom_model={self.contact.phantom_model!r}: use 'node' or 'foundation'")
        if self.contact.phantom_model == "foundation" and self.contact.rule == "centroid":
            raise ValueError("twin.contact.phantom_model='foundation' needs contact.rule='sdf'")
        if any(len(seg) != 4 for seg in self.scene.inclusions):
            raise ValueError("twin.scene.inclusions: each segment is [x0, y0, x1, y1] in world metres")
        if self.scene.phantom_thickness <= 0:
            raise ValueError(f"twin.scene.phantom_thickness={self.scene.phantom_thickness}: must be > 0 m")
        if self.contact.rule not in ("sdf", "centroid"):
            raise ValueError(f"twin.contact.rule={self.contact.rule!r}: use 'sdf' or 'centroid'")
        if self.health.check_every < 1:
            raise ValueError(f"twin.health.check_every={self.health.check_every}: must be >= 1")
        if self.integrator.force_sum not in ("auto", "scatter", "gather"):
            raise ValueError(f"twin.integrator.force_sum={self.integrator.force_sum!r}: use 'auto', "
                             "'scatter' or 'gather'")
        if self.integrator.force_sum == "gather" and self.contact.rule == "centroid":
            raise ValueError("twin.integrator.force_sum='gather' needs contact.rule='sdf' (the centroid "
                             "rule reads the scattered forces); use 'scatter' or 'auto'")
        if self.integrator.kernel not in KERNELS:
            raise ValueError(f"twin.integrator.kernel={self.integrator.kernel!r}: use one of {KERNELS}")
        if self.integrator.auto_min_envs < 1:
            raise ValueError(f"twin.integrator.auto_min_envs={self.integrator.auto_min_envs}: must be >= 1")
        if self.integrator.kernel == "resident" and self.contact.rule != "sdf":
            raise ValueError("twin.integrator.kernel='resident' needs contact.rule='sdf'; use 'streamed' or 'auto'")
        if (self.integrator.kernel == "resident" and self.layered
                and self.integrator.resident_variant not in LAYERED_VARIANTS):
            raise ValueError(f"twin.integrator.kernel='resident' with the layered elastic kernel needs "
                             f"resident_variant in {LAYERED_VARIANTS}, got {self.integrator.resident_variant!r}")
        if not 1 <= self.integrator.block_dim <= 512:  # 106 registers a thread on sm_90: 512 fit an SM
            raise ValueError(f"twin.integrator.block_dim={self.integrator.block_dim}: use 1..512 threads")
        if self.integrator.resident_variant not in RESIDENT_VARIANTS:
            raise ValueError(f"twin.integrator.resident_variant={self.integrator.resident_variant!r}: "
                             f"use one of {RESIDENT_VARIANTS}")
        if self.integrator.resident_coloring not in RESIDENT_COLORINGS:
            raise ValueError(f"twin.integrator.resident_coloring={self.integrator.resident_coloring!r}: "
                             f"use one of {RESIDENT_COLORINGS}")
        if self.material.shell_thickness < 0 or self.material.shell_ratio <= 0:
            raise ValueError(f"twin.material: need shell_thickness >= 0 and shell_ratio > 0, got "
                             f"{self.material.shell_thickness}, {self.material.shell_ratio}")
        if self.camera.f_scale <= 0:
            raise ValueError(f"twin.camera.f_scale={self.camera.f_scale}: must be > 0")
        if self.integrator.mass_scale <= 0:
            raise ValueError(f"twin.integrator.mass_scale={self.integrator.mass_scale}: must be > 0")
        return self


def register_configs() -> None:
    """Store the schemas so conf/twin/*.yaml can start with `defaults: [base_twin]`."""
    cs = ConfigStore.instance()
    cs.store(group="twin", name="base_twin", node=TwinConfig)
    cs.store(group="twin/mesh", name="base_mesh", node=MeshConfig)


register_configs()

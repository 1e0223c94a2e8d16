r"""A procedural, deterministic demo scene: analytic primitives, materials and rigid motions.

No downloaded assets: every shape is an analytic primitive (sphere, box, capped cylinder, plane)
so that the renderer can shade with exact normals and tests can compute exact depth and motion.

Coordinates and units
---------------------
* World: metres, right-handed, **z up**; the ground is the plane z = 0.
* Camera space (OpenCV, as in ``shared/CONVENTIONS.md``): X right, Y down, Z forward along the
  optical axis; planar depth is Z. A camera pose is the 4×4 camera-to-world matrix
  :math:`T_c = [R_c \mid C]` whose rotation columns are the camera's right, down and forward axes
  in world coordinates and C its centre, so :math:`P_w = R_c X_c + C`.
* An object pose is the 4×4 local-to-world matrix :math:`T_o(i) = [R_o(i) \mid t_o(i)]` of frame
  index i; :math:`P_w = R_o p + t_o`.

Rigid motion as a function of the frame index (so tests can compute motion analytically):

.. math::

    t(i) = t_0 + i\,\mathbf{v}, \qquad R(i) = \mathrm{Rot}(\mathbf{a}, \theta_0 + i\,\omega)\,R_0

with v in m/frame and ω in rad/frame about the unit axis **a** (Rodrigues' formula).

Radiometry (linear scene-referred RGB, arbitrary units where a white Lambertian surface facing the
sun reads ≈ 1): emitters carry radiance 100–1000, i.e. ≥ 100× diffuse white, for bokeh.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..errors import InputError

# ---------------------------------------------------------------------------------------------
# Rigid transforms
# ---------------------------------------------------------------------------------------------


def rotation(axis: Sequence[float], angle_rad: float) -> np.ndarray:
    r"""3×3 rotation by ``angle_rad`` about ``axis`` (Rodrigues):
    :math:`R = I + \sin\theta\,K + (1-\cos\theta)\,K^2`, K the cross-product matrix of the unit axis."""
    a = np.asarray(axis, dtype=np.float64)
    n = np.linalg.norm(a)
    if not n > 0:
        raise InputError(f"rotation axis {tuple(axis)} has zero length; give a non-zero direction")
    x, y, z = a / n
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + math.sin(angle_rad) * k + (1.0 - math.cos(angle_rad)) * (k @ k)


def rigid(r: np.ndarray, t: Sequence[float]) -> np.ndarray:
    """4×4 homogeneous matrix ``[R | t]``."""
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = t
    return m


def look_rotation(forward: Sequence[float], up: Sequence[float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera rotation (columns right, down, forward in world coordinates) looking along ``forward``
    with the image's up direction as close to ``up`` as possible."""
    f = np.asarray(forward, dtype=np.float64)
    f = f / np.linalg.norm(f)
    right = np.cross(f, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(right) < 1e-9:
        raise InputError(f"camera forward {tuple(forward)} is parallel to up {tuple(up)}; tilt it")
    right /= np.linalg.norm(right)
    down = np.cross(f, right)
    return np.column_stack([right, down, f])


@dataclass(frozen=True)
class RigidMotion:
    r"""A pose that moves linearly in frame index i: :math:`t(i) = t_0 + i v`,
    :math:`R(i) = \mathrm{Rot}(a, \theta_0 + i\omega) R_0` (metres, radians, per frame)."""

    position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity_m_per_frame: tuple[float, float, float] = (0.0, 0.0, 0.0)
    base_rotation: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    """R_0, row-major 3×3."""
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    angle_rad: float = 0.0
    angular_velocity_rad_per_frame: float = 0.0

    def matrix(self, frame: float) -> np.ndarray:
        """4×4 local-to-world matrix at frame index ``frame``."""
        r = rotation(self.axis, self.angle_rad + frame * self.angular_velocity_rad_per_frame)
        r = r @ np.asarray(self.base_rotation, dtype=np.float64)
        t = np.asarray(self.position_m, dtype=np.float64) + frame * np.asarray(self.velocity_m_per_frame, dtype=np.float64)
        return rigid(r, t)

    @property
    def is_static(self) -> bool:
        return not any(self.velocity_m_per_frame) and self.angular_velocity_rad_per_frame == 0.0

    @staticmethod
    def camera(position_m: Sequence[float], forward: Sequence[float], **motion) -> "RigidMotion":
        """A camera pose at ``position_m`` looking along ``forward`` (z-up world), optionally moving."""
        r = look_rotation(forward)
        return RigidMotion(position_m=tuple(map(float, position_m)),
                           base_rotation=tuple(tuple(map(float, row)) for row in r), **motion)


# ---------------------------------------------------------------------------------------------
# Primitives: a mesh for the rasterizer, analytic normals and ray intervals for shading
# ---------------------------------------------------------------------------------------------


def _slab(o: np.ndarray, d: np.ndarray, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Ray-parameter interval where lo <= o + t d <= hi (one axis); (-inf, inf) or empty when d = 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - o) / d
        t2 = (hi - o) / d
    inside = (o >= lo) & (o <= hi)
    t_in = np.where(d == 0, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
    t_out = np.where(d == 0, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
    return t_in, t_out


def _quadric_interval(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Interval of t with a t² + b t + c <= 0 (a >= 0); empty (inf, -inf) when there is none."""
    disc = b * b - 4.0 * a * c
    ok = (disc >= 0) & (a > 0)
    sq = np.sqrt(np.where(ok, disc, 0.0))
    a2 = np.where(ok, 2.0 * a, 1.0)
    t_in = np.where(ok, (-b - sq) / a2, np.inf)
    t_out = np.where(ok, (-b + sq) / a2, -np.inf)
    # a ray parallel to a cylinder's axis: inside for all t when c <= 0
    par = a <= 0
    t_in = np.where(par, np.where(c <= 0, -np.inf, np.inf), t_in)
    t_out = np.where(par, np.where(c <= 0, np.inf, -np.inf), t_out)
    return t_in, t_out


@dataclass(frozen=True)
class Sphere:
    """Sphere of ``radius_m`` centred at the local origin."""

    radius_m: float
    resolution: int = 96
    """Segments around the equator (latitude bands = half of it); 96 keeps the chord sagitta
    r(1 − cos(π/48)) ≈ 5e-4 r."""

    def mesh(self):
        import pyvista as pv
        return pv.Sphere(radius=self.radius_m, theta_resolution=self.resolution,
                         phi_resolution=max(self.resolution // 2, 8))

    def normal(self, p: np.ndarray) -> np.ndarray:
        """Unit outward normal n = p/|p| at local points p (N×3)."""
        return p / np.maximum(np.linalg.norm(p, axis=-1, keepdims=True), 1e-12)

    def interval(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ray-parameter interval inside the sphere for local rays o + t d (N×3 each)."""
        return _quadric_interval((d * d).sum(-1), 2.0 * (o * d).sum(-1), (o * o).sum(-1) - self.radius_m ** 2)

    @property
    def bounding_radius_m(self) -> float:
        return self.radius_m


@dataclass(frozen=True)
class Box:
    """Axis-aligned (in local space) box with half extents ``half_m`` (x, y, z)."""

    half_m: tuple[float, float, float]

    def mesh(self):
        import pyvista as pv
        hx, hy, hz = self.half_m
        return pv.Box(bounds=(-hx, hx, -hy, hy, -hz, hz)).triangulate()

    def normal(self, p: np.ndarray) -> np.ndarray:
        """Normal of the face the point is closest to: axis k = argmax |p_k|/h_k, n = sign(p_k) e_k."""
        q = np.abs(p) / np.asarray(self.half_m)
        k = np.argmax(q, axis=-1)
        n = np.zeros_like(p)
        np.put_along_axis(n, k[..., None], np.take_along_axis(np.sign(p), k[..., None], -1), -1)
        return n

    def interval(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t_in = np.full(o.shape[:-1], -np.inf)
        t_out = np.full(o.shape[:-1], np.inf)
        for k, h in enumerate(self.half_m):
            a, b = _slab(o[..., k], d[..., k], -h, h)
            t_in, t_out = np.maximum(t_in, a), np.minimum(t_out, b)
        return t_in, t_out

    @property
    def bounding_radius_m(self) -> float:
        return float(np.linalg.norm(self.half_m))


@dataclass(frozen=True)
class Cylinder:
    """Capped cylinder along local z: radius ``radius_m``, from z = −``half_height_m`` to +."""

    radius_m: float
    half_height_m: float
    resolution: int = 96

    def mesh(self):
        import pyvista as pv
        return pv.Cylinder(center=(0, 0, 0), direction=(0, 0, 1), radius=self.radius_m,
                           height=2 * self.half_height_m, resolution=self.resolution, capping=True).triangulate()

    def normal(self, p: np.ndarray) -> np.ndarray:
        """Cap normal ±e_z where |z|/h > ρ/r (closer to a cap), else the radial direction."""
        rho = np.hypot(p[..., 0], p[..., 1])
        cap = np.abs(p[..., 2]) / self.half_height_m > rho / self.radius_m
        radial = np.stack([p[..., 0], p[..., 1], np.zeros_like(rho)], -1) / np.maximum(rho, 1e-12)[..., None]
        capn = np.zeros_like(p)
        capn[..., 2] = np.sign(p[..., 2])
        return np.where(cap[..., None], capn, radial)

    def interval(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a = d[..., 0] ** 2 + d[..., 1] ** 2
        b = 2.0 * (o[..., 0] * d[..., 0] + o[..., 1] * d[..., 1])
        c = o[..., 0] ** 2 + o[..., 1] ** 2 - self.radius_m ** 2
        t_in, t_out = _quadric_interval(a, b, c)
        z_in, z_out = _slab(o[..., 2], d[..., 2], -self.half_height_m, self.half_height_m)
        return np.maximum(t_in, z_in), np.minimum(t_out, z_out)

    @property
    def bounding_radius_m(self) -> float:
        return math.hypot(self.radius_m, self.half_height_m)


@dataclass(frozen=True)
class Plane:
    """Square of side 2·``half_size_m`` in the local z = 0 plane, normal +z (one quad)."""

    half_size_m: float

    def mesh(self):
        import pyvista as pv
        s = 2 * self.half_size_m
        return pv.Plane(center=(0, 0, 0), direction=(0, 0, 1), i_size=s, j_size=s,
                        i_resolution=1, j_resolution=1).triangulate()

    def normal(self, p: np.ndarray) -> np.ndarray:
        n = np.zeros_like(p)
        n[..., 2] = 1.0
        return n

    def interval(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # infinitely thin: never casts a shadow in this renderer
        e = np.full(o.shape[:-1], np.inf)
        return e, -e

    @property
    def bounding_radius_m(self) -> float:
        return self.half_size_m * math.sqrt(2.0)


Shape = Sphere | Box | Cylinder | Plane


# ---------------------------------------------------------------------------------------------
# Materials and objects
# ---------------------------------------------------------------------------------------------

TEXTURES = ("flat", "checker", "ground", "board")


@dataclass(frozen=True)
class Material:
    """Lambertian albedo (linear RGB in [0, 1]) with an optional procedural texture, or an emitter.

    ``texture``: ``flat``; ``checker`` — a solid 3-D checker of cell ``texture_scale_m`` between
    ``albedo`` and ``albedo2``; ``ground`` — 1 m checker + 0.1 m checker + value noise (for the
    ground, so defocus shows at every depth). ``emission`` is linear RGB radiance (0 = none).
    """

    albedo: tuple[float, float, float] = (0.8, 0.8, 0.8)
    albedo2: tuple[float, float, float] = (0.2, 0.2, 0.2)
    texture: str = "flat"
    texture_scale_m: float = 0.25
    emission: tuple[float, float, float] = (0.0, 0.0, 0.0)
    board_squares: tuple[int, int] = (10, 7)
    """``board`` texture (a calibration target, distortion tests): squares (x, y) of side
    ``texture_scale_m`` centred on the local origin in the xy plane, ``albedo2`` in the corner
    squares, ``albedo`` between them and as the margin around the board."""
    board_blur: float = 0.0
    """``board`` texture only (the distortion calibration check): 0 box-filters the squares over
    the pixel footprint (default); > 0 filters them with a Gaussian of σ = ``board_blur`` ×
    footprint instead (≈ px; an optical low-pass), which is band-limited enough for sub-pixel
    edge fits and bicubic resampling not to depend on where a corner falls within its pixel."""

    def __post_init__(self) -> None:
        if self.texture not in TEXTURES:
            raise InputError(f"Material.texture={self.texture!r} must be one of {', '.join(TEXTURES)}")
        for name in ("albedo", "albedo2"):
            v = getattr(self, name)
            if not all(0.0 <= c <= 1.0 for c in v):
                raise InputError(f"Material.{name}={v!r} must be linear RGB in [0, 1] (reflectance)")
        if not all(math.isfinite(c) and c >= 0 for c in self.emission):
            raise InputError(f"Material.emission={self.emission!r} must be finite radiance >= 0")
        if not self.texture_scale_m > 0:
            raise InputError(f"Material.texture_scale_m={self.texture_scale_m!r} must be > 0 metres")
        # board_blur (distortion calibration check)
        if not (math.isfinite(self.board_blur) and self.board_blur >= 0):
            raise InputError(f"Material.board_blur={self.board_blur!r} must be a finite σ >= 0 in pixel "
                             "footprints (0 = box filter, e.g. 0.6 for a Gaussian low-pass)")

    @property
    def is_emitter(self) -> bool:
        return any(c > 0 for c in self.emission)


@dataclass(frozen=True)
class SceneObject:
    """A shape with a material and a (possibly moving) pose; ``casts_shadow`` for the sun."""

    name: str
    shape: Shape
    material: Material
    motion: RigidMotion = field(default_factory=RigidMotion)
    casts_shadow: bool = True


@dataclass(frozen=True)
class DemoScene:
    r"""Objects, lights and camera path of a procedural scene (metres, z up, frames indexed by int).

    Lighting (linear, deterministic): a directional sun of irradiance ``sun_irradiance`` from
    ``sun_direction`` (towards the sun) with shadows from the analytic shapes, a sky ambient term
    and the emitters as small unshadowed sphere lights. Outgoing radiance of a Lambertian point
    with albedo ρ and unit normal n:

    .. math::

        L = \rho\Big(E_s\,V\max(0, n\cdot s) + E_a\,\tfrac{1 + n_z}{2}
            + \sum_k L_k\,\pi r_k^2\,\frac{\max(0, n\cdot\omega_k)}{d_k^2}\Big)

    (π folded into the irradiances, so white albedo 0.8 facing the sun reads 0.8·(1 + E_a)).
    The sky has radiance ``sky_zenith`` blending to ``sky_horizon`` towards the horizon.
    """

    objects: tuple[SceneObject, ...]
    camera_motion: RigidMotion = field(default_factory=lambda: RigidMotion.camera((0, 0, 1.4), (0, 1, 0)))
    sun_direction: tuple[float, float, float] = (-0.45, -0.55, 0.70)
    sun_irradiance: float = 1.0
    ambient: float = 0.3
    sky_zenith: tuple[float, float, float] = (0.35, 0.55, 1.0)
    sky_horizon: tuple[float, float, float] = (0.95, 1.0, 1.05)
    emitter_lighting: bool = True

    def __post_init__(self) -> None:
        if not self.objects:
            raise InputError("DemoScene.objects is empty; add at least one SceneObject")
        if len(self.objects) > 65000:
            raise InputError("DemoScene: more than 65000 objects do not fit the 16-bit id pass")

    def camera_pose(self, frame: float) -> np.ndarray:
        """4×4 camera-to-world matrix ``[R_c | C]`` (columns right, down, forward) at ``frame``."""
        return self.camera_motion.matrix(frame)

    def object_pose(self, index: int, frame: float) -> np.ndarray:
        """4×4 local-to-world matrix of object ``index`` at ``frame``."""
        return self.objects[index].motion.matrix(frame)

    @property
    def sun_unit(self) -> np.ndarray:
        s = np.asarray(self.sun_direction, dtype=np.float64)
        return s / np.linalg.norm(s)

    # -- the demo --------------------------------------------------------------------------
    @staticmethod
    def default(camera_motion: bool = False) -> "DemoScene":
        """The demo: textured ground, objects from 0.5 m to 55 m, small bright emitters (radiance
        250–1000) at 1–54 m, four of them near the image corners, a cube at 5 m that slides 6 cm and
        spins 4° per frame, and (``camera_motion``) a dolly right of 1.5 cm + a pan left of 0.25° per
        frame.

        The layout is made for a 50 mm lens on a 36×24 mm sensor looking along +y from 1.4 m
        height, pitched 6° down; other lenses see more or less of it.
        """
        cam_forward = (0.0, math.cos(math.radians(6.0)), -math.sin(math.radians(6.0)))
        cam_kw = {}
        if camera_motion:
            # a slow dolly to the right with a slight pan left: both translation and rotation
            cam_kw = dict(velocity_m_per_frame=(0.015, 0.0, 0.0), axis=(0.0, 0.0, 1.0),
                          angular_velocity_rad_per_frame=math.radians(0.25))
        cam = RigidMotion.camera((0.0, 0.0, 1.4), cam_forward, **cam_kw)
        cam_r = cam.matrix(0)[:3, :3]
        cam_c = np.array(cam.position_m)

        # 50 mm / 36 mm sensor: tan(half FOV) = 18/50.85 horizontally, 12/50.85 vertically
        tan_x, tan_y = 18.0 / 50.85, 12.0 / 50.85

        def at_image(u: float, v: float, dist: float) -> tuple[float, float, float]:
            """World point at planar depth ``dist`` seen at normalised image position (u, v) ∈ [−1, 1]²
            (u right, v down) by the frame-0 camera."""
            xc = np.array([u * tan_x * dist, v * tan_y * dist, dist])
            return tuple(float(c) for c in cam_r @ xc + cam_c)

        def at(x: float, y: float, z: float) -> RigidMotion:
            return RigidMotion(position_m=(x, y, z))

        grey = Material(albedo=(0.8, 0.8, 0.8))
        objs: list[SceneObject] = [
            SceneObject("ground", Plane(200.0), Material(albedo=(0.55, 0.5, 0.42), albedo2=(0.12, 0.12, 0.13),
                                                         texture="ground"), casts_shadow=False),
            # foreground (0.5–1.5 m): a thin pole at the left edge, a small ball, a cube on a plinth
            SceneObject("near_pole", Cylinder(0.012, 0.8), Material(albedo=(0.7, 0.15, 0.1)),
                        RigidMotion(position_m=at_image(-0.85, 0.0, 0.8)[:2] + (0.8,))),
            SceneObject("near_ball", Sphere(0.025), Material(albedo=(0.9, 0.85, 0.2), albedo2=(0.1, 0.1, 0.5),
                                                             texture="checker", texture_scale_m=0.015),
                        at(*at_image(0.3, 0.7, 0.5))),
            SceneObject("plinth", Cylinder(0.12, 0.45), grey, at(0.55, 2.0, 0.45)),
            SceneObject("plinth_cube", Box((0.12, 0.12, 0.12)),
                        Material(albedo=(0.85, 0.85, 0.85), albedo2=(0.05, 0.2, 0.6), texture="checker",
                                 texture_scale_m=0.06),
                        RigidMotion(position_m=(0.55, 2.0, 1.02), angle_rad=math.radians(30))),
            # mid-ground: the focus plane (3 m) and the moving cube (≈ 5 m)
            SceneObject("ball_3m", Sphere(0.4), Material(albedo=(0.75, 0.3, 0.25), albedo2=(0.9, 0.9, 0.85),
                                                         texture="checker", texture_scale_m=0.1),
                        at(-0.75, 3.2, 0.4)),
            SceneObject("mover", Box((0.3, 0.3, 0.3)),
                        Material(albedo=(0.2, 0.55, 0.85), albedo2=(0.9, 0.9, 0.9), texture="checker",
                                 texture_scale_m=0.15),
                        RigidMotion(position_m=(0.9, 5.0, 0.3), velocity_m_per_frame=(-0.06, 0.0, 0.0),
                                    axis=(0.0, 0.0, 1.0), angle_rad=0.3,
                                    angular_velocity_rad_per_frame=math.radians(4.0))),
            SceneObject("pillar_8m", Cylinder(0.25, 1.0), Material(albedo=(0.6, 0.6, 0.55)), at(-1.6, 8.0, 1.0)),
            SceneObject("block_13m", Box((1.0, 1.0, 2.0)),
                        Material(albedo=(0.7, 0.65, 0.6), albedo2=(0.3, 0.25, 0.2), texture="checker",
                                 texture_scale_m=0.5),
                        RigidMotion(position_m=(-4.0, 13.0, 2.0), angle_rad=math.radians(20))),
            SceneObject("dome_25m", Sphere(2.0), Material(albedo=(0.3, 0.6, 0.3)), at(6.0, 25.0, 1.2)),
            SceneObject("tower_50m", Box((2.0, 2.0, 9.0)), Material(albedo=(0.6, 0.62, 0.7), albedo2=(0.2, 0.22, 0.3),
                                                                     texture="checker", texture_scale_m=1.0),
                        at(-11.0, 50.0, 9.0)),
            SceneObject("tower_55m", Box((3.0, 2.0, 6.0)), Material(albedo=(0.7, 0.6, 0.5)), at(12.0, 55.0, 6.0)),
        ]

        def light(name: str, pos, radius: float, radiance, casts=False) -> SceneObject:
            return SceneObject(name, Sphere(radius, resolution=24), Material(albedo=(0, 0, 0), emission=radiance),
                               at(*pos), casts_shadow=casts)

        warm, cool, white = (1.0, 0.75, 0.45), (0.6, 0.8, 1.0), (1.0, 1.0, 1.0)
        scale = lambda c, k: tuple(k * x for x in c)  # noqa: E731 - tiny local helper
        # near the four image corners at different depths
        objs += [
            light("lamp_tl_2m", at_image(-0.95, -0.88, 2.0), 0.006, scale(warm, 600.0)),
            light("lamp_br_1m", at_image(0.9, 0.85, 1.1), 0.004, scale(cool, 400.0)),
            light("lamp_tr_9m", at_image(0.88, -0.8, 9.0), 0.03, scale(white, 800.0)),
            light("lamp_bl_2_5m", at_image(-0.95, 0.85, 2.5), 0.008, scale((1.0, 0.3, 0.2), 500.0)),
        ]
        # street lights on poles along x = 3 m, 10–50 m away
        for k, y in enumerate((10.0, 20.0, 30.0, 40.0, 50.0)):
            objs.append(SceneObject(f"post_{k}", Cylinder(0.05, 1.2), Material(albedo=(0.25, 0.25, 0.25)),
                                    at(3.0, y, 1.2)))
            objs.append(light(f"street_{k}", (3.0, y, 2.5), 0.1, scale(warm, 300.0 + 100.0 * k)))
        # a row of distant city lights near the horizon and one over the mid-ground
        for k, x in enumerate((-6.0, -3.0, 1.0, 7.0)):
            objs.append(light(f"city_{k}", (x, 45.0 + 3 * k, 1.0 + 0.5 * k), 0.12, scale(cool if k % 2 else warm, 1000.0)))
        objs.append(light("lamp_mid_3m", (0.15, 3.0, 1.75), 0.01, scale(white, 250.0)))
        return DemoScene(objects=tuple(objs), camera_motion=cam)

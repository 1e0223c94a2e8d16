"""``clpost lens info`` / ``plot``: the numbers and datasheet plots of a lens (no image logic)."""
from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from .curves import _Field
from .lens import get_lens, lens_curves


def lens_info(name: str, sensor_mm=(36.0, 24.0), focus_distance_m: float = math.inf,
              f_number: float | None = None) -> dict:
    """Derived numbers of a lens (mm, degrees, %) as a JSON-ready dict, focused at
    ``focus_distance_m`` from the film (lens scale; ``at`` also gives the focus depth from the
    entrance pupil and the focused pinhole camera: its focal length K and angle of view)."""
    lens = get_lens(name)
    pres, px = lens.prescription, lens.paraxial
    n = lens.max_aperture if f_number is None else lens.clamp_f_number(f_number, warn=False)
    half_diag = math.hypot(*sensor_mm) / 2
    c = lens_curves(name, float(focus_distance_m), round(n, 9), half_diag)
    r_edge = c.image_height_max_mm
    covered = r_edge >= half_diag * (1 - 1e-9)

    def fov(k):
        r = k / 2
        if r > r_edge * (1 + 1e-9):
            return None
        return 2 * float(c.at("field_angle_deg", r))

    fs = lens.focus(focus_distance_m * 1000.0, n)
    ref = pres.reference
    out = {
        "name": name, "description": pres.description, "provenance": pres.provenance,
        "surfaces": len(pres.surfaces), "has_dispersion": pres.has_dispersion,
        "efl_mm": px.efl_mm, "bfl_mm": px.bfl_mm, "front_focal_z_mm": px.ffl_mm,
        "principal_planes_z_mm": [px.z_principal_front_mm, px.z_principal_rear_mm],
        "entrance_pupil": {"z_mm": px.z_entrance_pupil_mm, "diameter_mm": 2 * px.entrance_pupil_radius_mm},
        "exit_pupil": {"z_mm": px.z_exit_pupil_mm, "diameter_mm": 2 * px.exit_pupil_radius_mm},
        "total_track_mm": pres.total_track_mm,
        "f_number_range": [lens.max_aperture, lens.min_aperture],
        "paraxial_f_number": px.f_number, "nominal_f_number": pres.f_number,
        "min_focus_m": lens.min_focus_m,
        "sensor_mm": list(sensor_mm),
        "fov_deg": {"horizontal": fov(sensor_mm[0]), "vertical": fov(sensor_mm[1]),
                    "diagonal": fov(2 * half_diag)},
        "fov_paraxial_deg": {"horizontal": px.field_of_view_deg(sensor_mm[0]),
                             "vertical": px.field_of_view_deg(sensor_mm[1]),
                             "diagonal": px.field_of_view_deg(2 * half_diag)},
        "image_circle_covers_sensor": covered,
        "image_circle_radius_mm": r_edge,
        "at": {"focus_distance_m": focus_distance_m, "f_number": n,
               "extension_mm": fs.extension_mm, "back_distance_mm": fs.back_distance_mm,
               "thin_lens_error_mm": fs.thin_lens_error_mm,
               "focus_scale_m": fs.distance_mm / 1000.0, "depth_m": fs.depth_mm / 1000.0,
               "render_focal_mm": fs.render_focal_mm,
               "breathing": fs.render_focal_mm / lens.focus(math.inf, n).render_focal_mm,
               "fov_focused_deg": {"horizontal": math.degrees(2 * math.atan(sensor_mm[0] / (2 * fs.render_focal_mm))),
                                   "vertical": math.degrees(2 * math.atan(sensor_mm[1] / (2 * fs.render_focal_mm)))}},
        "corner": {"image_height_mm": r_edge, "field_angle_deg": float(c.field_angle_deg[-1]),
                   "distortion_pct": float(c.distortion_pct[-1]),
                   "relative_illumination": float(c.relative_illumination[-1]),
                   "lateral_color_um": 1000 * float(c.lateral_color_mm[-1])},
        "reference": dict(ref),
    }
    if "efl_mm" in ref:
        out["reference"]["efl_rel_error"] = px.efl_mm / ref["efl_mm"] - 1
        out["reference"]["bfl_rel_error"] = px.bfl_mm / ref["bfl_mm"] - 1
    if pres.published:
        out["published"] = dict(pres.published)
        out["published"]["efl_rel_error"] = px.efl_mm / pres.published["efl_mm"] - 1
    return out


def format_info(d: dict) -> str:
    def f(x, fmt="{:.4g}"):
        return "—" if x is None else fmt.format(x)

    fov, fovp, cn = d["fov_deg"], d["fov_paraxial_deg"], d["corner"]
    lines = [
        f"{d['name']}: {d['description']}",
        f"  source      {d['provenance'].get('source', '')}",
        f"  EFL {d['efl_mm']:.4f} mm   BFL {d['bfl_mm']:.4f} mm   track {d['total_track_mm']:.3f} mm   "
        f"{d['surfaces']} surfaces{'' if d['has_dispersion'] else ' (no dispersion data)'}",
        f"  principal planes H {d['principal_planes_z_mm'][0]:.3f}, H' {d['principal_planes_z_mm'][1]:.3f} mm "
        "(z from the first vertex)",
        f"  entrance pupil z {d['entrance_pupil']['z_mm']:.3f} mm, Ø {d['entrance_pupil']['diameter_mm']:.3f} mm; "
        f"exit pupil z {d['exit_pupil']['z_mm']:.3f} mm, Ø {d['exit_pupil']['diameter_mm']:.3f} mm",
        f"  f-number    f/{d['f_number_range'][0]:.3g} – f/{d['f_number_range'][1]:.3g} (real axial beam; "
        f"paraxial f/{d['paraxial_f_number']:.4g}, nominal f/{d['nominal_f_number']:g})   min focus {d['min_focus_m']:g} m",
        f"  FOV on {d['sensor_mm'][0]:g}x{d['sensor_mm'][1]:g}: {f(fov['horizontal'], '{:.1f}')}° H × "
        f"{f(fov['vertical'], '{:.1f}')}° V, {f(fov['diagonal'], '{:.1f}')}° diagonal (real chief rays; "
        f"paraxial {fovp['horizontal']:.1f}° × {fovp['vertical']:.1f}°, {fovp['diagonal']:.1f}°)",
    ]
    if not d["image_circle_covers_sensor"]:
        lines.append(f"  image circle radius {d['image_circle_radius_mm']:.2f} mm does not cover the sensor corner")
    lines.append(f"  at r = {cn['image_height_mm']:.2f} mm ({cn['field_angle_deg']:.1f}°), f/{d['at']['f_number']:.3g}, "
                 f"focus {d['at']['focus_distance_m']:g} m from the film: distortion {cn['distortion_pct']:+.2f} %, relative "
                 f"illumination {cn['relative_illumination']:.3f}, lateral colour {cn['lateral_color_um']:+.1f} µm")
    at = d["at"]
    lines.append(f"  focused at depth {at['depth_m']:.6g} m from the entrance pupil = {at['focus_scale_m']:.6g} m on the "
                 f"lens scale (from the film): render with focal length {at['render_focal_mm']:.4f} mm, "
                 f"{at['fov_focused_deg']['horizontal']:.2f}° × {at['fov_focused_deg']['vertical']:.2f}° "
                 f"(breathing ×{at['breathing']:.4f} of infinity focus)")
    ref = d.get("reference", {})
    if "efl_rel_error" in ref:
        lines.append(f"  vs reference ({ref.get('source', '')}): EFL {ref['efl_rel_error'] * 100:+.5f} %, "
                     f"BFL {ref['bfl_rel_error'] * 100:+.5f} %")
    if "published" in d:
        p = d["published"]
        lines.append(f"  vs published ({p.get('source', '')}): EFL {p['efl_rel_error'] * 100:+.3f} %")
    return "\n".join(lines)


def plot_lens(name: str, path, sensor_mm=(36.0, 24.0), focus_distance_m: float = math.inf) -> None:
    """A one-page datasheet: layout with ray fans, distortion, relative illumination at several
    f-numbers, field curves, spherical aberration, lateral colour."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise InputError("clpost lens plot needs matplotlib: pip install 'clpost[plot]'") from None
    from .trace import trace

    lens = get_lens(name)
    half_diag = math.hypot(*sensor_mm) / 2
    nmax = lens.max_aperture
    stops = [nmax] + [s for s in (2.0, 2.8, 4.0, 5.6, 8.0, 11.0, 16.0) if s > nmax * 1.05][:3]
    cs = {n: lens_curves(name, float(focus_distance_m), round(n, 9), half_diag) for n in stops}
    c0 = cs[nmax]
    fig = plt.figure(figsize=(13, 8.2))
    gs = fig.add_gridspec(2, 3, height_ratios=[1, 1], hspace=0.5, wspace=0.28)
    fig.suptitle(f"{name} — {lens.prescription.description}\nEFL {lens.efl_mm:.2f} mm, f/{nmax:.2g}, "
                 f"focus {'∞' if math.isinf(focus_distance_m) else f'{focus_distance_m:g} m'}, "
                 f"sensor {sensor_mm[0]:g}×{sensor_mm[1]:g} mm (d line unless noted)", fontsize=11)
    grid = dict(color="0.85", lw=0.6)

    # Layout with traced fans.
    ax = fig.add_subplot(gs[0, 0:2])
    pres = lens.focused(focus_distance_m * 1000.0, nmax)
    zs = pres.vertex_z
    surfs = pres.surfaces
    for k, s in enumerate(surfs):
        h = np.linspace(-s.semi_diameter_mm, s.semi_diameter_mm, 81)
        z = zs[k] + np.array([s.sag(abs(v)) for v in h])
        ax.plot(z, h, color="k" if not s.stop else "tab:red", lw=1.0 if not s.stop else 2.0)
        if s.n_d > 1 and k + 1 < len(surfs):  # glass element: draw its edges
            s2 = surfs[k + 1]
            hm = min(s.semi_diameter_mm, s2.semi_diameter_mm)
            for sg in (1, -1):
                ax.plot([zs[k] + s.sag(hm), zs[k + 1] + s2.sag(hm)], [sg * hm, sg * hm], color="k", lw=0.8)
    zf = zs[-1] + surfs[-1].thickness_mm
    ax.axvline(zf, color="0.4", lw=1.5)
    ax.axhline(0, color="0.6", lw=0.5, ls="-.")
    fld = _Field(lens, pres, focus_distance_m * 1000.0, lens.stop_radius_mm(nmax))
    r_e = lens.efl_mm / (2 * nmax)
    for frac, col in ((0.0, "tab:blue"), (0.7, "tab:green"), (1.0, "tab:orange")):
        th = math.radians(float(np.interp(frac * c0.image_height_max_mm, c0.image_height_mm, c0.field_angle_deg)))
        a = fld.chief_aim(np.array([th]))[0]
        ys = a + np.linspace(-1.6, 1.6, 41) * r_e / math.cos(th)
        o, d = fld.rays(np.full(ys.size, th), 0.0, ys)
        # Record the path surface by surface (trace to each vertex plane successively).
        pts = [o.copy()]
        for k in range(len(surfs)):
            part = type(pres)(**{**pres.__dict__, "surfaces": pres.surfaces[:k + 1]})
            rr = trace(part, o, d, stop_radius_mm=fld.stop_r if pres.stop_index <= k else None,
                       z_film=zs[k] + 1e-12)
            pts.append(np.where(rr.ok[:, None], rr.pos, np.nan))
        rr = trace(pres, o, d, stop_radius_mm=fld.stop_r)
        pts.append(np.where(rr.ok[:, None], rr.pos, np.nan))
        P = np.stack(pts)  # (S+2, N, 3)
        okr = rr.ok
        for j in np.flatnonzero(okr)[::3]:
            ax.plot(P[:, j, 2], P[:, j, 1], color=col, lw=0.6, alpha=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("z (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title("layout: rays on axis, at 70 % and 100 % field, wide open")
    ax.grid(**grid)

    # Spherical aberration.
    ax = fig.add_subplot(gs[0, 2])
    ax.plot(c0.lsa_mm, c0.pupil_rho, color="k")
    ax.axvline(0, color="0.5", lw=0.8)
    ax.set_xlabel("longitudinal SA from paraxial focus (mm)")
    ax.set_ylabel(f"pupil height (1 = f/{nmax:.2g})")
    ax.set_title("spherical aberration (on axis)")
    ax.grid(**grid)

    ax = fig.add_subplot(gs[1, 0])
    ax.plot(c0.image_height_mm, c0.distortion_pct, color="k")
    ax.axhline(0, color="0.5", lw=0.8)
    ax.set_xlabel("image height (mm)")
    ax.set_ylabel("distortion (%)")
    ax.set_title("distortion")
    ax.set_xlim(0, half_diag)
    ax.grid(**grid)

    ax = fig.add_subplot(gs[1, 1])
    for n, c in cs.items():
        ax.plot(c.image_height_mm, 100 * c.relative_illumination, label=f"f/{n:.2g}")
    ax.set_ylim(0, 105)
    ax.set_xlim(0, half_diag)
    ax.set_xlabel("image height (mm)")
    ax.set_ylabel("relative illumination (%)")
    ax.set_title("relative illumination (vignetting)")
    ax.legend(fontsize=8, loc="lower left")
    ax.grid(**grid)

    ax = fig.add_subplot(gs[1, 2])
    ax.plot(c0.sagittal_offset_mm, c0.image_height_mm, color="tab:blue", label="sagittal")
    ax.plot(c0.tangential_offset_mm, c0.image_height_mm, color="tab:blue", ls="--", label="tangential")
    if lens.prescription.has_dispersion:
        ax2 = ax.twiny()
        ax2.plot(1000 * c0.lateral_color_mm, c0.image_height_mm, color="tab:purple", lw=0.9)
        ax2.set_xlabel("lateral colour F−C (µm)", color="tab:purple")
    ax.axvline(0, color="0.5", lw=0.8)
    ax.set_ylim(0, half_diag)
    ax.set_xlabel("focal offset from the film (mm)")
    ax.set_ylabel("image height (mm)")
    ax.set_title(f"field curves (f/{nmax:.2g})", pad=18 if lens.prescription.has_dispersion else 6)
    ax.legend(fontsize=8, loc="lower left")
    ax.grid(**grid)
    from ..atomic import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)

"""Real lenses: prescriptions, paraxial vs published numbers, real trace, focusing, curves, CLI."""
import json
import math
import warnings

import numpy as np
import pytest

from clpost import Camera, InputError
from clpost.cli import main
from clpost.optics import FNumberClampedWarning, available_lenses, get_lens, load_prescription
from clpost.optics.paraxial import paraxial, yu_trace
from clpost.optics.prescription import cauchy_coefficients, parse_prescription
from clpost.optics.trace import CLIPPED, MISS, OK, STOP, TIR, trace

LENSES = available_lenses()
FLAGSHIP = "zeiss-planar-50-f1.4"


def test_all_required_lenses_present_with_provenance():
    for name in ("zeiss-planar-50-f1.4", "dgauss-50", "wide-22", "telephoto-250", "fisheye-10",
                 "thorlabs-ac254-050-a", "thorlabs-lb1471"):
        p = load_prescription(name)
        assert p.provenance["source"] and p.provenance["dataset"]


@pytest.mark.parametrize("name", LENSES)
def test_efl_bfl_match_reference_to_0p1_percent(name):
    p = load_prescription(name)
    q = paraxial(p)
    assert q.efl_mm == pytest.approx(p.reference["efl_mm"], rel=1e-3)
    assert q.bfl_mm == pytest.approx(p.reference["bfl_mm"], rel=1e-3)
    assert 2 * q.entrance_pupil_radius_mm == pytest.approx(p.reference["epd_mm"], rel=1e-3)
    if p.published:
        tol = p.published.get("tolerance", 1e-3)
        assert q.efl_mm == pytest.approx(p.published["efl_mm"], rel=tol)
        if "bfl_mm" in p.published:
            assert q.bfl_mm == pytest.approx(p.published["bfl_mm"], rel=tol)


def test_flagship_matches_patent_and_is_f1p4():
    lens = get_lens(FLAGSHIP)
    assert lens.efl_mm == pytest.approx(50.0, rel=1e-3)  # US 3,874,771 Ex. 5: F = 1 (x50)
    assert lens.paraxial.bfl_mm == pytest.approx(0.70993 * 50, rel=1e-3)
    assert lens.max_aperture == pytest.approx(1.4, rel=1e-4)  # stop sized for a real EFL/1.4 beam


def test_thick_lens_closed_form_for_the_singlet():
    # Lensmaker's equation for a thick lens (Hecht 6.2): 1/f = (n-1)[1/R1 - 1/R2 + (n-1)d/(n R1 R2)]
    n, r1, r2, d = 1.5168, 50.6, -50.6, 5.24
    f = 1 / ((n - 1) * (1 / r1 - 1 / r2 + (n - 1) * d / (n * r1 * r2)))
    assert get_lens("thorlabs-lb1471").efl_mm == pytest.approx(f, rel=1e-12)


@pytest.mark.parametrize("name", LENSES)
def test_real_and_paraxial_agree_near_the_axis(name):
    p = load_prescription(name)
    h = 1e-5
    r = trace(p, [[0.0, h, -1.0]], [[0.0, 0.0, 1.0]])
    assert r.status[0] == OK
    y, u = yu_trace(p, h, 0.0)
    slope_real = r.dir[0, 1] / r.dir[0, 2]
    assert slope_real == pytest.approx(u[-1], rel=1e-9)
    z_cross_real = r.pos[0, 2] - r.pos[0, 1] / slope_real - p.total_track_mm
    assert z_cross_real == pytest.approx(paraxial(p).bfl_mm, rel=1e-9)


def test_cauchy_reproduces_abbe_number_and_reference_indices():
    a, b = cauchy_coefficients(1.717, 47.99)
    nf, nd, nc = (a + b / lam ** 2 for lam in (486.1327, 587.5618, 656.2725))
    assert nd == pytest.approx(1.717, abs=1e-12)
    assert (nd - 1) / (nf - nc) == pytest.approx(47.99, rel=1e-12)
    assert (a, b) == pytest.approx((1.694337214, 7823.847906), rel=1e-9)  # reference table
    # N-BK7 (Schott Sellmeier n_F 1.5223763, n_C 1.5143223): the fit agrees to 1e-4
    p = load_prescription("thorlabs-lb1471")
    assert p.indices(486.1327)[1] == pytest.approx(1.5223763, abs=1e-4)
    assert p.indices(656.2725)[1] == pytest.approx(1.5143223, abs=1e-4)


def test_trace_reports_miss_clip_stop_and_tir_per_ray():
    p = load_prescription(FLAGSHIP)
    o = np.array([[0, 1, -1], [0, 30, -1], [0, 17.5, -1], [0, 0, -1], [0, 0, -1.0]])
    d = np.array([[0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 0, -1], [0, 0.999, 0.04]])
    r = trace(p, o, d)
    assert r.status[0] == OK
    assert r.status[1] == CLIPPED and r.surface[1] == 0
    assert r.status[3] == MISS  # travelling away from the lens
    stopped = trace(p, o[:1] * [1, 17, 1], d[:1], stop_radius_mm=1.0)
    assert stopped.status[0] == STOP and stopped.surface[0] == p.stop_index
    for arr in (r.pos, r.dir, r.stop_xy):
        assert np.isfinite(arr).all()
    # TIR: a plano-convex n = 1.9 lens, R = 10: a ray at h = 9 meets the plane exit at 35.8°,
    # beyond the critical angle asin(1/1.9) = 31.8°; the ray at h = 2 passes.
    slab = parse_prescription({"name": "tir", "focal_length_mm": 11.1, "f_number": 1.0, "provenance": {"source": "test"},
                               "surface": [dict(radius_mm=10.0, thickness_mm=8.0, n_d=1.9, semi_diameter_mm=9.5),
                                           dict(radius_mm=0, thickness_mm=5.0, n_d=1.0, semi_diameter_mm=9.5, stop=True)]},
                              "tir.toml")
    g = trace(slab, [[0, 9.0, -1], [0, 2.0, -1]], [[0, 0, 1], [0, 0, 1]])
    assert list(g.status) == [TIR, OK] and g.surface[0] == 1
    assert np.isfinite(g.pos).all()


def test_grazing_rays_stay_finite():
    p = load_prescription("wide-22")
    ang = np.radians(np.linspace(80, 89.999, 50))
    o = np.stack([np.zeros(50), np.full(50, -5.0), np.full(50, -1.0)], 1)
    d = np.stack([np.zeros(50), np.sin(ang), np.cos(ang)], 1)
    r = trace(p, o, d)
    assert np.isfinite(r.pos).all() and np.isfinite(r.dir).all()
    assert set(np.unique(r.status)) <= {OK, MISS, CLIPPED, STOP, TIR}


def test_opencl_trace_equals_numpy(rng):
    from clpost.optics.cltrace import trace_cl

    for name in (FLAGSHIP, "fisheye-10"):
        p = load_prescription(name)
        n = 4099
        o = np.c_[rng.uniform(-20, 20, (n, 2)), np.full(n, -3.0)]
        d = np.c_[rng.normal(0, 0.4, (n, 2)), np.ones(n)]
        a, b = trace(p, o, d), trace_cl(p, o, d)
        assert (a.status == b.status).all() and (a.surface == b.surface).all()
        assert len(set(a.status)) >= 3  # the bundle exercises several fates
        err = np.abs(a.pos - b.pos)
        worst = np.unravel_index(np.argmax(err), err.shape)
        assert err.max() < 1e-9, f"{name}: max |Δpos| {err.max():.3g} mm at ray {worst}"
        assert np.abs(a.dir - b.dir).max() < 1e-12
        assert np.abs(a.stop_xy - b.stop_xy).max() < 1e-9


def _write(tmp_path, text):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    return path


GOOD = """name = "bad"
focal_length_mm = 50.0
f_number = 2.0
[provenance]
source = "test"
[[surface]]
radius_mm = 50.6
thickness_mm = 5.0
n_d = 1.5168
V_d = 64.17
semi_diameter_mm = 12.0
[[surface]]
radius_mm = 0
thickness_mm = 2.0
n_d = 1.5168
semi_diameter_mm = 11.0
stop = true
[[surface]]
radius_mm = -50.6
thickness_mm = 48.0
n_d = 1.0
semi_diameter_mm = 12.0
"""


@pytest.mark.parametrize("edit, words", [
    (lambda s: s.replace("thickness_mm = 5.0", "thickness_mm = -5.0"), "surface 1: field 'thickness_mm'"),
    (lambda s: s.replace("n_d = 1.5168\nV_d", "V_d", 1), "surface 1: missing field 'n_d'"),
    (lambda s: s.replace("stop = true\n", ""), "stop = true"),
    (lambda s: s.replace("thickness_mm = 5.0", "thickness_mm = 0.2"), "surfaces 1 and 2 intersect"),
    (lambda s: s.replace("semi_diameter_mm = 12.0", "semi_diameter_mm = 60.0", 1), "surface 1: field 'semi_diameter_mm'"),
    (lambda s: s.replace('[provenance]\nsource = "test"\n', ""), "provenance"),
    (lambda s: s.replace("V_d = 64.17", 'V_d = "x"'), "surface 1: field 'V_d'"),
])
def test_malformed_files_name_file_surface_and_field(tmp_path, edit, words):
    from clpost.optics import load_prescription_file

    assert load_prescription_file(_write(tmp_path, GOOD)).stop_index == 1
    path = _write(tmp_path, edit(GOOD))
    with pytest.raises(InputError, match=words) as exc:
        load_prescription_file(path)
    assert str(path) in str(exc.value)


def test_f_number_below_maximum_is_clamped_with_warning():
    with pytest.warns(FNumberClampedWarning, match="maximum aperture"):
        cam = Camera(lens=FLAGSHIP, f_number=0.7)
    assert cam.f_number == pytest.approx(1.4, rel=1e-4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Camera(lens=FLAGSHIP, f_number=2.0)


def test_camera_with_real_lens_focus_from_min_to_infinity():
    lens = get_lens(FLAGSHIP)
    prev = None
    for u in (0.45, 0.6, 1.0, 3.0, 10.0, 1e4, math.inf):
        cam = Camera(lens=FLAGSHIP, f_number=2.0, focus_distance_m=u)
        v = cam.image_distance_mm
        assert math.isfinite(v) and v >= lens.efl_mm - 1e-9
        if prev is not None:
            assert v < prev  # closer focus needs more extension
        prev = v
        if u <= 10.0:  # beyond, the extension (< 1 µm) is below the solver's resolution
            # Stopped down the real focus is paraxial: the thin-lens equivalent (f = EFL,
            # v = f + extension, u from H) is within 0.1 %; wide open, spherical aberration's
            # focus shift changes with distance and moves it by up to ~2.5 %.
            st = lens.focus(u * 1000, 16.0)
            assert abs(st.thin_lens_error_mm) < 1e-3 * st.object_distance_from_h_mm
            st = lens.focus(u * 1000, 2.0)
            assert abs(st.thin_lens_error_mm) < 0.03 * st.object_distance_from_h_mm
    assert Camera(lens=FLAGSHIP, focus_distance_m=math.inf).image_distance_mm == pytest.approx(lens.efl_mm)
    assert Camera(lens=FLAGSHIP).focal_length_mm == pytest.approx(50.0, rel=1e-3)
    with pytest.raises(InputError, match="minimum focus distance 0.45 m"):
        Camera(lens=FLAGSHIP, focus_distance_m=0.3)
    with pytest.raises(InputError, match="zeiss-planar-50-f1.4"):
        Camera(lens="zeiss")
    assert Camera(lens="thin:50").optics is None and Camera(lens="thin:50").lens_curves() is None


def test_focused_lens_really_images_the_object_point():
    lens = get_lens(FLAGSHIP)
    st = lens.focus(1000.0, 8.0)
    pres = lens.focused(1000.0, 8.0)
    zf = pres.total_track_mm + pres.surfaces[-1].thickness_mm
    h = np.linspace(-1, 1, 21) * lens.efl_mm / 16 * 0.9
    o = np.tile([0.0, 0.0, zf - 1000.0], (h.size, 1))
    d = np.stack([np.zeros_like(h), h, np.full_like(h, lens.paraxial.z_entrance_pupil_mm - (zf - 1000.0))], 1)
    r = trace(pres, o, d, stop_radius_mm=lens.stop_radius_mm(8.0))
    assert r.ok.all()
    assert np.sqrt(np.mean(r.pos[:, 1] ** 2)) < 0.01  # < 10 µm RMS at f/8
    assert st.extension_mm > 0


@pytest.mark.parametrize("name", LENSES)
def test_curves_bounded_smooth_and_zero_on_axis(name):
    lens = get_lens(name)
    c = lens.curves(math.inf, lens.max_aperture)
    assert c.distortion_pct[0] == 0.0 and c.relative_illumination[0] == pytest.approx(1.0)
    assert ((c.relative_illumination >= 0) & (c.relative_illumination <= 1)).all()
    for arr in (c.distortion_pct, c.sagittal_offset_mm, c.tangential_offset_mm, c.lateral_color_mm, c.lsa_mm):
        assert np.isfinite(arr).all()
    # smooth: second differences of distortion are small against its range
    d2 = np.abs(np.diff(c.distortion_pct, 2))
    assert d2.max() <= 0.05 * max(1.0, np.ptp(c.distortion_pct))
    # astigmatic foci coincide on axis
    assert c.sagittal_offset_mm[0] == pytest.approx(c.tangential_offset_mm[0], abs=1e-6)
    assert np.diff(c.image_height_mm).min() > 0
    # stopping down never darkens the corner (optical vignetting shrinks)
    c8 = lens.curves(math.inf, max(8.0, lens.max_aperture))
    assert c8.relative_illumination[-1] >= c.relative_illumination[-1] - 0.02


def test_natural_vignetting_is_cos4_for_a_small_stop_singlet():
    # A stopped-down lens with small distortion follows cos^4 (Smith, MOE §10.3) to within its distortion.
    lens = get_lens("telephoto-250")
    c = lens.curves(math.inf, 32.0)
    th = np.radians(c.field_angle_deg)
    assert np.allclose(c.relative_illumination, np.cos(th) ** 4, atol=0.02)


def test_curves_are_cached_and_exposed_on_the_camera():
    cam = Camera(lens=FLAGSHIP, f_number=2.8, focus_distance_m=3.0)
    assert cam.lens_curves() is cam.lens_curves()
    c = cam.lens_curves()
    assert c.f_number == 2.8 and c.focus_distance_m == cam.focus_from_film_m  # curves: lens scale
    assert c.at("relative_illumination", 0.0) == pytest.approx(1.0)
    assert c.pupil_masks.shape[0] == c.pupil_field_mm.size
    frac = c.pupil_area_fraction()
    assert frac[0] == pytest.approx(1.0, abs=0.03) and frac[-1] < frac[0]  # cat's eye at the corner


@pytest.mark.slow
def test_cli_lens_list_info_json_and_plot(tmp_path, capsys):
    assert main(["lens", "list"]) == 0
    out = capsys.readouterr().out
    for name in LENSES:
        assert name in out
    assert main(["lens", "info", FLAGSHIP, "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["efl_mm"] == pytest.approx(50.0, rel=1e-3)
    from clpost.optics.report import lens_info

    assert d["efl_mm"] == lens_info(FLAGSHIP)["efl_mm"]
    assert main(["lens", "info", "no-such-lens"]) == 2
    assert "no-such-lens" in capsys.readouterr().err
    png = tmp_path / "planar.png"
    pytest.importorskip("matplotlib")
    assert main(["lens", "plot", "thorlabs-lb1471", "-o", str(png)]) == 0
    assert png.stat().st_size > 10000


def test_cli_plot_without_matplotlib_names_the_extra(tmp_path, capsys, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "matplotlib", None)
    assert main(["lens", "plot", FLAGSHIP, "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "clpost[plot]" in err and len(err.strip().splitlines()) == 1

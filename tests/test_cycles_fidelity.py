"""clpost on Blender/Cycles exports against Cycles' own truths (tests/data/cycles, docs/fidelity.md).

The pinhole EXRs are read exactly as Blender wrote them; the floors below are today's measured
levels (tools/cycles_compare.py, the table in docs/fidelity.md) minus a margin, so a change that
makes clpost worse on a renderer's output fails here. They are NOT the issue's targets (final
within 4 dB of the noise floor, FLIP ≤ 0.03, bokeh discs within 10 %, no in-focus halo, energy
within 3 %): docs/fidelity.md lists those as the goal. Raise a floor when clpost improves.
"""
import json
import math
from pathlib import Path

import numpy as np
import pytest

from clpost import fidelity as fd
from clpost.exr import read_frame

from conftest import assert_two_layers_meet_the_targets

DATA = Path(__file__).parent / "data" / "cycles"
MANIFEST = json.loads((DATA / "manifest.json").read_text())
MARGIN_DB = 0.5

# PSNR of the sRGB view vs the Cycles truth, measured with tools/cycles_compare.py (docs/fidelity.md):
# (scene, truth, quality) -> dB
# (final on every truth, draft where it differs most; preview equals draft on these small CoCs).
# Set after the DoF fringe rule: it gained 1.2-7.1 dB on emitters/highlights/thin/motion and lost 0.56 dB
# (occluder) and 1.42 dB (transparent: under a 0.3-opacity pane Cycles' depth pass is a per-pixel speckle
# of the pane's and the wall's depth, and the rule moves checker-edge pixels to the pane) — docs/fidelity.md.
MEASURED_PSNR = {
    # 33.50; 34.62 before the upsampling compared the original CoC; 35.16 before the narrow-source layer;
    # 37.06 before its 1/4-px coverage ramp
    ("emitters", "dof", "draft"): 37.38,
    ("emitters", "dof", "final"): 37.64,        # 37.34 before the lights' 1/4-px ramp (dof.LIGHT_RAMP_PX)
    # 38.32; 40.27 before the stricter fringe rule; 40.32 before UPSAMPLE_SAME_PX; 41.04 before the
    # narrow-source layer; 41.64 before its 1/4-px coverage ramp, 42.07 with it before the light's tail
    # (which keeps three single pixel-filter tail samples sharp, as in the export: docs/fidelity.md)
    ("highlights", "dof", "draft"): 41.92,
    ("highlights", "dof", "final"): 42.95,      # 42.41 before the lights' 1/4-px ramp; 42.64; 42.72 before the light's tail
    ("occluder", "dof", "final"): 41.12,        # 40.90 before the stricter fringe rule
    ("thin", "dof", "draft"): 39.16,            # 36.25; 37.45 before the 3x3 below r = 2 px; measured 39.06 now
    ("thin", "dof", "final"): 41.18,            # 40.55 before the 0.25 px front margin; measured 41.16 now
    ("motion", "dof", "draft"): 48.85,          # 48.78 before the light's tail; 39.85; 42.70 before the 3x3 below r = 2 px
    ("motion", "dof", "final"): 49.80,          # 48.36; 48.55 before final's small CoCs; 49.72 before the light's tail
    ("motion", "motion", "draft"): 37.90,       # 37.67 before draft's 19-tap cap; 34.10 before the coverage gather
    ("motion", "motion", "final"): 37.50,       # 34.52
    ("motion", "dofmotion", "final"): 37.45,    # 34.62; 37.42 before the 0.25 px front margin
    # 38.01; 38.73 before the despeckle; 39.96 before the lamp-behind-a-pane rule; 43.39 before the
    # small lights' 3x3 share (dof.small_layer) and the light's tail
    ("transparent", "dof", "draft"): 43.99,
    ("transparent", "dof", "final"): 44.62,     # 44.13 (measured 44.34) before the lights' 1/4-px ramp (44.618 with the small lights' 3x3); 39.82 before the despeckle; 41.10 before the lamp-behind-a-pane rule
    ("macro", "dof", "draft"): 29.94,           # 28.67; 29.94 before the narrow-source layer (NARROW_EDGE_PX), 29.91 after it and before the depth-aware tile plan
    ("macro", "dof", "final"): 34.45,           # 33.94 (its large-reach tiles take the half-resolution path)
}


_channels = fd.read_rgb


def _scene(name):
    entry = MANIFEST["scenes"][name]
    return entry, read_frame(DATA / entry["pinhole"]["file"])


def _run(entry, frame, kind, quality):
    return fd.cycles_pipeline(entry, kind, quality).run(frame).color[..., :3]


def _lamps(entry, frame, quality, lamps=None):
    """Each lamp's emitter metrics (clpost.fidelity.emitter_metrics) for clpost's DoF at ``quality``."""
    return fd.lamp_metrics(lambda f: _run(entry, f, "dof", quality), DATA, entry, frame, 0.6, lamps=lamps)


def test_pinhole_exports_read_as_blender_writes_them():
    """Every pinhole is Blender's multilayer layout: planar depth with the 1e10 sky read as +inf,
    the lamps' depth where they are, and vectors (static scenes: zero)."""
    for name, entry in MANIFEST["scenes"].items():
        frame = read_frame(DATA / entry["pinhole"]["file"])
        w, h = entry["size"]
        assert frame.metadata["layout"] == "blender", name
        assert frame.color.shape[:2] == (h, w) and frame.velocity is not None, name
        assert np.all(np.isinf(frame.depth) | (frame.depth < 1000)), name
        if not entry["shot"]["motion"]:
            assert np.abs(frame.velocity).max() < 0.01, name
        for lamp in entry["lamps"]:
            i, j = round(lamp["x_px"]), round(lamp["y_px"])
            if 0 <= i < w and 0 <= j < h and frame.depth[j, i] < 1000 and lamp["diameter_px"] >= 2:
                if abs(frame.depth[j, i] - lamp["depth_m"]) < 0.05 * lamp["depth_m"]:
                    continue
                # a lamp hidden behind a nearer surface
                assert frame.depth[j, i] < lamp["depth_m"], (name, lamp["name"])


@pytest.mark.skipif("motion" not in MANIFEST["scenes"], reason="no motion scene stored")
def test_blender_vectors_are_forward_y_down_after_reading():
    """Blender 5.0's Vector pass as clpost reads it (docs/conventions.md): the ball moves −0.12 m
    in x and −0.09 m in z per frame at ≈ 2.4 m, i.e. left and down in the image: (−34, +25) px/frame
    at 480 wide; the cube slides right (+0.12 m per frame at 4 m)."""
    entry, frame = _scene("motion")
    f_px = entry["shot"]["focal_mm"] * entry["size"][0] / entry["shot"]["sensor_mm"]
    # 20 px left of the ball's centre (x 0.33, z 1.2 at frame 1, depth 2.5): clear of the pillar
    x = (entry["size"][0] - 1) / 2 + f_px * 0.33 / 2.5 - 20
    y = (entry["size"][1] - 1) / 2 - f_px * (1.2 - 1.5) / 2.5
    v = frame.velocity[round(y) - 2:round(y) + 3, round(x) - 2:round(x) + 3].reshape(-1, 2)
    depth = float(np.median(frame.depth[round(y) - 2:round(y) + 3, round(x) - 2:round(x) + 3]))
    assert 2.3 < depth < 2.5  # on the ball
    expect = np.array([-0.12, 0.09]) * f_px / depth  # pure translation: f_px·ΔX/Z
    assert np.allclose(np.median(v, axis=0), expect, rtol=0.03), (np.median(v, axis=0), expect)
    cube = frame.velocity[(entry["size"][1] - 1) // 2 + 50, (entry["size"][0] - 1) // 2 - 10]
    assert cube[0] > 15 and abs(cube[1]) < 3, cube  # slides right, spins about the vertical


@pytest.mark.parametrize("scene,kind,quality", sorted(MEASURED_PSNR))
def test_psnr_floor_vs_cycles(scene, kind, quality):
    entry, frame = _scene(scene)
    truth = _channels(DATA / entry["truths"][kind]["file"], "")
    out = _run(entry, frame, kind, quality)
    psnr = fd.psnr_srgb(truth, out)
    assert psnr >= MEASURED_PSNR[scene, kind, quality] - MARGIN_DB, f"{scene} {kind} {quality}: {psnr:.2f} dB"


def test_truths_are_defocused_beyond_their_noise():
    """Guards the data: each truth differs from its pinhole far more than its own seed-to-seed noise,
    and the floors recorded are the ≥ 36 dB the suite promises."""
    for name, entry in MANIFEST["scenes"].items():
        frame = read_frame(DATA / entry["pinhole"]["file"])
        for kind, t in entry["truths"].items():
            truth = _channels(DATA / t["file"], "")
            assert t["noise_floor_psnr_srgb_db"] >= 36.0, (name, kind)
            assert fd.psnr_srgb(truth, frame.color) < t["noise_floor_psnr_srgb_db"] - 3.0, (name, kind)


def test_emitter_regressions_on_the_emitters_scene():
    """clpost final's per-lamp behaviour may not get worse than measured (issue 16: today the discs
    are up to 2.1× Cycles' area and in-focus lamps get ≈ 100-pixel halos; the goal is 1 ± 0.1 and
    ≤ 2× Cycles' halo)."""
    entry, frame = _scene("emitters")
    m = _lamps(entry, frame, "final")
    areas = [x["area_ratio"] for x in m if x.get("area_ratio") is not None]
    energy = [x["energy_ratio"] for x in m if x["energy_ratio"] is not None]
    halo = sum(x["halo_test"] for x in m if x["in_focus"])
    assert max(areas) <= MEASURED_EMITTERS["area_ratio_max"] + 0.1, areas
    assert halo <= MEASURED_EMITTERS["halo_px_sum"] * 1.2, halo
    assert min(energy) >= MEASURED_EMITTERS["energy_min"] - 0.03, energy
    assert max(abs(e - 1) for e in energy) < 0.5 and not any(math.isnan(e) for e in energy)
    # the defocused lamps meet issue 16's energy target (3 %) since the 0.25 px front margin
    # (the 12 m lamps kept 95.0 % / 96.3 % before); the in-focus 1 px lamp01 does not: the depth
    # pass missed it (docs/fidelity.md, "Emitter energy")
    defocused = {x["name"]: round(x["energy_ratio"], 3) for x in m if not x["in_focus"] and x["energy_ratio"]}
    assert len(defocused) >= 6 and all(abs(e - 1) <= 0.03 for e in defocused.values()), defocused
    # the defocused discs meet issue 16's 10 % since the lights' ¼-px ramp (dof.LIGHT_RAMP_PX):
    # 0.93–1.03, lamp09 (2 px at r = 2.1 px before the wall) 1.235 and lamp10 1.116 before
    assert len(areas) >= 7 and all(0.9 <= a <= 1.1 for a in areas), areas


def test_in_focus_lamps_with_a_depth_sample_have_no_halo():
    """highlights' in-focus lamps 00, 02, 03 (2–3 px at 2.5 m over buildings at 13–46 m): single
    samples of the export's pixel-filter tail two pixels from their depth hits kept the buildings'
    depth and spread as halos of 16, 14, 15 px (draft) / 13, 25, 10 (final), Cycles 0, until the
    light's tail clause of the fringe rule (docs/fidelity.md, "In-focus halos"): 2, 0, 0 / 0, 0, 0.
    lamp01 (1 px) has no depth sample at all: its 30 px are left (no evidence of its depth)."""
    entry, frame = _scene("highlights")
    for quality, most in (("draft", 2), ("final", 0)):
        m = _lamps(entry, frame, quality, lamps=[x for x in entry["lamps"] if x["name"] != "lamp01"])
        assert all(x["in_focus"] and x["halo_truth"] == 0 for x in m)
        assert sum(x["halo_test"] for x in m) <= most, (quality, [x["halo_test"] for x in m])


def test_draft_emitters_keep_final_s_discs_and_energy():
    """The emitters scene's defocused lamps at draft (= preview here): the half-resolution path's
    soft disc edge (2×2 box, working coverage ramp, bilinear upsampling) saturated 1.15–1.48×
    Cycles' disc area at 100–1000× white and spread light beyond the window (energy 0.917–1.012);
    the narrow-source layer spreads them at full resolution (docs/fidelity.md, "The narrow-source
    layer"): 1.00–1.24× and 0.978–1.015 measured, final's own levels; with its 1/4-px coverage
    ramp (dof.NARROW_RAMP_PX: the input is already pixel-filtered) 0.93–1.03× — lamp09, 2 px at
    r = 2.1 px before the wall, was 1.24× with the 1-px ramp — and the same energies."""
    entry, frame = _scene("emitters")
    m = _lamps(entry, frame, "draft")
    defocused = {x["name"]: (round(x["area_ratio"], 2), round(x["energy_ratio"], 3)) for x in m
                 if not x["in_focus"] and x["energy_ratio"]}
    assert len(defocused) >= 7
    assert all(0.90 <= a <= 1.10 for a, _ in defocused.values()), defocused
    assert all(abs(e - 1) <= 0.03 for _, e in defocused.values()), defocused


def test_the_lamp_behind_the_pane_keeps_its_own_depth():
    """The transparent scene's lamp01 (2 px at 9 m) seen through the 0.3-opacity pane, whose depth
    pass is a speckle of the pane's depth: its brightest pixel's sample hit the pane, and it spread
    as a near-field blob of 2.7x (final) / 3.7x (draft) Cycles' saturated disc area before the
    despeckle's light-behind-a-pane rule (docs/fidelity.md, "Transparent: stochastic depth");
    1.12 / 1.46 measured after; draft 1.08 since its excess leaves the working image despite the
    pane's few depth samples around it (dof.NARROW_FRONT_MAX, dof.small_layer)."""
    entry, frame = _scene("transparent")
    lamp = next(x for x in entry["lamps"] if x["name"] == "lamp01")
    for quality, measured in (("final", 1.12), ("draft", 1.08)):
        m, = _lamps(entry, frame, quality, lamps=[lamp])
        assert m["area_ratio"] <= measured + 0.1, (quality, m["area_ratio"])


MEASURED_EMITTERS = {"area_ratio_max": 2.13, "halo_px_sum": 129 + 108 + 146 + 35, "energy_min": 0.857}


# The DoF targets on the scenes stored as two layers as well (tools/cycles_truth/make.py
# --layers): the foreground rendered as its own layer, processed with the front_layer stage
# (docs/fidelity.md, "Two layers: the foreground rendered as its own layer"). Measured (PSNR / FLIP,
# draft and final): occluder 52.65 / 0.00675, 54.39 / 0.00618; thin 42.36 / 0.01555, 42.22 / 0.01631;
# transparent 49.14 / 0.00841, 49.02 / 0.00844.
LAYERED = sorted(n for n, e in MANIFEST["scenes"].items() if "layers" in e)


def test_layered_scenes_are_stored():
    assert {"occluder", "thin", "transparent"} <= set(LAYERED)


@pytest.mark.parametrize("scene", LAYERED)
@pytest.mark.parametrize("quality", ["draft", "final"])
def test_two_layers_meet_the_targets(scene, quality):
    assert_two_layers_meet_the_targets(DATA, MANIFEST["scenes"][scene], scene, quality)

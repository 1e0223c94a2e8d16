"""clpost on HELD-OUT Cycles scenes (tests/data/cycles_heldout, docs/fidelity.md "Held-out scenes"):
the suite's failure classes with other geometry, colours, textures, depths and lenses, never used to
tune clpost. The data checks are quick; the scores are slow-marked regression floors (today's
measured levels minus a margin, tools/cycles_compare.py --data tests/data/cycles_heldout), NOT
the issue's targets — several of which these scenes show unmet (docs/fidelity.md)."""
import json
from pathlib import Path

import pytest

from clpost import fidelity as fd
from clpost.exr import read_frame

from conftest import assert_two_layers_meet_the_targets

DATA = Path(__file__).parent / "data" / "cycles_heldout"
MANIFEST = json.loads((DATA / "manifest.json").read_text())
MARGIN_DB = 0.5

# (scene, truth, quality) -> PSNR sRGB dB vs Cycles, measured (docs/fidelity.md, "Held-out scenes")
MEASURED_PSNR = {
    # 39.06 before the in-focus lights left the working image; 39.94 / 41.34 / 42.55 before the
    # depth-aware tile plan, the light's tail and the narrow layer's 1/4-px coverage ramp
    ("h_lamps", "dof", "draft"): 41.22,
    ("h_lamps", "dof", "preview"): 42.66,
    ("h_lamps", "dof", "final"): 44.63,      # 42.86 before the lights' 1/4-px ramp (dof.LIGHT_RAMP_PX)
    ("h_panes", "dof", "draft"): 32.96,      # 32.88 (FLIP 0.0342) before the depth-aware tile plan and the 1/4-px ramp
    ("h_panes", "dof", "preview"): 33.02,
    ("h_panes", "dof", "final"): 33.17,      # 33.10 before the lights' 1/4-px ramp
    ("h_fence", "dof", "draft"): 36.51,
    ("h_fence", "dof", "final"): 38.76,
    ("h_spin", "dof", "draft"): 49.96,
    ("h_spin", "dof", "final"): 49.65,       # was 44.89: final over-blurred the wall's 0.9 px CoC radius
    ("h_spin", "motion", "draft"): 47.07,      # 46.35 before draft's 19-tap cap (it takes 15 here, as final)
    ("h_spin", "motion", "final"): 47.07,
    ("h_spin", "dofmotion", "final"): 45.60,
}


_channels = fd.read_rgb


def _run(entry, frame, kind, quality):
    return fd.cycles_pipeline(entry, kind, quality).run(frame).color[..., :3]


def _lamps(entry, frame, quality, lamps=None):
    """Each lamp's emitter metrics (clpost.fidelity.emitter_metrics) for clpost's DoF at ``quality``."""
    return fd.lamp_metrics(lambda f: _run(entry, f, "dof", quality), DATA, entry, frame, 0.6, lamps=lamps)


def test_heldout_truths_are_sound():
    """Guards the data: Blender's layout, floors ≥ 36 dB, each truth far from its pinhole, and the
    held-out scenes really differ from the suite's cameras."""
    suite = json.loads((DATA.parent / "cycles" / "manifest.json").read_text())["scenes"]
    cams = {(e["shot"]["focal_mm"], e["shot"]["f_number"], e["shot"]["focus_m"], e["shot"]["blades"])
            for e in suite.values()}
    assert len(MANIFEST["scenes"]) >= 3
    for name, entry in MANIFEST["scenes"].items():
        frame = read_frame(DATA / entry["pinhole"]["file"])
        w, h = entry["size"]
        assert frame.metadata["layout"] == "blender" and frame.color.shape[:2] == (h, w), name
        s = entry["shot"]
        assert (s["focal_mm"], s["f_number"], s["focus_m"], s["blades"]) not in cams, name
        for kind, t in entry["truths"].items():
            truth = _channels(DATA / t["file"], "")
            assert t["noise_floor_psnr_srgb_db"] >= 36.0, (name, kind)
            assert fd.psnr_srgb(truth, frame.color) < t["noise_floor_psnr_srgb_db"] - 3.0, (name, kind)


@pytest.mark.slow
@pytest.mark.parametrize("scene,kind,quality", sorted(k for k in MEASURED_PSNR if k[0] in MANIFEST["scenes"]))
def test_heldout_psnr_floor_vs_cycles(scene, kind, quality):
    entry = MANIFEST["scenes"][scene]
    frame = read_frame(DATA / entry["pinhole"]["file"])
    truth = _channels(DATA / entry["truths"][kind]["file"], "")
    psnr = fd.psnr_srgb(truth, _run(entry, frame, kind, quality))
    assert psnr >= MEASURED_PSNR[scene, kind, quality] - MARGIN_DB, f"{scene} {kind} {quality}: {psnr:.2f} dB"


@pytest.mark.slow
def test_heldout_emitters_do_not_get_worse():
    """h_lamps at final: the nine defocused lamps' discs were 0.98–1.11× Cycles' area, 0.92–1.02× since
    the lights' ¼-px ramp (dof.LIGHT_RAMP_PX: issue 16's 1 ± 0.1 held), and the in-focus 1-px lamp on
    the wall had a 25-pixel halo (Cycles: 0) — two pixels from the lamp's depth sample, beyond the
    fringe rule's 3×3 reach — until the light's tail clause (none since) (docs/fidelity.md,
    "Held-out scenes", for these numbers' history).

    Energy: each lamp's against what the input holds of it — the pinhole's Emission pass over the
    same window, as a share of the truth's (the identity's emitter metrics): no post-process can
    restore light its input lacks (lamp10's pinhole holds 0.939 of Cycles' light in any window).
    The floor was 0.943 of the truth's (an earlier run's 0.973 − 0.03), which lamp10 met only by
    adding 2.8 % to its input's (0.965: a small-CoC light's 1-px-ramp lattice sum in front of the
    wall, docs/fidelity.md "Final's small lights"); with the lights' ¼-px ramp (dof.LIGHT_RAMP_PX)
    every lamp keeps 0.999–1.001 of its input's, held here to 1 %."""
    entry = MANIFEST["scenes"]["h_lamps"]
    frame = read_frame(DATA / entry["pinhole"]["file"])
    m = _lamps(entry, frame, "final")
    held = {x["name"]: x["energy_ratio"]
            for x in fd.lamp_metrics(lambda f: f.color[..., :3], DATA, entry, frame, 0.6)}
    areas = [x["area_ratio"] for x in m if x.get("area_ratio") is not None]
    kept = {x["name"]: x["energy_ratio"] / held[x["name"]] for x in m if x["energy_ratio"] is not None}
    halo = sum(x["halo_test"] for x in m if x["in_focus"])
    assert len(areas) == 9 and all(0.9 <= a <= 1.1 for a in areas), areas  # 0.92–1.02 (0.98–1.11 before the ¼-px ramp)
    assert halo == 0, halo
    assert len(kept) == 11 and all(abs(k - 1.0) <= 0.01 for k in kept.values()), kept


@pytest.mark.slow
def test_heldout_lamps_at_draft_and_preview_keep_their_energy():
    """h_lamps at draft and preview: the half-resolution path spread the defocused lamps' light
    beyond Cycles' discs (lamp10, 2 px at 4.5 m before the wall at 5.9 m, kept 0.65 of its energy
    at preview and 0.53 at draft; discs up to 1.8× Cycles' area) until the narrow-source layer
    (docs/fidelity.md, "The narrow-source layer") spread them at full resolution: measured
    0.949 (lamp10; final 0.973) … 1.016 and discs 1.00–1.46× (lamp10's 1.46 is final's too: its
    fringe keeps the wall's depth); with the layer's 1/4-px coverage ramp (dof.NARROW_RAMP_PX)
    0.92–1.01× (lamp10: 0.93; its energy, 0.939, is the pinhole input's own: its Emission pass holds
    0.939 of the truth's light). The in-focus lamps have no halo (Cycles: none): lamp00, 2 px
    in focus over the sky, had 68 px at draft until its light left the working image
    (docs/fidelity.md, "The narrow-source layer", in-focus lights)."""
    entry = MANIFEST["scenes"]["h_lamps"]
    frame = read_frame(DATA / entry["pinhole"]["file"])
    for quality in ("draft", "preview"):
        m = _lamps(entry, frame, quality)
        defocused = {x["name"]: (x["area_ratio"], x["energy_ratio"]) for x in m if not x["in_focus"]}
        assert len(defocused) == 9
        assert all(0.90 <= a <= 1.10 for a, _ in defocused.values()), (quality, defocused)
        assert all(e >= 0.949 - 0.03 for _, e in defocused.values()), (quality, defocused)
        halos = {x["name"]: x["halo_test"] for x in m if x["in_focus"]}
        assert len(halos) == 2 and sum(halos.values()) == 0, (quality, halos)


# Two layers (docs/fidelity.md, "Two layers: the foreground rendered as its own layer"), held
# out: never used to build the front_layer stage. Measured (PSNR / FLIP, draft and final): h_fence
# 48.53 / 0.01187, 48.76 / 0.00912; h_panes 40.52 / 0.01682, 41.21 / 0.01123.
LAYERED = sorted(n for n, e in MANIFEST["scenes"].items() if "layers" in e)


def test_layered_heldout_scenes_are_stored():
    assert {"h_fence", "h_panes"} <= set(LAYERED)


@pytest.mark.parametrize("scene", LAYERED)
@pytest.mark.parametrize("quality", ["draft", "final"])
def test_two_layers_meet_the_targets_held_out(scene, quality):
    assert_two_layers_meet_the_targets(DATA, MANIFEST["scenes"][scene], scene, quality)

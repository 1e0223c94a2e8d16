import numpy as np
import pytest

# Keep hypothesis quick and deterministic on the 2-core CI machine.
from hypothesis import settings

settings.register_profile("ci", max_examples=25, deadline=None, derandomize=True)
settings.load_profile("ci")


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def odd_frame(rng, w=37, h=23, scale=10.0, depth=True):
    """A small odd-sized HDR frame (odd sizes catch x/y and stride mix-ups)."""
    from clpost import Frame

    color = (rng.random((h, w, 3)) * scale).astype(np.float32)
    d = rng.uniform(0.2, 50.0, (h, w)).astype(np.float32) if depth else None
    return Frame(color, depth=d)


def assert_planned(pipe, frame, *stages):
    """Assert that each of ``stages`` runs in ``pipe``'s plan for ``frame``.

    Call it before comparing a kernel with its reference: a stage that is not planned is the
    identity on both sides, so a regressed skip rule would otherwise pass every comparison.
    The message lists the plan's reasons (as ``--explain`` prints them)."""
    planned = [getattr(s, "name", s) for s in pipe.plan(frame)]
    missing = [s for s in stages if s not in planned]
    if missing:
        why = "\n".join(str(e) for e in pipe.explain(frame))
        raise AssertionError(f"stage(s) {missing} not planned for this camera and frame, so the "
                             f"kernel-vs-reference comparison would compare two identities:\n{why}")
    return planned


def assert_stage_runs(stage, camera, frame):
    """``assert_planned`` for a stage object whose ``reference`` a test calls directly."""
    why = stage.skip_reason(camera, frame)
    assert why is None, f"stage '{stage.name}' is skipped ({why}): the comparison would be vacuous"


def assert_two_layers_meet_the_targets(data, entry: dict, scene: str, quality: str) -> None:
    """A Cycles scene stored as two layers (docs/fidelity.md, "Two layers"): the layers are the
    one-layer export split; clpost on them beats clpost on the one-layer export (itself above
    Blender's Defocus) at every quality, and final meets the issue's targets (within 4 dB of the
    noise floor, FLIP ≤ 0.03)."""
    from clpost import fidelity as fd
    from clpost.exr import read_frame

    frame = read_frame(data / entry["pinhole"]["file"])
    truth = fd.read_rgb(data / entry["truths"]["dof"]["file"], "")
    layered = fd.cycles_layers(data, entry)
    f = layered.front
    assert fd.psnr_srgb(frame.color, f[..., :3] + (1 - f[..., 3:4]) * layered.color) > 50
    two = fd.cycles_pipeline(entry, "dof", quality, front=True).run(layered).color
    one = fd.cycles_pipeline(entry, "dof", quality).run(frame).color
    psnr, flip = fd.psnr_srgb(truth, two), fd.flip_ldr(truth, two)
    floor = entry["truths"]["dof"]["noise_floor_psnr_srgb_db"]
    assert psnr > fd.psnr_srgb(truth, one), f"{scene} {quality}: {psnr:.2f} dB"
    assert quality != "final" or psnr >= floor - 4, f"{scene} final: {psnr:.2f} dB, floor {floor}"
    if flip is not None:
        assert flip < fd.flip_ldr(truth, one) and (quality != "final" or flip <= 0.03), f"{scene} {quality}: {flip:.5f}"

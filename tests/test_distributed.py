"""Sequences on a Dask LocalCluster: same results as serial, worker death, failing frames."""
import os
import signal

import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline, exr
from clpost.batch import FrameJob, process_sequence
from clpost.cli import main
from clpost.distributed import PipelineSpec, connect, disconnect, process_sequence_dask

pytestmark = pytest.mark.slow  # Dask clusters: integration runs

CAM = Camera(f_number=2.8, shutter_s=1 / 60, iso=200, luminance_scale=50.0)
N = 12


@pytest.fixture(scope="module")
def client():
    c = connect(workers=2)
    yield c
    disconnect(c)


def make_sequence(folder, n=N, w=160, h=120):
    rng = np.random.default_rng(7)
    for i in range(1, n + 1):
        f = Frame((rng.random((h, w, 3)) * 3).astype(np.float32),
                  depth=rng.uniform(0.5, 50, (h, w)).astype(np.float32))
        exr.write_frame(folder / f"in.{i:04d}.exr", f, layout="blender")
    return [FrameJob(i, folder / f"in.{i:04d}.exr", folder / "out" / f"o.{i:04d}.exr") for i in range(1, n + 1)]


def visible_outputs(folder):
    return sorted(p.name for p in (folder / "out").iterdir() if not p.name.startswith("."))


def test_local_cluster_matches_serial(tmp_path, client):
    jobs = make_sequence(tmp_path)
    rep = process_sequence_dask(client, PipelineSpec(CAM), jobs)
    assert rep.done == list(range(1, N + 1)) and not rep.failed
    serial = [FrameJob(j.frame, j.src, tmp_path / "serial" / j.dst.name) for j in jobs]
    process_sequence(Pipeline(CAM), serial)
    for j, s in zip(jobs, serial):
        np.testing.assert_array_equal(exr.read_frame(j.dst).color, exr.read_frame(s.dst).color)
    # resume: a second run skips everything
    again = process_sequence_dask(client, PipelineSpec(CAM), jobs)
    assert sorted(again.skipped) == list(range(1, N + 1)) and not again.done


def test_killing_a_worker_mid_sequence_still_completes_every_frame(tmp_path, client):
    jobs = make_sequence(tmp_path)
    pids = client.run(os.getpid)
    victim = sorted(pids.values())[0]
    killed = []

    def kill_once(n_done):
        if n_done == 2 and not killed:
            os.kill(victim, signal.SIGKILL)
            killed.append(victim)

    rep = process_sequence_dask(client, PipelineSpec(CAM), jobs, on_result=kill_once)
    assert killed, "the worker was never killed: the test did not test anything"
    assert not rep.failed, rep.failed
    assert sorted(rep.done + rep.skipped) == list(range(1, N + 1)), (rep.done, rep.skipped)
    assert visible_outputs(tmp_path) == [f"o.{i:04d}.exr" for i in range(1, N + 1)]
    ref = Pipeline(CAM)
    for j in jobs:  # every output is complete and correct (a truncated EXR would not read)
        np.testing.assert_array_equal(exr.read_frame(j.dst).color, ref.run(exr.read_frame(j.src)).color)


def test_a_failing_frame_is_named_and_the_others_finish(tmp_path, capsys):
    make_sequence(tmp_path, n=5)
    (tmp_path / "in.0003.exr").write_bytes(b"corrupt")
    code = main(["process", str(tmp_path / "in.####.exr"), "-o", str(tmp_path / "out" / "o.####.exr"),
                 "--workers", "2", "--retries", "1", "--quiet",
                 "--f-number", "2.8", "--shutter", "1/60", "--iso", "200", "--luminance-scale", "50"])
    err = capsys.readouterr().err
    assert code == 2  # a bad input frame is the user's error: exit 2, as in a serial run
    assert "frame 3 failed" in err and "in.0003.exr" in err and "1 of 5 frame(s) failed" in err
    assert visible_outputs(tmp_path) == ["o.0001.exr", "o.0002.exr", "o.0004.exr", "o.0005.exr"]


def test_long_exposure_tree_reduction_equals_serial(tmp_path, client):
    from clpost.distributed import expose_dask
    from clpost.expose import expose
    from clpost.sequence import expand

    make_sequence(tmp_path, n=11, w=40, h=30)
    pattern = str(tmp_path / "in.####.exr")
    frames = list(range(1, 12))
    t0, t1 = "0.07", "0.43"  # 24 fps: starts inside frame 1, ends inside frame 10
    serial = expose(lambda n: exr.read_frame(expand(pattern, n)), frames, 24, t0, t1)
    tree = expose_dask(client, pattern, frames, 24, t0, t1, chunk=3)
    assert tree.seconds == serial.seconds and tree.applied == serial.applied and tree.count == serial.count
    np.testing.assert_allclose(tree.mean(), serial.mean(), rtol=1e-6, atol=1e-7)


def test_animated_camera_on_workers_matches_serial(tmp_path, client):
    """A focus pull from the inputs' OpenEXR focus attributes plus a track: each worker resolves
    its frame's camera as the serial loop does."""
    import json

    from clpost.camera_sources import CameraSources
    from clpost.camera_track import load_track

    rng = np.random.default_rng(5)
    f = Frame((rng.random((40, 64, 3)) + 0.1).astype(np.float32),
              depth=rng.uniform(0.8, 6, (40, 64)).astype(np.float32))
    jobs = []
    for i, u in enumerate((1.0, 2.0, 3.0, 4.0), 1):
        exr.write_frame(tmp_path / f"in.{i:04d}.exr", f, header={"focus": u})
        jobs.append(FrameJob(i, tmp_path / f"in.{i:04d}.exr", tmp_path / "out" / f"o.{i:04d}.exr"))
    (tmp_path / "t.json").write_text(json.dumps([{"frame": 1, "f-number": 1.4}, {"frame": 4, "f-number": 4.0}]))
    src = CameraSources(flags={"depth_of_field": True}, track=load_track(tmp_path / "t.json"))
    base = src.resolve(1, {"focus": 1.0}).camera
    rep = process_sequence_dask(client, PipelineSpec(base), jobs, sources=src)
    assert rep.done == [1, 2, 3, 4] and not rep.failed
    serial = [FrameJob(j.frame, j.src, tmp_path / "serial" / j.dst.name) for j in jobs]
    process_sequence(Pipeline(base), serial, sources=src)
    outs = []
    for j, s in zip(jobs, serial):
        a, b = exr.read_frame(j.dst), exr.read_frame(s.dst)
        np.testing.assert_array_equal(a.color, b.color)
        outs.append(a)
    assert [o.metadata["attributes"]["focus"] for o in outs] == [1.0, 2.0, 3.0, 4.0]
    assert [o.metadata["attributes"]["aperture"] for o in outs] == pytest.approx([1.4, 1.4 + 2.6 / 3, 1.4 + 5.2 / 3, 4.0], rel=1e-6)  # linear
    assert not np.array_equal(outs[0].color, outs[1].color)  # the camera did change per frame

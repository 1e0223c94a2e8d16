"""process_sequence overlaps read / run / write across frames: same outputs as one frame at a
time, in order, and an error in frame k leaves frames < k complete and nothing after it."""
import numpy as np
import pytest

from clpost import Camera, Frame, Pipeline, exr
from clpost.batch import FrameJob, process_one, process_sequence
from clpost.errors import InputError

CAM = Camera(luminance_scale=1.0, vignetting="natural")


def _inputs(tmp_path, n, bad=None):
    jobs = []
    rng = np.random.default_rng(3)
    for k in range(n):
        w, h = (40, 24) if k != bad else (41, 24)
        src = tmp_path / f"in.{k:04d}.exr"
        exr.write_frame(src, Frame(rng.uniform(0, 2, (h, w, 3)).astype(np.float32),
                                   depth=np.full((h, w), 3.0, np.float32)))
        jobs.append(FrameJob(k, src, tmp_path / "out" / f"out.{k:04d}.exr"))
    (tmp_path / "out").mkdir()
    return jobs


def test_overlapped_sequence_equals_frame_by_frame(tmp_path):
    jobs = _inputs(tmp_path, 5)
    seen = []
    rep = process_sequence(Pipeline(CAM), jobs, progress=lambda j, s: seen.append(j.frame))
    assert rep.done == seen == [0, 1, 2, 3, 4] and len(rep.seconds) == 5
    for job in jobs:
        one = process_one(Pipeline(CAM), FrameJob(job.frame, job.src, tmp_path / "one.exr"))
        np.testing.assert_array_equal(exr.read_frame(job.dst).color, one.color)


def test_error_in_a_frame_leaves_earlier_outputs_complete_and_later_unwritten(tmp_path):
    jobs = _inputs(tmp_path, 5, bad=2)
    with pytest.raises(InputError, match="in.0002.exr"):
        process_sequence(Pipeline(CAM), jobs)
    assert [j.dst.is_file() for j in jobs] == [True, True, False, False, False]
    for j in jobs[:2]:
        assert exr.read_frame(j.dst).color.shape == (24, 40, 3)
    assert not [p for p in (tmp_path / "out").iterdir() if p.name not in ("out.0000.exr", "out.0001.exr")]


def test_a_termination_is_reported_even_when_the_write_in_flight_fails(tmp_path, monkeypatch):
    """SIGTERM removes the temporary file the writer thread is filling (clpost.atomic), so that
    write fails; the sequence must end with the termination (exit 143), not the write's error."""
    import threading

    import clpost.batch as batch
    from clpost.atomic import Terminated
    from clpost.errors import OutputError

    jobs = _inputs(tmp_path, 4)
    writing = threading.Event()
    real_run = batch.run_job

    def store(job, *a, **k):
        writing.set()
        raise OutputError(f"{job.dst}: cannot replace it (No such file or directory)")

    def run(pipeline, job, *a, **k):
        if job.frame == 1:  # frame 0's write is in flight: the signal arrives now
            writing.wait(10)
            raise Terminated("signal 15")
        return real_run(pipeline, job, *a, **k)

    monkeypatch.setattr(batch, "store_job", store)
    monkeypatch.setattr(batch, "run_job", run)
    with pytest.raises(Terminated):
        process_sequence(Pipeline(CAM), jobs)

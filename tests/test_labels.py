"""labels: label planes through the geometry (nearest, never blended), COCO keypoints/boxes by the
exact forward model, and the effective camera in OpenCV / Kalibr / COLMAP form."""
import json
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from clpost import Camera, Frame, InputError, Pipeline, exr
from clpost.calibration import OpenCVModel, load_calibration
from clpost.cli import main
from clpost.labels import auto_label, camera_texts, effective_camera, map_coco, select_labels
from clpost.labels.coco import Mapping, map_box, map_keypoints, map_points

from conftest import assert_planned

cv2 = pytest.importorskip("cv2")

W, H = 41, 29
MODELS = {  # barrel, pincushion, the full rational/tangential/thin-prism/tilt model, and fisheye
    "barrel": OpenCVModel(W, H, 30, 31, 20.3, 14.1, k1=-0.35, k2=0.12, p1=0.003),
    "pincushion": OpenCVModel(W, H, 33, 33, 19.6, 13.8, k1=0.25, k2=0.05, p2=-0.004),
    "full": OpenCVModel(W, H, 32, 31, 20.1, 14.2, k1=-0.2, k2=0.05, p1=0.002, p2=-0.001, k3=-0.01, k4=0.01,
                        k5=0.002, s1=0.001, s3=0.0007, tau_x=0.01, tau_y=-0.02),
    "fisheye": OpenCVModel(W, H, 18, 18, 20.0, 14.0, k1=0.05, k2=-0.01, k3=0.002, distortion_model="fisheye"),
}


def _ids(rng, h, w, n=7, block=3):
    """A held-out random instance-id map: blocks of ids drawn from a large range (hash-like uint32)."""
    pool = rng.integers(1, 2**32 - 1, n, dtype=np.uint64).astype(np.uint32)
    small = rng.integers(0, n, (-(-h // block), -(-w // block)))
    return pool[np.kron(small, np.ones((block, block), int))[:h, :w]]


def _frame(rng, model, **extra):
    spec = required_render(model)
    w, h = spec.width, spec.height
    k = spec.intrinsics()
    labels = {"id": _ids(rng, h, w), "seg": rng.integers(0, 5, (h, w)).astype(np.int32),
              "N.X": rng.normal(size=(h, w)).astype(np.float32)}
    return Frame(rng.random((h, w, 3)).astype(np.float32), depth=rng.uniform(1, 9, (h, w)), labels=labels,
                 metadata={"intrinsics": k}, **extra)


def required_render(model):
    from clpost.calibration import required_render as rr

    return rr(model)


def _neighbourhood_ok(src, out, pos, ok):
    """Every valid output value is one of the 2×2 source pixels around its source position."""
    h, w = src.shape
    x0 = np.clip(np.floor(pos[0]).astype(int), 0, w - 1)
    y0 = np.clip(np.floor(pos[1]).astype(int), 0, h - 1)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    cand = np.stack([src[y0, x0], src[y0, x1], src[y1, x0], src[y1, x1]])
    return bool(np.all((cand == out[None]).any(axis=0) | ~ok))


@pytest.mark.parametrize("name", list(MODELS))
@pytest.mark.parametrize("quality", ["preview", "final"])
def test_ids_never_take_a_value_absent_from_their_source_neighbourhood(rng, name, quality):
    from clpost.stages.distortion import distortion_map

    model = MODELS[name]
    frame = _frame(rng, model)
    cam = Camera(distortion=model)
    pipe = Pipeline(cam, quality=quality, stages=["distortion"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert_planned(pipe, frame, "distortion")
        out = pipe.run(frame)
        ref = pipe.plan_for(frame, pipe.camera_for(frame)).stages[0].host_buffers(pipe.camera_for(frame), frame)
    pos, ok = distortion_map(model, frame.size, tuple(frame.metadata["intrinsics"]))
    assert out.labels.keys() == frame.labels.keys()
    for k, src in frame.labels.items():
        o = out.labels[k]
        assert o.dtype == src.dtype and o.shape == (model.height, model.width)
        assert np.array_equal(o.view(np.uint32), ref["labels"][k].view(np.uint32)), k  # device == numpy, bit for bit
        assert _neighbourhood_ok(src, o, pos, ok), k
        assert np.all(o[~ok] == 0)
    # a blend of two ids would be a new value; here every output id is one of the input's
    assert set(np.unique(out.labels["id"][ok])) <= set(np.unique(frame.labels["id"]))
    # the label follows the same pixel as depth: nearest source pixel, one for all planes
    xi = np.clip(np.rint(pos[0]), 0, frame.width - 1).astype(int)
    yi = np.clip(np.rint(pos[1]), 0, frame.height - 1).astype(int)
    assert np.array_equal(out.labels["id"][ok], frame.labels["id"][yi, xi][ok])
    assert np.array_equal(out.depth[ok], frame.depth[yi, xi][ok])


def test_labels_with_input_alpha_take_the_host_path_and_agree(rng):
    model = MODELS["barrel"]
    frame = _frame(rng, model)
    a = rng.uniform(0.2, 1.0, (frame.height, frame.width)).astype(np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dev = Pipeline(Camera(distortion=model), stages=["distortion"]).run(frame)
        host = Pipeline(Camera(distortion=model), stages=["distortion"]).run(frame.replace(alpha=a))
    for k in frame.labels:
        assert np.array_equal(dev.labels[k].view(np.uint32), host.labels[k].view(np.uint32))


def test_a_second_frame_carries_its_own_labels(rng):
    """Labels are uploaded from each frame (the distortion stage is not replayed with labels)."""
    model = MODELS["pincushion"]
    f1, f2 = _frame(rng, model), _frame(rng, model)
    pipe = Pipeline(Camera(distortion=model), stages=["distortion"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        o1, o2 = pipe.run(f1), pipe.run(f2)
        r2 = pipe.plan_for(f2, pipe.camera_for(f2)).stages[0].host_buffers(pipe.camera_for(f2), f2)
    assert np.array_equal(o2.labels["id"], r2["labels"]["id"]) and not np.array_equal(o1.labels["id"], o2.labels["id"])


def test_labels_pass_unchanged_through_non_geometric_stages_and_follow_breathing(rng):
    frame = Frame(rng.random((23, 37, 3)).astype(np.float32), depth=np.full((23, 37), 2.0),
                  labels={"id": _ids(rng, 23, 37)})
    pipe = Pipeline(Camera(vignetting="natural"), stages=["vignetting"])
    assert_planned(pipe, frame, "vignetting")
    out = pipe.run(frame)
    assert np.array_equal(out.labels["id"], frame.labels["id"]) and not np.array_equal(out.color, frame.color)
    from clpost.breathing import rescale_plate, source_positions

    cam = Camera(lens="thin:50", focus_distance_m=0.6, plate_fov="infinity")
    re = rescale_plate(frame, cam)
    assert re is not frame
    from clpost.breathing import magnification

    xp, yp = source_positions(frame.size, magnification(cam), (18.0, 11.0))
    inside = (xp >= -0.5) & (xp <= 36.5) & (yp >= -0.5) & (yp <= 22.5)
    assert _neighbourhood_ok(frame.labels["id"], re.labels["id"], (xp, yp), inside)
    assert np.all(re.labels["id"][~inside] == 0)


def test_frame_label_validation_names_the_plane_and_keeps_types(rng):
    f = Frame(np.zeros((4, 5, 3), np.float32), labels={"a": np.arange(20, dtype=np.uint8).reshape(4, 5),
                                                       "b": np.zeros((4, 5), np.float16),
                                                       "c": -np.ones((4, 5), np.int64), "d": np.ones((4, 5), bool)})
    assert [f.labels[k].dtype for k in "abcd"] == [np.uint32, np.float32, np.int32, np.uint32]
    with pytest.raises(InputError, match=r"labels\['x'\]: shape \(4, 4\)"):
        Frame(np.zeros((4, 5, 3), np.float32), labels={"x": np.zeros((4, 4))})
    with pytest.raises(InputError, match=r"labels\['x'\].*NaN"):
        Frame(np.zeros((4, 5, 3), np.float32), labels={"x": np.full((4, 5), np.nan)})
    with pytest.raises(InputError, match="renumber"):
        Frame(np.zeros((4, 5, 3), np.float32), labels={"x": np.full((4, 5), 2**40)})


def test_channel_selection():
    names = ["ViewLayer.IndexOB.X", "ViewLayer.Normal.X", "ViewLayer.Normal.Y", "id", "CryptoObject00.R", "foo"]
    assert [n for n in names if auto_label(n)] == ["ViewLayer.IndexOB.X", "id", "CryptoObject00.R"]
    assert select_labels("auto", names) == ["ViewLayer.IndexOB.X", "id", "CryptoObject00.R"]
    assert select_labels("Normal,foo", names) == ["ViewLayer.Normal.X", "ViewLayer.Normal.Y", "foo"]
    assert select_labels("all", names) == names and select_labels("none", names) == []
    with pytest.raises(InputError, match="--labels Norm takes no channel; .*ViewLayer.Normal.X"):
        select_labels("Norm", names, "in.exr")
    with pytest.raises(InputError, match="Camera.labels"):
        Camera(labels="auto,,x")
    assert Camera(labels=" IndexOB , Normal").labels == "IndexOB,Normal"


def _write_labelled_exr(path, rng, w, h, k=None):
    import OpenEXR

    ch = {c: rng.random((h, w)).astype(np.float32) for c in "RGB"}
    ch["Z"] = rng.uniform(1, 5, (h, w)).astype(np.float32)
    ch["id"] = _ids(rng, h, w)  # UINT
    ch["object.index"] = rng.integers(0, 9, (h, w)).astype(np.float32)
    ch["N.X"], ch["N.Y"], ch["N.Z"] = (rng.normal(size=(h, w)).astype(np.float32) for _ in range(3))
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, dict(ch)).write(str(path))
    return ch


def test_exr_label_channels_are_read_carried_and_written_exactly(rng, tmp_path):
    model = MODELS["barrel"]
    spec = required_render(model)
    ch = _write_labelled_exr(tmp_path / "in.exr", rng, spec.width, spec.height)
    f = exr.read_frame(tmp_path / "in.exr")
    assert sorted(f.labels) == ["id"] and f.labels["id"].dtype == np.uint32  # auto: the id channel
    assert np.array_equal(f.labels["id"], ch["id"])
    f = exr.read_frame(tmp_path / "in.exr", labels="id,N,index")
    assert sorted(f.labels) == ["N.X", "N.Y", "N.Z", "id", "object.index"]
    assert sorted(exr.read_frame(tmp_path / "in.exr", labels="all").labels) == sorted(f.labels)
    with pytest.raises(InputError, match="in.exr: --labels nope takes no channel"):
        exr.read_frame(tmp_path / "in.exr", labels="nope")
    cal = tmp_path / "cam.yaml"
    from clpost.calibration import write_calibration

    write_calibration(model, cal)
    rc = main(["process", str(tmp_path / "in.exr"), "-o", str(tmp_path / "out.exr"), "--calibration", str(cal),
               "--stages", "distortion", "--labels", "id,N", "--camera-files", "--quiet"])
    assert rc == 0
    out = exr.read_frame(tmp_path / "out.exr", labels="all")
    assert sorted(out.labels) == ["N.X", "N.Y", "N.Z", "id"] and out.labels["id"].dtype == np.uint32
    lib = Pipeline(Camera(distortion=model, labels="id,N"), stages=["distortion"]).run(
        exr.read_frame(tmp_path / "in.exr", labels="id,N"))
    for k in out.labels:
        assert np.array_equal(out.labels[k], lib.labels[k])
    # a normal's three components come from one source pixel: they are a source normal
    nrm = np.stack([out.labels[f"N.{c}"] for c in "XYZ"], -1)[out.alpha > 0]
    src = {tuple(v) for v in np.stack([ch[f"N.{c}"] for c in "XYZ"], -1).reshape(-1, 3)}
    assert all(tuple(v) in src for v in nrm)
    # the effective camera: in the header and beside the output, loadable by OpenCV
    _, strings = exr.read_attributes(tmp_path / "out.exr")
    assert {"clpost.camera.opencv", "clpost.camera.kalibr", "clpost.camera.colmap"} <= strings.keys()
    fs = cv2.FileStorage(str(tmp_path / "out.camera.yaml"), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("camera_matrix").mat(), model.matrix(), rtol=0, atol=1e-12)
    d = fs.getNode("distortion_coefficients").mat().ravel()
    np.testing.assert_allclose(d, model.vector()[:d.size], rtol=0, atol=1e-15)
    for name in ("out.kalibr.yaml", "out.cameras.txt", "out.camera.yaml"):
        back = load_calibration(str(tmp_path / name))
        assert (back.fx, back.fy, back.cx, back.cy, back.k1, back.k2, back.p1) == pytest.approx(
            (model.fx, model.fy, model.cx, model.cy, model.k1, model.k2, model.p1), abs=1e-12)
    assert (tmp_path / "out.camera.yaml").read_text() == strings["clpost.camera.opencv"]


def test_effective_camera_without_distortion_and_under_fill_crop(rng):
    frame = Frame(np.zeros((20, 30, 3), np.float32))
    cam = Camera()
    m = effective_camera(cam, frame, ())
    assert (m.width, m.height) == (30, 20) and (m.fx, m.fy, m.cx, m.cy) == pytest.approx(cam.intrinsics(30, 20))
    assert "PINHOLE" in camera_texts(m)["colmap"]
    model = MODELS["barrel"]
    small = Frame(np.zeros((H, W, 3), np.float32))
    crop = effective_camera(Camera(distortion=model, fill="crop"), small, ("distortion",))
    from clpost.stages.distortion import crop_scale

    s = crop_scale(model, (W, H), (model.fx, model.fy, model.cx, model.cy))
    assert s > 1 and crop.fx == pytest.approx(model.fx * s) and crop.cx == model.cx and crop.k1 == model.k1
    full = MODELS["full"]  # Kalibr radtan cannot hold k3.. and thin prism: left out, never approximated
    assert set(camera_texts(full)) == {"opencv-yaml"}


# -- COCO ------------------------------------------------------------------------------------

def _identity_mapping(model):
    return Mapping(model, (model.fx, model.fy, model.cx, model.cy))


@pytest.mark.parametrize("name", ["barrel", "pincushion", "full"])
def test_points_map_as_cv2_project_points(rng, name):
    model = MODELS[name]
    mp = _identity_mapping(model)
    s = rng.uniform([0, 0], [W - 1, H - 1], (400, 2))
    u, v, _ = map_points(mp, s[:, 0], s[:, 1])
    obj = np.c_[(s[:, 0] - model.cx) / model.fx, (s[:, 1] - model.cy) / model.fy, np.ones(len(s))]
    ref, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), model.matrix(), model.vector())
    assert np.abs(ref[:, 0, 0] - u).max() < 1e-9 and np.abs(ref[:, 0, 1] - v).max() < 1e-9


def test_points_map_as_cv2_fisheye_distort_points(rng):
    model = MODELS["fisheye"]
    spec = required_render(model)
    mp = Mapping(model, spec.intrinsics())
    s = rng.uniform([0, 0], [spec.width - 1, spec.height - 1], (400, 2))
    u, v, vis = map_points(mp, s[:, 0], s[:, 1])
    fx, fy, cx, cy = spec.intrinsics()
    und = np.c_[(s[:, 0] - cx) / fx, (s[:, 1] - cy) / fy][:, None]
    ref = cv2.fisheye.distortPoints(und, model.matrix(), model.coefficients())
    assert np.abs(ref[:, 0, 0] - u).max() < 1e-9 and np.abs(ref[:, 0, 1] - v).max() < 1e-9
    inside = (u >= -0.5) & (u <= W - 0.5) & (v >= -0.5) & (v <= H - 0.5)
    assert np.array_equal(vis, inside)  # no fold for this model: visible = inside the image


def test_a_box_is_the_bound_of_its_mapped_region_not_of_its_corners():
    model = OpenCVModel(400, 300, 300, 300, 199.5, 149.5, k1=-0.4, k2=0.15)
    mp = _identity_mapping(model)
    box = [60.0, 40.0, 280.0, 60.0]  # a wide box above the centre: its top edge bows
    got = map_box(mp, box)
    xs, ys = np.meshgrid(np.linspace(box[0], box[0] + box[2], 801) - 0.5,
                         np.linspace(box[1], box[1] + box[3], 201) - 0.5)
    u, v, vis = map_points(mp, xs.ravel(), ys.ravel())
    dense = [u[vis].min() + 0.5, v[vis].min() + 0.5, u[vis].max() + 0.5, v[vis].max() + 0.5]
    assert got[0] == pytest.approx(dense[0], abs=1e-3) and got[1] == pytest.approx(dense[1], abs=1e-3)
    assert got[0] + got[2] == pytest.approx(dense[2], abs=1e-3) and got[1] + got[3] == pytest.approx(dense[3], abs=1e-3)
    cu, cv, _ = map_points(mp, np.array([box[0], box[0] + box[2]]) - 0.5, np.array([box[1], box[1]]) - 0.5)
    assert got[1] < min(cv) + 0.5 - 1.0  # barrel: the top edge's middle lies above its mapped corners


def test_keypoints_outside_become_v0_and_coco_maps_end_to_end(tmp_path):
    model = OpenCVModel(200, 150, 150, 150, 99.5, 74.5, k1=-0.3, k2=0.1)
    spec = required_render(model)
    coco = {"images": [{"id": 1, "width": spec.width, "height": spec.height, "file_name": "a.exr"}],
            "annotations": [
                {"id": 10, "image_id": 1, "bbox": [10, 10, 40, 30], "area": 1200, "category_id": 1,
                 "keypoints": [30, 25, 2, 0, 0, 0, 1, 1, 2], "num_keypoints": 2,
                 "segmentation": [[10, 10, 50, 10, 50, 40, 10, 40]]},
                {"id": 11, "image_id": 1, "bbox": [0, 0, 1, 1], "area": 1, "category_id": 1,
                 "segmentation": {"counts": "abc", "size": [1, 1]}}],
            "categories": [{"id": 1, "name": "thing"}]}
    out, rep = map_coco(coco, lambda w, h: Mapping(model, spec.intrinsics()))
    assert out["images"][0]["width"] == 200 and out["images"][0]["height"] == 150
    a = out["annotations"][0]
    kp = np.array(a["keypoints"]).reshape(-1, 3)
    mp = Mapping(model, spec.intrinsics())
    u, v, vis = map_points(mp, np.array([30.0, 1.0]), np.array([25.0, 1.0]))
    assert vis[0] and kp[0].tolist() == pytest.approx([u[0], v[0], 2])
    assert kp[1].tolist() == [0, 0, 0]  # was not labelled
    assert kp[2].tolist() == [0, 0, 0] and not vis[1]  # a render corner is outside the distorted image
    assert a["num_keypoints"] == 1 and rep.keypoints_hidden == 1
    assert len(a["segmentation"]) == 1 and a["area"] > 0
    assert coco["annotations"][0]["bbox"] == [10, 10, 40, 30]  # the input is not touched
    # the CLI: same result, atomic output, bad input one line exit 2
    src, dst, cal = tmp_path / "in.json", tmp_path / "out.json", tmp_path / "cam.yaml"
    src.write_text(json.dumps(coco))
    from clpost.calibration import write_calibration

    write_calibration(model, cal)
    assert main(["labels", "map", str(src), "-o", str(dst), "--calibration", str(cal), "--camera-files"]) == 0
    assert json.loads(dst.read_text()) == json.loads(json.dumps(out))
    assert load_calibration(str(tmp_path / "out.camera.yaml")) == replace(model, source="x")  # source: not compared
    assert main(["labels", "map", str(src), "-o", str(dst), "--calibration", str(cal)]) == 2  # exists
    bad = tmp_path / "bad.json"
    bad.write_text("{nope")
    assert main(["labels", "map", str(bad), "-o", str(tmp_path / "o2.json"), "--calibration", str(cal)]) == 2
    assert not (tmp_path / "o2.json").exists()
    other = tmp_path / "other.json"
    other.write_text(json.dumps({**coco, "images": [{"id": 1, "width": 77, "height": 55}]}))
    assert main(["labels", "map", str(other), "-o", str(tmp_path / "o3.json"), "--calibration", str(cal)]) == 2
    assert not (tmp_path / "o3.json").exists()


def test_labels_map_errors_are_one_line(tmp_path, capsys):
    cal = tmp_path / "cam.yaml"
    from clpost.calibration import write_calibration

    write_calibration(MODELS["barrel"], cal)
    (tmp_path / "x.json").write_text(json.dumps({"images": [{"id": 1, "width": W, "height": H}],
                                                 "annotations": [{"id": 3, "image_id": 9, "bbox": [0, 0, 1, 1]}]}))
    assert main(["labels", "map", str(tmp_path / "x.json"), "-o", str(tmp_path / "y.json"), "--calibration",
                 str(cal)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "annotation 3: its image_id is not in 'images'" in err


def test_labels_and_coco_follow_fill_crop_magnification(rng):
    """Under --fill crop the stage samples a magnified model; labels and COCO points follow the same one."""
    from clpost.labels.command import mapping_factory
    from clpost.stages.distortion import _scaled, crop_scale, distortion_map

    model = MODELS["barrel"]
    frame = Frame(rng.random((H, W, 3)).astype(np.float32), labels={"id": _ids(rng, H, W)})
    cam = Camera(distortion=model, fill="crop")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = Pipeline(cam, stages=["distortion"]).run(frame)
    k = (model.fx, model.fy, model.cx, model.cy)
    s = crop_scale(model, (W, H), k)
    assert s > 1
    pos, ok = distortion_map(_scaled(model, s), (W, H), k)
    assert ok.all() and _neighbourhood_ok(frame.labels["id"], out.labels["id"], pos, ok)
    mp = mapping_factory(model, "crop")(W, H)
    assert mp.model.fx == pytest.approx(model.fx * s)
    # a render point and the output pixel whose source it is agree: u(s(p)) = p
    j, i = 7, 11
    u, v, vis = map_points(mp, pos[0][j, i], pos[1][j, i])
    assert vis and u == pytest.approx(i, abs=1e-6) and v == pytest.approx(j, abs=1e-6)


def test_label_planes_are_written_exactly_whatever_their_type(rng, tmp_path):
    ids = rng.integers(0, 2**32, (5, 7), dtype=np.uint64).astype(np.uint32)
    neg = rng.integers(-1000, 1000, (5, 7)).astype(np.int32)
    pos = rng.integers(0, 2**31 - 1, (5, 7)).astype(np.int32)
    f = Frame(np.zeros((5, 7, 3), np.float32), labels={"id": ids, "neg.class": neg, "pos.class": pos,
                                                       "N.X": rng.normal(size=(5, 7))})
    exr.write_frame(tmp_path / "l.exr", f)
    g = exr.read_frame(tmp_path / "l.exr", labels="all")
    assert g.labels["id"].dtype == np.uint32 and np.array_equal(g.labels["id"], ids)
    assert np.array_equal(g.labels["neg.class"], neg.astype(np.float32))  # FLOAT: exact below 2^24
    assert g.labels["pos.class"].dtype == np.uint32 and np.array_equal(g.labels["pos.class"], pos)
    assert np.array_equal(g.labels["N.X"], f.labels["N.X"])
    assert exr.read_frame(tmp_path / "l.exr", labels="none").labels == {}
    big = Frame(np.zeros((1, 2, 3), np.float32), labels={"x": np.array([[-(1 << 25), 0]], np.int32)})
    with pytest.raises(InputError, match="renumber them as non-negative ids"):
        exr.write_frame(tmp_path / "b.exr", big)
    assert not (tmp_path / "b.exr").exists()

"""Parameters declared by their stage (clpost.params): every declaration reaches Camera, the CLI,
describe()/the EXR header and validation, and a new stage's declaration needs no other edit."""
import dataclasses
import inspect
import math
import pickle
from dataclasses import dataclass

import numpy as np
import pytest

import clpost.camera
import clpost.cli
import clpost.stages
from clpost import Camera, InputError
from clpost.calibration import OpenCVModel
from clpost.cli import build_parser, camera_from_args, main
from clpost.params import one_of, param, parse_fraction, positive
from clpost.stages import PointwiseStage, registry

SPECS = Camera.param_specs()
STORED = [s for s in SPECS if not s.meta.input_only]

# A valid non-default value for the parameters whose header entry is omitted at their default.
EXAMPLES = {
    "field_curvature_mm": 0.1, "astigmatism_mm": 0.1, "coma_mm": 0.05, "lateral_color_mm": 0.01,
    "vignetting": "natural", "plate_fov": "infinity", "fill": "crop",
    "luminance_scale": 100.0,  # None (passthrough) by default
    "distortion": OpenCVModel(width=640, height=480, fx=500.0, fy=500.0, cx=319.5, cy=239.5, k1=-0.1),
}
BAD = ("not-a-value", float("nan"), -1e9, object())


def _example(spec):
    """A valid non-default value: EXAMPLES, else the owning stage's declared ``example``."""
    if spec.name in EXAMPLES:
        return EXAMPLES[spec.name]
    from clpost.stages import registry

    for cls in registry().values():
        if spec.name in getattr(cls, "example", {}):
            return cls.example[spec.name]
    raise AssertionError(f"{spec.name}: give its stage an `example` with a non-default value")


def _print_help(monkeypatch, argv) -> None:
    monkeypatch.setenv("COLUMNS", "1000")  # one line per option: no wrapping inside the help text
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 0


def _option_blocks(help_text: str) -> list[str]:
    """Each option's help as one line (argparse puts a long invocation and its help on two)."""
    blocks: list[str] = []
    for line in help_text.splitlines():
        if line.startswith("  -"):
            blocks.append(line.strip())
        elif blocks and line.startswith("   "):
            blocks[-1] += " " + line.strip()
    return blocks


def test_declarations_are_complete_and_owned_by_registered_stages():
    owners = {"camera"} | {name for name, cls in registry().items() if cls.params is not None}
    assert {s.owner for s in SPECS} == owners
    assert SPECS[0].owner == "camera" and SPECS[0].name == "lens"
    stage_order = [s.owner for s in SPECS if s.owner != "camera"]
    assert stage_order == sorted(stage_order, key=lambda n: registry()[n].order)  # physical order
    for s in SPECS:
        assert s.meta.unit and s.meta.help, s.name
        assert isinstance(s.meta.scalar, bool), s.name
    # the camera core reads no stage internals (each stage's checks live with its declaration)
    src = inspect.getsource(clpost.camera)
    assert "SENSOR_PRESETS" not in src and "stages.sensor" not in src


def test_every_declared_field_is_a_camera_field_with_its_default():
    names = [f.name for f in dataclasses.fields(Camera)]
    assert names == [s.name for s in STORED]
    cam = Camera()
    for s in STORED:
        # iso: None means "the film's box speed, else 100" and validation sets it
        assert getattr(cam, s.name) == (100.0 if s.name == "iso" else s.default), s.name
        assert Camera(**{s.name: s.default}) == cam, s.name  # keyword construction


def test_every_flag_is_in_process_help_with_its_default(monkeypatch, capsys):
    _print_help(monkeypatch, ["process", "--help"])
    out = capsys.readouterr().out
    flagged = [s for s in SPECS if s.meta.flag]
    assert len(flagged) == len(SPECS)  # every camera parameter has a command-line option today
    for s in flagged:
        block = next((b for b in _option_blocks(out) if b.startswith(s.meta.flag + " ")), None)
        assert block is not None, s.meta.flag
        assert f"{s.meta.help} (default: {s.help_default()})" in block, block
    assert "(default: 1/50)" in out and "(default: thin:50)" in out and "(default: off)" in out


def test_demo_and_bench_help_show_the_demo_cameras_defaults(monkeypatch, capsys):
    from clpost.demo import DEMO_CAMERA_DEFAULTS

    for command in ("demo", "bench"):
        _print_help(monkeypatch, [command, "--help"])
        blocks = {b.split()[0]: b for b in _option_blocks(capsys.readouterr().out)}
        assert blocks["--lens"].endswith(f"(default: {DEMO_CAMERA_DEFAULTS['lens']})")
        assert blocks["--shutter"].endswith("(default: auto)") and DEMO_CAMERA_DEFAULTS["shutter_s"] is None
        assert blocks["--iso"].endswith("(default: 100)")  # not in the demo defaults: Camera's


def test_every_header_key_is_in_describe():
    for s in STORED:
        if s.meta.header is None:
            continue
        value = s.header_text(s.default)
        if value is None:
            cam = Camera(**{s.name: _example(s)})
            assert s.meta.header not in Camera().describe(), s.name  # unset / off: omitted
        else:
            cam = Camera()
        assert s.meta.header in cam.describe(), s.name
        # a value resolved from a default rule (iso: the film's box speed, else 100; marked
        # "<field>_default") is recorded as the rule, so a camera read back applies the rule again
        recorded = None if cam.__dict__.get(f"{s.name}_default") else getattr(cam, s.name)
        assert cam.describe()[s.meta.header] == s.header_text(recorded)


def test_describe_keeps_todays_keys_and_formatting():
    d = Camera(f_number=None, shutter_s=1 / 50, depth_of_field=True, blades=6, film="neutral-100").describe()
    assert d["clpost.fNumber"] == "auto" and d["clpost.shutter_s"] == "0.02"
    assert d["clpost.focalLength_mm"] == "50" and d["clpost.sensor_mm"] == "36x24"
    assert d["clpost.blades"] == "6" and d["clpost.depthOfField"] == "True"
    assert d["clpost.film"] == "neutral-100" and d["clpost.sensorPreset"] == "none"
    assert d["clpost.noiseSeed"] == "0" and d["clpost.workingSpace"] == "rec709"
    dist = Camera(distortion=EXAMPLES["distortion"]).describe()["clpost.distortion"]
    # named fields since issue 19 (the bare list "640 480 500 …" is still read, tests/test_calibration_formats.py)
    assert dist.split()[:8] == ["model=opencv", "width=640", "height=480", "fx=500", "fy=500", "cx=319.5",
                                "cy=239.5", "k1=-0.1"]
    assert all(isinstance(v, str) for v in d.values())


@pytest.mark.parametrize("spec", SPECS, ids=lambda s: s.name)
def test_validation_rejects_a_bad_value_in_one_line_naming_the_field(spec):
    rejected = []
    for bad in BAD:
        try:
            Camera(**{spec.name: bad})
        except InputError as exc:
            msg = str(exc)
            assert "\n" not in msg and spec.name in msg, msg
            rejected.append(bad)
        # any other exception type fails the test: a bad value must be a user error, not a crash
    assert rejected, f"Camera.{spec.name} accepted all of {BAD}"


def test_structure_key_and_scalars():
    a, b = Camera(), Camera(focus_distance_m=5.0, f_number=4.0, shutter_s=1 / 100, exposure_compensation_ev=1.0)
    assert a.structure_key() == b.structure_key() and hash(a.structure_key()) == hash(b.structure_key())
    assert a.scalars() != b.scalars() and b.scalars()["focus_distance_m"] == 5.0
    assert Camera(blades=6).structure_key() != a.structure_key()
    assert Camera(lens="thin:35").structure_key() != a.structure_key()
    keys = {n for n, _ in a.structure_key()}
    assert keys.isdisjoint(a.scalars()) and keys | set(a.scalars()) == {s.name for s in STORED}
    assert {"f_number", "focus_distance_m", "shutter_s", "iso"} <= set(a.scalars())
    assert {"lens", "blades", "film", "sensor_preset"} <= keys


def test_camera_stays_a_frozen_picklable_dataclass():
    cam = Camera(depth_of_field=True, blades=6, film="neutral-100")
    assert Camera.__module__ == "clpost.camera" and Camera.__qualname__ == "Camera"
    back = pickle.loads(pickle.dumps(cam))
    assert back == cam and hash(back) == hash(cam) and type(back) is Camera
    with pytest.raises(dataclasses.FrozenInstanceError):
        cam.blades = 5
    assert dataclasses.replace(cam, blades=8).blades == 8 and cam.with_(f_number=4).f_number == 4.0
    assert cam.focal_length_mm == 50 and cam.intrinsics(64, 48)[2] == 31.5
    assert cam.params("dof").blades == 6 and cam.params("camera").lens == "thin:50"


def test_shutter_angle_is_a_library_parameter():
    cam = Camera(frame_rate_fps=24, shutter_angle_deg=180)
    assert cam.shutter_s == pytest.approx(1 / 48)
    assert cam.with_(iso=200).shutter_s == pytest.approx(1 / 48)  # replace keeps the derived shutter
    with pytest.raises(InputError, match="needs Camera.frame_rate_fps"):
        Camera(shutter_angle_deg=180)
    with pytest.raises(InputError, match="shutter-angle"):
        Camera(frame_rate_fps=24, shutter_angle_deg=400)


def test_metering_options_only_in_auto_exposure_via_from_options():
    with pytest.raises(InputError, match="act only in auto-exposure"):
        Camera.from_options({"metering": "spot"})
    assert Camera.from_options({"metering": "spot", "shutter_s": None}).metering == "spot"
    # defaults (e.g. the demo's) are not options the user gave
    cam = Camera.from_options({"shutter_s": 1 / 50}, {"shutter_s": None, "exposure_compensation_ev": 1.0})
    assert cam.exposure_compensation_ev == 1.0 and not cam.is_auto_exposure


# -- a stage added without editing camera.py or cli.py -------------------------------------------

@dataclass(frozen=True)
class ToyParams:
    toy_gain: float = param(1.0, unit="× signal", flag="--toy-gain", parse=parse_fraction, header="clpost.toyGain",
                            check=positive("× signal", "e.g. 2"), scalar=True, help="toy gain")
    toy_mode: str = param("a", unit="mode", flag="--toy-mode", check=one_of("a", "b"), header="clpost.toyMode",
                          scalar=False, help="toy mode: a or b")

    @staticmethod
    def validate(camera, inputs):
        if camera.toy_mode == "b" and camera.toy_gain > 10:
            raise InputError(f"Camera.toy_gain={camera.toy_gain:g} needs Camera.toy_mode='a' above 10")


class Toy(PointwiseStage):
    name = "toy"
    order = 65.0
    params = ToyParams
    args = (("float", "gain"),)

    def skip_reason(self, camera, frame):
        return None

    def values(self, camera, frame):
        return (np.float32(camera.toy_gain),)

    def reference(self, camera, frame, color):
        return np.asarray(color, np.float64) * camera.toy_gain


@pytest.fixture
def toy_camera(monkeypatch):
    stages = dict(sorted({**registry(), "toy": Toy}.items(), key=lambda kv: kv[1].order))
    monkeypatch.setattr(clpost.stages, "registry", lambda: stages)
    cls = clpost.camera.build_camera_class()
    monkeypatch.setattr(clpost.cli, "Camera", cls)
    return cls


def test_a_new_stage_declares_its_parameters_everywhere(toy_camera, monkeypatch, capsys):
    cam = toy_camera(toy_gain=3.0, toy_mode="b", blades=6)
    assert (cam.toy_gain, cam.toy_mode, cam.blades) == (3.0, "b", 6)
    assert [s.owner for s in toy_camera.param_specs() if s.name.startswith("toy")] == ["toy", "toy"]
    names = [s.name for s in toy_camera.param_specs()]
    assert names.index("toy_gain") > names.index("vignetting") and names.index("toy_mode") < names.index("metering")
    d = cam.describe()
    assert d["clpost.toyGain"] == "3" and d["clpost.toyMode"] == "b" and d["clpost.blades"] == "6"
    assert ("toy_mode", "b") in cam.structure_key() and cam.scalars()["toy_gain"] == 3.0
    with pytest.raises(InputError, match=r"Camera\.toy_gain=-1 must be > 0"):
        toy_camera(toy_gain=-1)
    with pytest.raises(InputError, match="toy_mode"):
        toy_camera(toy_mode="c")
    with pytest.raises(InputError, match="needs Camera.toy_mode='a'"):
        toy_camera(toy_gain=20, toy_mode="b")
    # the command line: options, defaults in --help, parsing
    args = build_parser().parse_args(["process", "a.exr", "-o", "b.exr", "--toy-gain", "1/4", "--toy-mode", "b"])
    got = camera_from_args(args)
    assert type(got) is toy_camera and (got.toy_gain, got.toy_mode) == (0.25, "b")
    _print_help(monkeypatch, ["process", "--help"])
    out = capsys.readouterr().out
    assert "--toy-gain" in out and "toy gain (default: 1)" in out and "toy mode: a or b (default: a)" in out
    # the default Camera is untouched
    assert "toy_gain" not in {f.name for f in dataclasses.fields(Camera)}


def test_two_stages_declaring_one_name_are_refused():
    @dataclass(frozen=True)
    class Clash:
        blades: int = param(0, unit="blades", scalar=False, help="again")

    class Other(Toy):
        name = "other"
        params = Clash

    with pytest.raises(TypeError, match="blades.*both dof and other"):
        clpost.camera.build_camera_class({**registry(), "other": Other})


def test_extremes_of_the_declared_ranges_are_valid():
    Camera(transmittance=1.0, aperture_roundness=1.0, spherical_aberration=-1.0, optical_vignetting=1.0,
           noise_seed=2**32 - 1, readout_time_s=0.0, grain_amount=0.0, focus_distance_m=math.inf)

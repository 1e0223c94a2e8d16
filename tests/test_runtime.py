"""OpenCL runtime: device choice by name, build errors, kernel sources found when installed."""
import os
import sysconfig
from pathlib import Path

import pytest

from clpost import KernelBuildError, OpenCLUnavailableError
from clpost.runtime import BUILD_OPTIONS, choose_device, get_runtime, kernels_dir


def test_default_device_builds_kernels():
    rt = get_runtime()
    prog = rt.program("__kernel void k(__global float *a) { a[0] = 1.0f; }", "k")
    assert prog is rt.program("__kernel void k(__global float *a) { a[0] = 1.0f; }", "k")  # cached


def test_device_by_name_substring_and_env(monkeypatch):
    dev = choose_device()
    sub = dev.name.strip()[:6]
    assert choose_device(sub.upper()).name == dev.name or sub.upper() in choose_device(sub.upper()).name.upper()
    monkeypatch.setenv("CLPOST_DEVICE", "no-such-device-xyz")
    with pytest.raises(OpenCLUnavailableError, match="no-such-device-xyz.*matches no OpenCL device.*have:"):
        choose_device()


def test_build_failure_names_kernel_options_and_log():
    rt = get_runtime()
    with pytest.raises(KernelBuildError) as exc:
        rt.program("__kernel void broken(__global float *a) { a[0] = undefined_name; }", "broken")
    msg = str(exc.value)
    assert "'broken' failed to build" in msg and "-cl-std=CL1.2" in msg and "undefined_name" in msg


def test_no_ieee_breaking_build_options():
    for bad in ("fast-relaxed-math", "finite-math-only", "denorms-are-zero", "unsafe-math"):
        assert not any(bad in o for o in BUILD_OPTIONS)


def test_pocl_cache_dir_is_set():
    assert os.environ.get("POCL_CACHE_DIR")


def test_kernels_come_from_the_installed_package_in_ci():
    d = kernels_dir()
    assert (d / "exposure.cl").is_file()
    if os.environ.get("CLPOST_EXPECT_INSTALLED"):
        site = Path(sysconfig.get_paths()["purelib"]).resolve()
        assert site in d.resolve().parents, f"kernels found at {d}, not in the installed wheel"


def test_pocl_matches_by_implementation_name():
    dev = choose_device("pocl")
    assert "pocl" in dev.platform.version.lower()


def test_device_option_after_the_subcommand(capsys):
    from clpost.cli import main

    assert main(["bench", "--device", "no-such-device-xyz", "--sizes", "8x8"]) == 2
    assert "no-such-device-xyz" in capsys.readouterr().err

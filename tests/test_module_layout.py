"""Module layout: no import cycles inside the packages split into one module per job (a lazy
import inside a function counts: it is a cycle that only hides until first call), and the
lens curves cached on the lens object that break the optics cycle."""
import ast
import functools
import math
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ACYCLIC = ("clpost.optics", "clpost.calibration", "clpost.render.image_based_lens", "clpost.render.ibl")
"""Module prefixes that must not take part in an import cycle."""


def _modules() -> dict[str, Path]:
    out = {}
    for p in (ROOT / "clpost").rglob("*.py"):
        parts = list(p.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


@functools.cache
def import_graph() -> dict[str, set[str]]:
    """clpost module → the clpost modules it imports anywhere in its body."""
    mods = _modules()
    graph = {m: set() for m in mods}
    for m, p in mods.items():
        package = m.split(".") if p.name == "__init__.py" else m.split(".")[:-1]
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.ImportFrom):
                base = package[:len(package) - node.level + 1] if node.level else []
                name = ".".join(base + ([node.module] if node.module else []))
                targets = [f"{name}.{a.name}" if f"{name}.{a.name}" in mods else name for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                continue
            graph[m].update(t for t in targets if t in mods and t != m)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_the_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_the_split_packages_have_no_import_cycle():
    graph = import_graph()
    assert "clpost.optics.curves" in graph and "clpost.calibration.model" in graph
    bad = [c for c in cycles(graph) if any(m.startswith(ACYCLIC) for m in c)]
    assert not bad, bad
    assert not any(t.startswith("clpost.optics.lens") for t in graph["clpost.optics.curves"])


def test_lens_curves_are_cached_on_the_lens():
    from clpost.optics import Lens, LensCurves, get_lens, lens_curves

    lens = get_lens("thorlabs-lb1471")  # a singlet: its curves are the quickest to trace
    c = lens.curves(3.0, 8.0)
    assert isinstance(c, LensCurves) and (c.focus_distance_m, c.f_number) == (3.0, 8.0)
    assert lens.curves(3.0, 8.0) is c and lens_curves(lens.name, 3.0, 8.0) is c
    assert lens.curves(3.0, 11.0) is not c
    # a second Lens object of the same prescription has its own cache, same numbers
    other = Lens(lens.prescription)
    assert other.curves(3.0, 8.0) is not c
    assert other.curves(3.0, 8.0).distortion_pct == pytest.approx(c.distortion_pct)


def test_the_curves_cache_is_bounded(monkeypatch):
    from clpost.optics import lens as lens_mod

    lens = lens_mod.get_lens("zeiss-planar-50-f1.4")
    calls = []
    monkeypatch.setattr(lens_mod, "compute_curves", lambda *a: calls.append(a) or object())
    monkeypatch.setattr(lens, "_curves_cache", {})
    monkeypatch.setattr(lens, "_CURVES_KEPT", 3)
    for d in (1.0, 2.0, 3.0, 4.0):
        lens.curves(d, 2.8)
    assert len(lens._curves_cache) == 3 and len(calls) == 4
    lens.curves(4.0, 2.8)
    assert len(calls) == 4  # still kept
    lens.curves(1.0, 2.8)
    assert len(calls) == 5  # the oldest went first
    assert calls[0][1:] == (1.0, 2.8, pytest.approx(math.hypot(36, 24) / 2))


LAYERS = {
    # each job module imports only the layers before it
    "clpost.render": ["ibl_rays", "ibl_build", "ibl_warp", "ibl_raster", "image_based_lens"],
    "clpost.calibration": ["model", "frustum", "traced", "formats"],
}


@pytest.mark.parametrize("package", sorted(LAYERS))
def test_job_modules_import_only_the_layers_below(package):
    graph = import_graph()
    layers = [f"{package}.{m}" for m in LAYERS[package]]
    for i, m in enumerate(layers):
        above = set(layers[i + 1:])
        assert m in graph and not graph[m] & above, (m, graph[m] & above)


def test_the_image_based_lens_facade_exports_the_job_modules_objects():
    from clpost.render import ibl_build, ibl_rays, ibl_warp, image_based_lens

    for name in image_based_lens.__all__:
        obj = getattr(image_based_lens, name)
        homes = [m for m in (ibl_rays, ibl_build, ibl_warp, image_based_lens) if getattr(m, name, None) is obj]
        assert homes, name
        if callable(obj):  # defined in the first (lowest) module that has it, not copied
            assert obj.__module__ == homes[0].__name__, name

"""The physical order of the stages: each stage declares its order, role and domains, and the
order is checked against the domains (a misplaced stage fails); the README lists stages in it."""
import re
from pathlib import Path

from clpost.stages import order_problems, order_table, physical_order, registry

ROOT = Path(__file__).resolve().parents[1]


def _stage(name, order, domains, role="why"):
    return type(name.title(), (), {"name": name, "order": order, "domains": domains, "role": role})


def test_the_registry_order_is_physically_sound():
    assert order_problems(registry()) == []
    assert physical_order() == tuple(registry())
    # the conversions happen in the order light meets them
    order = physical_order()
    for a, b in (("motion_blur", "distortion"), ("distortion", "vignetting"), ("vignetting", "exposure"),
                 ("exposure", "film"), ("exposure", "sensor"), ("film", "grain"), ("grain", "print")):
        assert order.index(a) < order.index(b)


def test_the_order_check_catches_misplaced_stages():
    reg = registry()
    # vignetting (on the sensor) before the resampling into the sensor's geometry
    early = {**reg, "vignetting": _stage("vignetting", 45.0, ("image", "image"))}
    assert any("'vignetting' (order 45) reads 'image', which 'distortion'" in p for p in order_problems(early))
    # grain after the print left the density domain
    late = {**reg, "grain": _stage("grain", 99.0, ("density", "density"))}
    assert any("'grain' (order 99) works within 'density', which 'print'" in p for p in order_problems(late))
    # a blur in the render's geometry placed after distortion
    blur = {**reg, "halation": _stage("halation", 55.0, ("render", "render"))}
    assert any("'halation' (order 55) works within 'render', which 'distortion'" in p for p in order_problems(blur))
    assert any("share an order" in p for p in order_problems({**reg, "x": _stage("x", 70.0, ("image", "image"))}))
    assert any("no role" in p for p in order_problems({**reg, "x": _stage("x", 61.0, ("image", "image"), "")}))
    assert any("unknown domain" in p for p in order_problems({**reg, "x": _stage("x", 61.0, ("light", "image"))}))


def test_a_new_stage_declared_in_its_module_alone_joins_the_order(monkeypatch):
    """What `clpost stages` prints is generated from the declarations (no list to edit)."""
    reg = dict(registry())
    reg["halation"] = _stage("halation", 82.0, ("density", "density"), "red halo from the film base")
    monkeypatch.setattr("clpost.stages.registry", lambda: dict(sorted(reg.items(), key=lambda kv: kv[1].order)))
    assert order_problems(reg) == []
    table = order_table()
    assert "82     halation       density → density  red halo from the film base" in table
    rows = [ln.split()[1] for ln in table.splitlines()[3:-1]]
    assert rows.index("film") < rows.index("halation") < rows.index("sensor")


def test_readme_stage_table_follows_the_physical_order():
    text = (ROOT / "README.md").read_text()
    section = text.split("## What is modelled", 1)[1].split("\n## ", 1)[0]
    names = [n for n in re.findall(r"^\| (\w+) \|", section, re.M) if n != "stage"]
    assert set(names) <= set(physical_order())
    assert names == [n for n in physical_order() if n in names]

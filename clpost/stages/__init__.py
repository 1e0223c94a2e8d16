"""The stage registry: every module here that defines a :class:`~clpost.stages.base.Stage`
subclass contributes one stage — adding a stage edits no other file.

Physical order (light from the scene through the lens to the recorded image): each stage
declares its ``order``, its ``role`` (why it sits there) and its ``domains`` (input, output:
:data:`~clpost.stages.base.DOMAINS`); :func:`order_problems` checks the order against the
domains (converters into a domain before its users, transforms within a domain before the
converter out of it), and ``clpost stages`` prints the table (:func:`order_table`).

Linear pointwise stages (vignetting, exposure) commute with the linear blurs; where a
stage is non-linear (film, sensor clipping, grain, print) its position matters.
"""
from __future__ import annotations

import importlib
import inspect
import pkgutil
from functools import lru_cache

from .base import DOMAINS, QUALITIES, GatherStage, PointwiseStage, Stage

__all__ = ["DOMAINS", "QUALITIES", "GatherStage", "PointwiseStage", "Stage", "order_problems", "order_table",
           "physical_order", "registry", "stage_names"]

@lru_cache(maxsize=None)
def registry() -> dict[str, type[Stage]]:
    """All stage classes by name, in physical order (a class with ``form_of`` set is another form of
    a registered stage, which plans it through :meth:`~clpost.stages.base.Stage.planned_form`)."""
    found: dict[str, type[Stage]] = {}
    for mod in pkgutil.iter_modules(__path__):
        if mod.name == "base":
            continue
        module = importlib.import_module(f"{__name__}.{mod.name}")
        for obj in vars(module).values():
            if (inspect.isclass(obj) and issubclass(obj, Stage) and not inspect.isabstract(obj)
                    and obj.__module__ == module.__name__ and not getattr(obj, "form_of", None)):
                if obj.name in found:
                    raise RuntimeError(f"two stages are named {obj.name!r}")
                found[obj.name] = obj
    return dict(sorted(found.items(), key=lambda kv: kv[1].order))


def stage_names() -> list[str]:
    return list(registry())


def physical_order() -> tuple[str, ...]:
    """Stage names in physical order (the registry sorted by each stage's ``order``)."""
    return tuple(registry())


def order_problems(reg: dict) -> list[str]:
    """What is wrong with the physical order of ``reg`` (name → stage class): orders not unique,
    a stage without a role or with an unknown domain, a stage before a converter into its input
    domain, or a transform within a domain after the converter out of it (see
    :data:`~clpost.stages.base.DOMAINS`). Empty for a sound order."""
    problems = []
    items = sorted(reg.items(), key=lambda kv: kv[1].order)
    orders = [c.order for _, c in items]
    if len(set(orders)) != len(orders):
        problems.append(f"two stages share an order: {orders}")
    for name, c in items:
        if not getattr(c, "role", ""):
            problems.append(f"stage '{name}' declares no role (why it sits where it does)")
        bad = [d for d in c.domains if d not in DOMAINS]
        if bad:
            problems.append(f"stage '{name}' has unknown domain(s) {bad}; known: {', '.join(DOMAINS)}")
    for name, c in items:
        d_in, d_out = c.domains
        for other, o in items:
            o_in, o_out = o.domains
            if o_out == d_in and o_in != o_out and not o.order < c.order:
                problems.append(f"'{name}' (order {c.order:g}) reads {d_in!r}, which '{other}' (order "
                                f"{o.order:g}) produces: it must come later")
            if d_in != d_out and o_in == o_out == d_in and not o.order < c.order:
                problems.append(f"'{other}' (order {o.order:g}) works within {d_in!r}, which '{name}' "
                                f"(order {c.order:g}) leaves: it must come earlier")
    return problems


def order_table() -> str:
    """A reStructuredText table of every stage in physical order: order, name, domains, role
    (``clpost stages`` prints it)."""
    rows = [(f"{c.order:g}", name, f"{c.domains[0]} → {c.domains[1]}", c.role) for name, c in registry().items()]
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(("order", "stage", "domains"))]
    rule = "  ".join(["=" * w for w in widths] + ["=" * max(len(r[3]) for r in rows)])
    head = "  ".join(f"{h:<{w}}" for h, w in zip(("order", "stage", "domains"), widths)) + "  role"
    body = ["  ".join(f"{v:<{w}}" for v, w in zip(r[:3], widths)) + "  " + r[3] for r in rows]
    return "\n".join([rule, head, rule, *body, rule])

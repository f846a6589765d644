"""Direct time-integration schemes (paper Appendix A) behind one entry point.

    ds = simulate(system, "hht(0.1)", variant="both", periods=2)
    rows = compare_schemes(system, schemes="all", periods=2)

Registry: :data:`slipstep.methods.registry.SCHEMES` (one entry per scheme, with its parameter
defaults). To add a scheme, write one module with an
:class:`~slipstep.integrators.base.Integrator` subclass (the contract is in its docstring)
and add its entry there; :data:`INTEGRATORS` is built from it.
"""

from __future__ import annotations

import re
from slipstep.errors import InputError
from slipstep.model.validate import number_text
from slipstep.integrators.base import VARIANTS, ExplicitIntegrator, ImplicitIntegrator, Integrator
from slipstep.integrators.central_difference import CentralDifference
from slipstep.integrators.generalized_alpha import GeneralizedAlpha
from slipstep.integrators.hht import HHT
from slipstep.integrators.newmark import LinearAcceleration, Newmark
from slipstep.integrators.rk4 import RK4
from slipstep.methods.registry import SCHEME_ALIASES, SCHEMES


def _class_of(path: str) -> type[Integrator]:
    """The integrator class a registry entry names (``module:Class``)."""
    import importlib

    module, name = path.split(":")
    return getattr(importlib.import_module(module), name)


#: name -> integrator class, in the order of slipstep.methods.registry.SCHEMES
INTEGRATORS: dict[str, type[Integrator]] = {name: _class_of(entry.cls) for name, entry in SCHEMES.items()}
ALIASES = SCHEME_ALIASES
for _name, _cls in INTEGRATORS.items():  # the registry's kind is the class's (its variants follow from it)
    if _cls.kind != SCHEMES[_name].kind:
        raise RuntimeError(f"scheme {_name}: registry kind {SCHEMES[_name].kind}, class kind {_cls.kind}")

_CALL = re.compile(r"^\s*([A-Za-z0-9_\- ]+?)\s*(?:\((.*)\))?\s*$")


def _number(field: str, text: str) -> float:
    return number_text(field, text)  # finite, bounded digits: '1e100000000' is refused, not built


def parse_scheme(spec: str) -> tuple[str, list[float], dict[str, float]]:
    """'hht(0.1)' -> ('hht', [0.1], {}); 'newmark(beta=1/6, gamma=1/2)' -> ('newmark', [], {...})."""
    m = _CALL.match(str(spec))
    if not m:
        raise InputError("scheme", f"cannot read {spec!r}", "write name or name(p1, p2) e.g. newmark(1/6, 1/2)")
    name = m.group(1).strip().lower().replace("_", "-").replace(" ", "-")
    name = ALIASES.get(name, name)
    args, kwargs = [], {}
    if m.group(2) and m.group(2).strip():
        for part in m.group(2).split(","):
            if "=" in part:
                key, value = part.split("=", 1)
                kwargs[key.strip()] = _number(f"scheme.{key.strip()}", value)
            else:
                args.append(_number("scheme", part))
    return name, args, kwargs


def get_integrator(name: str | Integrator, *args, **params) -> Integrator:
    """An :class:`Integrator` from a registry name (optionally with parameters in
    parentheses, e.g. ``'newmark(1/6, 1/2)'``) and/or keyword parameters."""
    if isinstance(name, Integrator):
        return name
    key, pargs, kwargs = parse_scheme(name)
    if key not in INTEGRATORS:
        raise InputError("scheme", f"unknown scheme {name!r}", f"use one of {', '.join(INTEGRATORS)}")
    kwargs.update(params)
    try:
        return INTEGRATORS[key](*pargs, *args, **kwargs)
    except TypeError as exc:
        raise InputError(
            f"scheme {key}", f"bad parameters ({exc})", f"see help(slipstep.integrators.{INTEGRATORS[key].__name__})"
        ) from None


def simulate(system, scheme: str | Integrator = "newmark", variant: str = "fixed", **options):
    """Simulate ``system`` with a scheme of :data:`INTEGRATORS` in one of its variants
    ('fixed', 'adaptive', 'piecewise-linear', 'both') and return the result Dataset.

    Options: those of :class:`slipstep.methods.options.RunOptions` (periods, duration,
    step_ratio, ...; ``scheme`` is given here instead)."""
    if "scheme" in options:
        raise InputError("scheme", "given twice", "pass the scheme as the second argument")
    return get_integrator(scheme).run(system, variant, **options)


from slipstep.integrators.compare import compare_schemes, format_table  # noqa: E402

__all__ = [
    "INTEGRATORS",
    "VARIANTS",
    "CentralDifference",
    "ExplicitIntegrator",
    "GeneralizedAlpha",
    "HHT",
    "ImplicitIntegrator",
    "Integrator",
    "LinearAcceleration",
    "Newmark",
    "RK4",
    "compare_schemes",
    "format_table",
    "get_integrator",
    "parse_scheme",
    "simulate",
]

"""slipstep: fast, trustworthy time-domain simulation of structures with friction contacts.

Implements the methods of Gastaldi & Berruti (2018), "Competitive Time Marching Solution
Methods for Systems with Friction-Induced Nonlinearities", on any linear structure with
any number of spring-slider contact elements.

The public names below are imported on first use (PEP 562), so ``import slipstep`` is fast
and a script that only loads a case does not pay for numba or xarray until it runs.
"""

from __future__ import annotations

import importlib

# public name -> (module, attribute in it); None: the module itself
_EXPORTS = {
    "post": ("slipstep.post", None),
    "advise": ("slipstep.study.advise", "advise"),
    "builtin_cases": ("slipstep.casefile.files", "builtin_cases"),
    "load_case": ("slipstep.casefile.case", "load_case"),
    "load_system": ("slipstep.casefile.case", "load_system"),
    "InputError": ("slipstep.errors", "InputError"),
    "Interrupted": ("slipstep.errors", "Interrupted"),
    "OutputError": ("slipstep.errors", "OutputError"),
    "SolverError": ("slipstep.errors", "SolverError"),
    "Status": ("slipstep.errors", "Status"),
    "METHODS": ("slipstep.methods.registry", "METHODS"),
    "PAPER_METHODS": ("slipstep.methods.registry", "PAPER_METHODS"),
    "get_method": ("slipstep.methods.registry", "get_method"),
    "Scheme": ("slipstep.methods.schemes", "Scheme"),
    "generalized_alpha": ("slipstep.methods.schemes", "generalized_alpha"),
    "hht": ("slipstep.methods.schemes", "hht"),
    "newmark": ("slipstep.methods.schemes", "newmark"),
    "Save": ("slipstep.methods.save", "Save"),
    "RunOptions": ("slipstep.methods.simulation", "RunOptions"),
    "Simulation": ("slipstep.methods.simulation", "Simulation"),
    "run": ("slipstep.methods.simulation", "run"),
    "state_t_min": ("slipstep.methods.step_control", "state_t_min"),
    "state_eigenvalues": ("slipstep.methods.step_control", "state_eigenvalues"),
    "ContactElement": ("slipstep.model.contact", "ContactElement"),
    "DamperContact": ("slipstep.model.damper", "DamperContact"),
    "Platform": ("slipstep.model.damper", "Platform"),
    "rigid_damper": ("slipstep.model.damper", "rigid_damper"),
    "Excitation": ("slipstep.model.excitation", "Excitation"),
    "Harmonic": ("slipstep.model.excitation", "Harmonic"),
    "Signal": ("slipstep.model.excitation", "Signal"),
    "Tabulated": ("slipstep.model.excitation", "Tabulated"),
    "Structure": ("slipstep.model.structure", "Structure"),
    "load_result": ("slipstep.output.results", "load"),
    "save_result": ("slipstep.output.results", "save"),
    "CompiledSystem": ("slipstep.model.system", "CompiledSystem"),
    "System": ("slipstep.model.system", "System"),
    # substructures and assemblies (issue 11)
    "DamperLink": ("slipstep.model.assembly", "DamperLink"),
    "HarmonicForce": ("slipstep.model.assembly", "HarmonicForce"),
    "LinkContact": ("slipstep.model.assembly", "LinkContact"),
    "PlatformLink": ("slipstep.model.assembly", "PlatformLink"),
    "assemble": ("slipstep.model.assembly", "assemble"),
    "blade_chain": ("slipstep.model.assembly", "blade_chain"),
    "engine_order_forces": ("slipstep.model.assembly", "engine_order_forces"),
    "Point": ("slipstep.model.substructure", "Point"),
    "Substructure": ("slipstep.model.substructure", "Substructure"),
    "craig_bampton": ("slipstep.model.substructure", "craig_bampton"),
    "frame_blade": ("slipstep.model.substructure", "frame_blade"),
    "load_mtx": ("slipstep.model.substructure", "load_mtx"),
    "load_npz": ("slipstep.model.substructure", "load_npz"),
}

__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name: str):
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            value = version("slipstep")
        except PackageNotFoundError:
            value = "0+unknown"
    elif name in _EXPORTS:
        module_name, attr = _EXPORTS[name]
        module = importlib.import_module(module_name)
        value = module if attr is None else getattr(module, attr)
    else:
        raise AttributeError(f"module 'slipstep' has no attribute {name!r}")
    globals()[name] = value  # the next access is a plain attribute
    return value


def __dir__():
    return __all__

"""slipstep: fast, trustworthy time-domain simulation of structures with friction contacts.

Implements the methods of Gastaldi & Berruti (2018), "Competitive Time Marching Solution
Methods for Systems with Friction-Induced Nonlinearities", on any linear structure with
any number of spring-slider contact elements.
"""

from slipstep import post
from slipstep.advise import advise
from slipstep.config import builtin_cases, load_case, load_system
from slipstep.errors import InputError, SolverError, Status
from slipstep.methods.registry import METHODS, PAPER_METHODS, get_method
from slipstep.methods.schemes import Scheme, generalized_alpha, hht, newmark
from slipstep.methods.simulation import RunOptions, Simulation, run, state_t_min
from slipstep.model.contact import ContactElement
from slipstep.model.damper import DamperContact, Platform, rigid_damper
from slipstep.model.excitation import Excitation, Harmonic, Signal, Tabulated
from slipstep.model.structure import Structure
from slipstep.model.assembly import (DamperLink, HarmonicForce, LinkContact, PlatformLink, assemble, blade_chain,
                                     engine_order_forces)
from slipstep.model.substructure import Point, Substructure, craig_bampton, frame_blade, load_mtx, load_npz
from slipstep.results import load as load_result, save as save_result
from slipstep.system import CompiledSystem, System

__version__ = "0.1.0"

__all__ = [
    "advise", "post", "CompiledSystem", "ContactElement", "DamperContact", "Excitation", "Harmonic", "InputError", "METHODS",
    "PAPER_METHODS", "Platform", "RunOptions", "Scheme", "Signal", "Simulation", "SolverError", "Status",
    "Structure", "System", "Tabulated", "builtin_cases", "generalized_alpha", "get_method", "hht", "load_case",
    "load_result", "load_system", "newmark", "rigid_damper", "run", "save_result", "state_t_min",
    # substructures and assemblies (issue 11)
    "DamperLink", "HarmonicForce", "LinkContact", "PlatformLink", "Point", "Substructure", "assemble", "blade_chain",
    "craig_bampton", "engine_order_forces", "frame_blade", "load_mtx", "load_npz",
]

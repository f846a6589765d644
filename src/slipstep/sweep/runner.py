"""The per-worker case runner of a sweep (docs/architecture.md, "The sweep runner").

The cases of a sweep differ only in the values of its parameters. The case-format path
(slipstep.sweep.execute.run_case) builds each case from its TOML dictionary: pydantic, the
System, its compilation, plan_run and a new Marcher, about 2 ms of Python beside a 0.3-0.5 ms
kernel on the paper case. A :class:`CaseRunner` builds its first case that way once, then for
every case writes the parameter values into a copy of the compiled arrays (:class:`Patch`),
plans again only what they change (a contact stiffness, or a friction coefficient where the
stability limit depends on it: T_min and the step limits, slipstep.methods.plan.replanned;
otherwise the kernel settings) and marches on the same Marcher (Marcher.retarget: its buffers
kept); the summary comes from the kernel's arrays (post.summary.summarise_record).

    runner = case_runner(payload)      # one per worker thread and sweep payload, cached
    result = runner.run(values)        # what execute.run_case(payload, values) returns

Patched key paths (any other parameter, an assembly case, the banded backend, a method with
massless DOFs, a dynamic run with the step refinement pilot, a case that stores more than
the summary: every case takes the case-format path):

    damper cases     damper.centrifugal_force_N, damper.contacts.<c>.friction_coefficient,
                     damper.contacts.<c>.normal_stiffness_N_per_um,
                     damper.contacts.<c>.tangential_stiffness_N_per_um, motion.<i>.amplitude
    structure cases  contacts.<c>.friction_coefficient, contacts.<c>.normal_stiffness_N_per_m,
                     contacts.<c>.tangential_stiffness_N_per_m (one value), contacts.<c>.normal_offset_m,
                     structure.constant_force_N.<k>, motion.<i>.amplitude, force.<i>.amplitude

Each patch writes what the model layer computes, with the same floating-point operations
(f0 = F_c (cos a, sin a, 0); k = value x unit; the harmonic columns amplitude x cos(phase),
amplitude x sin(phase); the law table and the length scale by slipstep.model.system's own
functions), so the patched system equals System.compile's array for array. A value the case
format refuses (a negative stiffness, ...) takes the case-format path, which records the case's
INPUT_ERROR.

The runner checks itself: its first case, and the first case that moves each parameter away
from the runner's first case, are run through the case-format path as well, and the two results
(status, message, warning, summary) must be equal; if they are not, the runner stops patching (that case and
every later one take the case-format path) and says why in :attr:`CaseRunner.reason` and the log.
"""

from __future__ import annotations

import hashlib
import logging
import math
import pickle
import threading
import warnings
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from slipstep.model.validate import MAX_MAGNITUDE

log = logging.getLogger(__name__)

#: runners kept per worker thread (each holds a marcher's buffers)
CACHE_SIZE = 2
_LOCAL = threading.local()


@dataclass(frozen=True)
class Patch:
    """One location a parameter's value v writes into the compiled system:

    field 'constant_force'  f0 = v * vector (the centrifugal load), or f0[index] = v
          'mu', 'kn'        mu[index] = v, kn[index] = v * scale (then the law table)
          'kt'              kt[d] = v * scale for the directions d in ``index``
          'g'               g[index] = v (a contact's normal offset)
          'motion', 'force' the amplitude of component ``index[1]`` of harmonic ``index[0]`` = v * scale

    ``bound`` is the case format's check of v ('' any finite value, '>0', '>=0'; 'offset': > 0
    when the contact's normal is fixed); a value it refuses takes the case-format path."""

    field: str
    index: tuple
    scale: float = 1.0
    bound: str = ""
    vector: np.ndarray | None = None

    def admits(self, v: float) -> bool:
        if not (math.isfinite(v) and abs(v) <= MAX_MAGNITUDE and abs(v * self.scale) <= MAX_MAGNITUDE):
            return False
        return {"": True, ">0": v > 0, ">=0": v >= 0, "offset": v > 0}.get(self.bound, True)

    def write(self, v: float, array, amplitude) -> None:
        """Write v: ``array(name)`` is the case's copy of a compiled array, ``amplitude(field,
        h)`` its copy of harmonic h's amplitude vector."""
        if self.field == "constant_force" and self.vector is not None:
            array("constant_force")[:] = v * self.vector
        elif self.field in ("motion", "force"):
            amplitude(self.field, self.index[0])[self.index[1]] = v * self.scale
        elif self.field in ("kn", "kt"):
            array(self.field)[list(self.index)] = v * self.scale
        else:
            array(self.field)[list(self.index)] = v


class CaseRunner:
    """The cases of one sweep payload in one worker thread (module docstring)."""

    def __init__(self, payload):
        self.payload = payload
        self.patching: bool | None = None  # None until a first valid case has built the runner
        self.reason = ""  # why every case takes the case-format path
        self.checked: set | None = None  # the parameters whose patch a case-format run has confirmed
        # (None until the runner's first case has been confirmed)

    # -- one case -----------------------------------------------------------------------------
    def run(self, values) -> dict:
        """The result of the case ``values`` (one value per payload parameter), equal to
        execute.run_case(payload, values) but for the timings."""
        from slipstep.sweep.case_run import guarded, run_case

        values = [float(v) for v in values]
        if self.patching is None:
            self._build(values)
        if not self.patching or not all(p.admits(v) for ps, v in zip(self.patches, values) for p in ps):
            return run_case(self.payload, values)
        result = guarded(lambda r: self._march(values, r))
        moved = {j for j, v in enumerate(values) if v != self.values0[j] and j not in (self.checked or ())}
        if moved or self.checked is None:  # the first case, or a parameter's first move: check it
            reference = run_case(self.payload, values)
            difference = result_difference(result, reference)
            if difference:
                self._stop(f"the patched case {values} differs from the case format's: {difference}")
                return reference
            self.checked = (self.checked or set()) | moved
        return result

    def _march(self, values: list, result: dict) -> None:
        from slipstep.methods.simulation import Simulation
        from slipstep.sweep.case_run import _run_fast

        plan = self.plan_for(values)
        if not self.replans:
            for message in self.plan_warnings:  # what plan_run warned of the runner's first case
                warnings.warn(message, stacklevel=2)
        self.marcher.retarget(plan)
        self.marcher.ws.tmin_used[:] = False  # a fresh workspace's: T_min per state depends on k and mu
        result.update(_run_fast(Simulation.from_plan(plan, self.marcher), self.interfaces))

    # -- the patched system and plan -----------------------------------------------------------
    def compiled_for(self, values: list):
        """The base compiled system with ``values`` written in (module docstring)."""
        from slipstep.model.excitation import force_signal, motion_signal
        from slipstep.model.system import _law_table, _length_scale

        base = self.base.compiled
        arrays: dict = {}
        amplitudes: dict = {}

        def array(name):
            if name not in arrays:
                arrays[name] = getattr(base, name).copy()
            return arrays[name]

        def amplitude(field, h):
            if (field, h) not in amplitudes:
                amplitudes[field, h] = self.harmonics[field][h][0].copy()
            return amplitudes[field, h]

        for patches, v in zip(self.patches, values):
            for p in patches:
                p.write(v, array, amplitude)
        for (field, h), amp in amplitudes.items():  # compile_signal's columns
            phase = self.harmonics[field][h][1]
            array(f"{field}_sin")[:, h] = amp * np.cos(phase)
            array(f"{field}_cos")[:, h] = amp * np.sin(phase)
        if "kn" in arrays or "mu" in arrays:
            arrays["law_par"] = _law_table(arrays.get("kn", base.kn), arrays.get("mu", base.mu))
        cs = base._replace(**arrays)
        stiffnesses = np.concatenate([cs.kn, self.k_diagonal])
        return cs._replace(
            length_scale=_length_scale(cs.constant_force, force_signal(cs), motion_signal(cs), stiffnesses)
        )

    def plan_for(self, values: list):
        """The base plan on the patched system: planned again (T_min, step limits, step) when a
        patched number sets them, else with its kernel settings recomputed when they depend on it."""
        from slipstep.methods.plan import kernel_settings, replanned

        cs = self.compiled_for(values)
        if self.replans:
            return replanned(self.base, cs)
        plan = self.base.replace(compiled=cs)
        if plan.settings.err_scale == 0.0:  # the one number kernel_settings takes from the compiled
            return plan  # system: rtol's error scale (0 without rtol)
        return plan.replace(settings=kernel_settings(plan, plan.dt, plan.max_step, plan.low_rank))

    # -- building ------------------------------------------------------------------------------
    def _build(self, values: list) -> None:
        """Build the runner from the case ``values`` by the case format; a case that is not
        valid leaves it unbuilt (the next case tries again)."""
        from slipstep.casefile.case import build_system, parse_case
        from slipstep.errors import InputError, SolverError
        from slipstep.methods.plan import plan_run
        from slipstep.sweep.cases import apply_values, case_kind
        from slipstep.sweep.case_run import _fast, _run_options

        p = self.payload
        why = _unsupported_payload(p)
        if why:
            return self._stop(why)
        try:
            data = apply_values(p.base, p.parameters, values)
            kind = case_kind(data)
            if kind not in ("damper", "structure"):
                return self._stop(f"an {kind} case")
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                spec = parse_case(data, source="the swept case")
                system = build_system(spec)
                options = _run_options(spec.run, p.extra_run)
                plan = plan_run(system, spec.run.method or "newmark", **options)
        except (InputError, SolverError):  # not a valid case: the case-format path records why
            return None
        except Exception as exc:  # noqa: BLE001 - the case-format path records it as the case's ERROR
            return self._stop(f"building the first case raised {type(exc).__name__}: {exc}")
        if not _fast(p, options):
            return self._stop("the sweep stores more than the summary (histories, FRF or [run.save])")
        if plan.pilot_allowed or plan.massless is not None or plan.compiled.banded:
            return self._stop("the run refines its step by a pilot, has massless DOFs or a banded structure")
        try:
            self._set_up(values, data, spec, system, plan, [w.message for w in caught])
        except Unpatchable as exc:
            return self._stop(str(exc))
        except Exception as exc:  # noqa: BLE001 - a runner that cannot be set up leaves the cases to run_case
            return self._stop(f"setting up the runner raised {type(exc).__name__}: {exc}")
        self.patching = True
        return None

    def _set_up(self, values: list, data: dict, spec, system, plan, plan_warnings: list) -> None:
        from slipstep.methods.marcher import Marcher
        from slipstep.post.loops import interfaces_from_system
        from slipstep.sweep.cases import case_kind

        self.patches = [patches_of(q, case_kind(data), spec, system, plan.compiled) for q in self.payload.parameters]
        self.base, self.values0 = plan, values
        self.marcher = Marcher(plan)
        self.interfaces = interfaces_from_system(system)
        self.plan_warnings = plan_warnings
        self.k_diagonal = system.structure.diagonal("stiffness")
        self.harmonics = {
            what: [(h.amplitude, h.phase) for h in (sig.harmonics if sig is not None else ())]
            for what, sig in (("motion", system.excitation.motion), ("force", system.excitation.force))
        }
        stability = not plan.method.quasi_static and math.isfinite(plan.options.scheme.omega_crit)
        fields = {q.field for ps in self.patches for q in ps}
        self.replans = bool(fields & {"kn", "kt"}) or ("mu" in fields and stability)

    def _stop(self, why: str) -> None:
        if self.patching:
            log.warning("sweep runner: %s; the remaining cases take the case-format path", why)
        self.patching, self.reason = False, why


class Unpatchable(Exception):
    """A parameter the runner cannot write into the compiled system."""


def _unsupported_payload(payload) -> str:
    outputs = payload.outputs
    if outputs.get("time_summary", True) is False or outputs.get("frf") or outputs.get("histories"):
        return "the sweep stores more than the summary (histories or FRF)"
    if any(q.mistuning is not None for q in payload.parameters):
        return "a mistuning parameter (an assembly)"
    return ""


def patches_of(param, kind: str, spec, system, cs) -> list[Patch]:
    """The patches of a resolved sweep parameter (slipstep.sweep.cases.ResolvedParameter): one
    per location it sets; raises :class:`Unpatchable` for a location the runner does not patch."""
    if kind not in ("damper", "structure"):
        raise Unpatchable(f"a parameter of an {kind} case")
    return [_patch(path, kind, spec, system, cs, param.keys[0]) for path in param.paths]


def _patch(path: tuple, kind: str, spec, system, cs, key: str) -> Patch:
    from slipstep.casefile.case import N_PER_UM, UM

    damper = kind == "damper"
    if damper and path == ("damper", "centrifugal_force_N"):
        a = math.radians(spec.damper.centrifugal_angle_deg)
        return Patch("constant_force", (), bound=">=0", vector=np.array([math.cos(a), math.sin(a), 0.0]))
    if not damper and len(path) == 3 and path[:2] == ("structure", "constant_force_N"):
        return Patch("constant_force", (path[2],))
    if path[:1] in (("motion",), ("force",)) and len(path) == 3 and path[2] == "amplitude":
        return _harmonic_patch(path[0], path[1], spec, system, UM if damper and path[0] == "motion" else 1.0)
    contacts = ("damper", "contacts") if damper else ("contacts",)
    n = len(contacts)
    if path[:n] == contacts and len(path) == n + 2:
        entry = (spec.damper.contacts if damper else spec.contacts)[path[n]]
        c = _contact_index(system, entry.name)
        unit = N_PER_UM if damper else 1.0
        suffix = "_N_per_um" if damper else "_N_per_m"
        last = path[-1]
        if last == "friction_coefficient":
            return Patch("mu", (c,), bound=">=0")
        if last == "normal_stiffness" + suffix:
            return Patch("kn", (c,), unit, ">0")
        if last == "tangential_stiffness" + suffix:
            first, count = int(cs.first_direction[c]), int(cs.n_directions[c])
            return Patch("kt", tuple(range(first, first + count)), unit, ">0")
        if last == "normal_offset_m" and not damper:
            contact = system.contacts[c]
            return Patch("g", (int(cs.normal_row[c]),), bound="offset" if _fixed_normal(contact) else "")
    raise Unpatchable(f"{key} is not a key the sweep runner patches")


def _harmonic_patch(what: str, i: int, spec, system, scale: float) -> Patch:
    """The amplitude of [[motion]] / [[force]] entry i: harmonic (its frequency's rank among the
    signal's frequencies, as casefile.case._signal groups them), component."""
    entry = getattr(spec, what)[i]
    signal = getattr(system.excitation, what)
    names = system.motion_names if what == "motion" else system.structure.dof_names
    frequencies = [h.frequency for h in signal.harmonics]
    if frequencies.count(entry.frequency_Hz) != 1 or entry.component not in names:
        raise Unpatchable(f"{what}.{i + 1}.amplitude: its harmonic is not found in the compiled signal")
    return Patch(what, (frequencies.index(entry.frequency_Hz), list(names).index(entry.component)), scale)


def _contact_index(system, name: str) -> int:
    names = list(system.contact_names)
    if names.count(name) != 1:  # a face of nodes gives one contact per node
        raise Unpatchable(f"contact {name!r} is not one contact of the system")
    return names.index(name)


def _fixed_normal(contact) -> bool:
    """The contact's normal row sees neither DOFs nor motions (model.contact: then an offset
    <= 0 is refused)."""
    A = contact.dof_gather
    row = A[[A.shape[0] - 1]]
    zero = row.nnz == 0 if hasattr(row, "nnz") else bool(np.all(row == 0))
    B = contact.motion_gather
    return zero and (B is None or bool(np.all(B[-1] == 0)))


# -- the results and the cache --------------------------------------------------------------------


def result_difference(a: dict, b: dict) -> str:
    """'' when two case results carry the same status, message, warning and summary (NaN equal
    to NaN), else the first difference."""
    for key in ("status", "message", "warning"):
        if a[key] != b[key]:
            return f"{key} {a[key]!r} != {b[key]!r}"
    if a["summary"].keys() != b["summary"].keys():
        return "the summary keys differ"
    for key, x in a["summary"].items():
        y = b["summary"][key]
        if not (x == y or (isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y))):
            return f"{key} {x!r} != {y!r}"
    return ""


def case_runner(payload) -> CaseRunner:
    """The runner of ``payload`` in this thread (created on first use; the last CACHE_SIZE kept).
    Payloads are told apart by content: a worker receives the same sweep's payload as separate
    objects (the warm-up and the tasks)."""
    cache = getattr(_LOCAL, "runners", None)
    if cache is None:
        cache = _LOCAL.runners = OrderedDict()
        _LOCAL.keys = {}
    known = _LOCAL.keys.get(id(payload))
    if known is not None and known[0] is payload:
        key = known[1]
    else:
        key = hashlib.sha256(pickle.dumps(payload, protocol=4)).hexdigest()
        _LOCAL.keys = {id(payload): (payload, key)}
    runner = cache.get(key)
    if runner is None:
        runner = cache[key] = CaseRunner(payload)
        while len(cache) > CACHE_SIZE:
            cache.popitem(last=False)
    cache.move_to_end(key)
    return runner

"""From a sweep spec to its cases: key paths into the case's TOML dictionary, the sample
points, and one resolved case dictionary (and its hash) per case.

Key paths are the keys the user writes in the case file, joined by dots. Inside a list of
tables (``[[damper.contacts]]``, ``[[motion]]``) a segment selects entries by

* a 1-based index: ``motion.1.amplitude`` is the first ``[[motion]]`` table;
* a ``name`` or ``component``: ``damper.contacts.P3.friction_coefficient``,
  ``motion.right.x.amplitude`` (names may contain dots);
* ``*``: every entry, set to the same value: ``damper.contacts.*.friction_coefficient``.

A list of numbers takes a 1-based index too (``damper.contacts.P3.position_mm.2``). The last
segment may be a key that the base case leaves at its default (``damper.centrifugal_angle_deg``);
the case's own validation then names it if it is not a key at all.

The case hash is the SHA-256 of the canonical JSON of the resolved case dictionary (the base
case with the parameter values written in, the sweep's [run] table merged into its [run]) and
the sweep's extra run options and outputs: equal hashes mean equal inputs.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from slipstep.casefile.case import CASES_DIR, builtin_cases, read_toml
from slipstep.errors import InputError
from slipstep.sweep.spec import CASE_RUN_KEYS, Mistuning, SweepSpec, parameter_values

Path_ = tuple  # a resolved key path: str keys and int list indices (0-based)


@dataclass(frozen=True)
class ResolvedParameter:
    name: str
    unit: str
    keys: tuple[str, ...]  # as the user wrote them
    paths: tuple[Path_, ...]  # every concrete location they set
    integer: bool  # the target holds integers (e.g. run.steps_per_period)
    mistuning: Mistuning | None = None  # a coordinate of a mistuning parameter (slipstep.sweep.mistuning) ...
    role: str = ""  # ... its "level" or its "sample"


@dataclass(frozen=True)
class Plan:
    """Every case of a sweep: ``values[i, j]`` is parameter j of case i; ``grid_shape`` is the
    shape of the full grid (first parameter slowest) or None; ``hashes[i]`` identifies case i."""

    spec: SweepSpec
    base: dict
    kind: str  # "damper", "structure" or "assembly" (case_kind)
    parameters: tuple[ResolvedParameter, ...]
    values: np.ndarray
    grid_shape: tuple[int, ...] | None
    hashes: tuple[str, ...]
    extra_run: dict
    outputs: dict
    base_dir: str | None = None  # the base case file's folder (an assembly's matrix files)

    @property
    def n_cases(self) -> int:
        return self.values.shape[0]

    def case_dict(self, i: int) -> dict:
        return apply_values(self.base, self.parameters, self.values[i])


# -- base case and key paths ---------------------------------------------------------------------


def base_case(spec: SweepSpec) -> dict:
    """The base case dictionary with the sweep's case-file [run] keys merged into its [run]."""
    if isinstance(spec.base, dict):
        data = copy.deepcopy(spec.base)
    else:
        path = Path(spec.base)
        if not path.suffix and spec.base in builtin_cases():
            path = CASES_DIR / f"{spec.base}.toml"
        elif not path.suffix:
            raise InputError(
                "[sweep] base",
                f"{spec.base!r} is not a built-in case",
                f"use one of {', '.join(builtin_cases())} or a TOML case file path",
            )
        try:
            data = read_toml(path)
        except InputError as exc:
            raise InputError("[sweep] base", exc.problem, exc.fix) from None
    run = dict(data.get("run") or {})
    run.update({k: v for k, v in spec.run.items() if k in CASE_RUN_KEYS})
    data["run"] = run
    return data


def base_dir_of(spec: SweepSpec) -> str | None:
    """The folder of a base case given as a file (relative paths in the case start there)."""
    if isinstance(spec.base, str) and Path(spec.base).suffix:
        return str(Path(spec.base).resolve().parent)
    return str(CASES_DIR) if isinstance(spec.base, str) else None


def case_kind(data: dict) -> str:
    """The kind of a case dictionary (slipstep.casefile.case): damper, structure or assembly."""
    if "substructures" in data:
        return "assembly"
    return "damper" if "damper" in data else "structure"


def build_case(data: dict, base_dir: str | None = None, source: str = "the swept case"):
    """(System, run table) of a case dictionary of any kind, through the public config
    functions: parse_case + build_system, or parse_assembly + build_assembly."""
    if case_kind(data) == "assembly":
        from slipstep.casefile.assembly import build_assembly, parse_assembly

        spec = parse_assembly(data, source=source)
        return build_assembly(spec, Path(base_dir) if base_dir else Path.cwd()), spec.run
    from slipstep.casefile.case import build_system, parse_case

    spec = parse_case(data, source=source)
    return build_system(spec), spec.run


def _split(key: str) -> list[str]:
    return [s.strip() for s in key.split(".")]


def resolve(data: dict, key: str) -> list[Path_]:
    """Every concrete location (tuple of dict keys and 0-based list indices) of ``key`` in
    ``data``; raises InputError naming ``key`` when a segment matches nothing."""
    segs = _split(key)
    if any(not s for s in segs):
        raise InputError(key, "has an empty segment", "write the key path with single dots, e.g. motion.1.amplitude")
    paths = _walk(data, segs, 0, (), key)
    for path in paths:
        target = _get(data, path)
        if target is not None and (isinstance(target, bool) or not isinstance(target, (int, float))):
            what = "a list" if isinstance(target, list) else "a table" if isinstance(target, dict) else repr(target)
            raise InputError(key, f"is {what}, not a number", "address one number (a list element: key.1)")
    return paths


def _walk(node, segs: list[str], i: int, prefix: Path_, key: str) -> list[Path_]:
    if i == len(segs):
        return [prefix]
    seg = segs[i]
    here = _written(segs[:i]) or "the case"
    if isinstance(node, dict):
        if seg == "*":
            return [p for k in node for p in _walk(node[k], segs, i + 1, prefix + (k,), key)]
        if seg not in node:
            if i == len(segs) - 1:
                return [prefix + (seg,)]  # a key left at its default; the case validation checks it
            raise InputError(key, f"{here} has no key {seg!r}", f"use one of {', '.join(map(str, node)) or '(none)'}")
        return _walk(node[seg], segs, i + 1, prefix + (seg,), key)
    if isinstance(node, list):
        if seg == "*":
            return [p for j, e in enumerate(node) for p in _walk(e, segs, i + 1, prefix + (j,), key)]
        if re.fullmatch(r"[+-]?\d+", seg):
            j = int(seg)
            if not 1 <= j <= len(node):
                raise InputError(
                    key,
                    f"index {j} is out of range: {here} has {len(node)} entr{'y' if len(node) == 1 else 'ies'}",
                    f"use 1..{len(node)} (indices count from 1)",
                )
            return _walk(node[j - 1], segs, i + 1, prefix + (j - 1,), key)
        for k in range(len(segs), i, -1):  # longest match first: names may contain dots
            label = ".".join(segs[i:k])
            hits = [
                j for j, e in enumerate(node) if isinstance(e, dict) and label in (e.get("name"), e.get("component"))
            ]
            if len(hits) > 1:
                raise InputError(
                    key,
                    f"{label!r} matches {len(hits)} entries of {here}",
                    f"use an index 1..{len(node)} to pick one, or * for all",
                )
            if hits:
                return _walk(node[hits[0]], segs, k, prefix + (hits[0],), key)
        labels = [e.get("name", e.get("component")) for e in node if isinstance(e, dict)]
        labels = [str(x) for x in labels if x is not None]
        raise InputError(
            key,
            f"{here} has no entry {seg!r}",
            f"use an index 1..{len(node)}, *, or one of {', '.join(labels) or '(no names)'}",
        )
    raise InputError(key, f"{here} is a value, not a table", f"end the key path at {here}")


def _written(segs: list[str]) -> str:
    return ".".join(segs)


def _get(data, path: Path_):
    node = data
    for p in path:
        if isinstance(node, dict):
            if p not in node:
                return None
            node = node[p]
        else:
            node = node[p]
    return node


def _set(data, path: Path_, value) -> None:
    node = data
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value


def _integer_key(path: Path_, kind: str = "damper") -> bool:
    """True when the case format (slipstep.casefile.case.CaseSpec, or AssemblyCaseSpec) declares
    the key an integer."""
    import typing

    from pydantic import BaseModel

    if kind == "assembly":
        from slipstep.casefile.assembly import AssemblyCaseSpec as node
    else:
        from slipstep.casefile.case import CaseSpec as node

    for p in path:
        if isinstance(p, int):
            continue
        fields = getattr(node, "model_fields", None)
        if fields is None or p not in fields:
            return False
        node = fields[p].annotation
        while not (isinstance(node, type) and issubclass(node, BaseModel)) and typing.get_args(node):
            args = [a for a in typing.get_args(node) if a is not type(None)]
            if len(args) != 1:
                return False
            node = args[0]
    return node is int


def probe_case(plan: Plan) -> dict:
    """The base case with every swept location it does not hold set to that parameter's first
    value (what a sweep's first case is checked on: its keys, not its values)."""
    data = copy.deepcopy(plan.base)
    for j, param in enumerate(plan.parameters):
        for path in param.paths:
            if _get(data, path) is None:
                v = plan.values[0, j]
                _set(data, path, round(v) if param.integer else float(v))
    return data


def apply_values(base: dict, parameters, values) -> dict:
    """A deep copy of ``base`` with each parameter's value written at all its paths (a
    mistuning parameter: the blade deltas of its level and sample, slipstep.sweep.mistuning)."""
    from slipstep.sweep.mistuning import apply_mistuning

    data = copy.deepcopy(base)
    draws: dict = {}
    for param, value in zip(parameters, values):
        if param.mistuning is not None:
            draws.setdefault(param.mistuning, {})[param.role] = float(value)
            continue
        v = round(float(value)) if param.integer else float(value)
        for path in param.paths:
            _set(data, path, v)
    for m, d in draws.items():
        apply_mistuning(data, m, d["level"], round(d["sample"]))
    return data


# -- units and names -----------------------------------------------------------------------------


def unit_of(key: str, kind: str) -> str:
    """The unit of a case-file key path, read from its last key's name by the case format's own
    rule (slipstep.casefile.check.unit_of: motion and force amplitudes by their table); "1" for
    a dimensionless key."""
    from slipstep.casefile.check import unit_of as case_unit

    named = [s for s in _split(key) if s != "*" and not re.fullmatch(r"[+-]?\d+", s)]
    last = named[-1] if named else ""
    return case_unit(last, "damper" if kind == "damper" else "structure", table=named[0] if named else "") or "1"


def _names(spec: SweepSpec) -> list[str]:
    """Store names of the parameters: ``name`` if given, else the last key segment, extended
    leftwards (``P3_friction_coefficient``) until the names are unique."""
    chosen, first = [], None
    for depth in range(1, 8):
        chosen = []
        for p in spec.parameters:
            if isinstance(p, Mistuning):
                chosen.extend(mistuning_names(p))
                continue
            if p.name:
                chosen.append(p.name)
                continue
            segs = [s for s in _split(p.keys[0]) if s != "*"]
            start = len(segs) - depth
            while start > 0 and re.fullmatch(r"[+-]?\d+", segs[start]):  # an index: name its list too
                start -= 1
            chosen.append("_".join(segs[start:]).replace("+", "p").replace(".", "_"))
        if len(set(chosen)) == len(chosen):
            return chosen
        first = first or chosen
    dup = sorted({n for n in first if first.count(n) > 1})
    raise InputError("[[parameter]] name", f"two parameters are both named {dup[0]!r}", "give each a distinct name")


def mistuning_names(m: Mistuning) -> list[str]:
    """The store coordinates of a mistuning parameter: <name>_level, <name>_sample."""
    from slipstep.sweep.mistuning import LEVEL, SAMPLE

    return [f"{m.name}_{LEVEL}", f"{m.name}_{SAMPLE}"]


def _grid_lists(params) -> list[list[float]]:
    """The grid's axes: one per parameter, two (levels, sample numbers) per mistuning one."""
    out = []
    for p in params:
        if isinstance(p, Mistuning):
            out += [[float(v) for v in p.levels], [float(k) for k in range(p.n_samples)]]
        else:
            out.append(parameter_values(p))
    return out


def _check_names(names: list[str]) -> None:
    """Parameter names become store variables: a plain name that no store variable uses."""
    from slipstep.post.summary import FIELDS
    from slipstep.sweep.mistuning import MISTUNING_FIELDS
    from slipstep.sweep.store import RESERVED

    for i, name in enumerate(names):
        where = f"[[parameter]] {i + 1}: name"
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.+-]*", name):
            raise InputError(where, f"is {name!r}", "use letters, digits and _ (starting with a letter)")
        if name in FIELDS or name in MISTUNING_FIELDS or name in RESERVED or name.startswith(("history_", "frf_")):
            raise InputError(where, f"{name!r} is a variable of the sweep store", "give the parameter another name")


# -- the plan ------------------------------------------------------------------------------------


def sample_points(spec: SweepSpec) -> tuple[np.ndarray, tuple[int, ...] | None]:
    """The (n_cases, n_parameters) values and the grid shape (grid sampling only)."""
    params = spec.parameters
    if spec.sampling == "grid":
        lists = _grid_lists(params)
        values = np.array(list(itertools.product(*lists)), dtype=float).reshape(-1, len(lists))
        return values, tuple(len(v) for v in lists)
    if spec.sampling == "zip":
        return np.array([parameter_values(p) for p in params], dtype=float).T.copy(), None
    from scipy.stats import qmc

    d, n = len(params), spec.samples
    rng = np.random.default_rng(spec.seed)
    if spec.sampling == "sobol":
        unit = qmc.Sobol(d, scramble=True, rng=rng).random_base2(int(np.log2(n)))
    else:
        unit = qmc.LatinHypercube(d, rng=rng).random(n)
    out = np.empty_like(unit)
    for j, p in enumerate(params):
        if p.scale == "log":
            out[:, j] = np.exp(np.log(p.low) + unit[:, j] * (np.log(p.high) - np.log(p.low)))
        else:
            out[:, j] = p.low + unit[:, j] * (p.high - p.low)
    return out, None


def _mistuning_parameters(base: dict, m: Mistuning, names: list[str]) -> list[ResolvedParameter]:
    """The level and sample coordinates of a mistuning parameter, checked against the base case
    (an assembly; its blades; one delta vector per blade for a given list)."""
    from slipstep.sweep.mistuning import LEVEL, SAMPLE, blades_of

    blades = blades_of(base, m)
    if m.deltas is not None and len(m.deltas[0]) != len(blades):
        raise InputError(
            f"[[parameter]] {m.name}: deltas",
            f"has vectors of {len(m.deltas[0])} deltas for {len(blades)} blades",
            "give one delta per blade",
        )
    key = (
        ("chain.mistuning",) if base.get("chain") is not None else tuple(f"substructures.{b}.mistuning" for b in blades)
    )
    level_unit = {"normal": "1 (std)", "uniform": "1 (half-width)", "list": "1 (scale)"}[m.distribution]
    return [
        ResolvedParameter(names[0], level_unit, key, (), False, m, LEVEL),
        ResolvedParameter(names[1], "1", key, (), True, m, SAMPLE),
    ]


def _mistuning_outputs(base: dict, spec: SweepSpec, outputs: dict) -> None:
    """A mistuning sweep summarises each case's FRF at the blades' response DOFs: it needs
    [outputs.frf], whose responses default to (and must hold) those DOFs."""
    from slipstep.sweep.mistuning import response_dofs

    m = next((p for p in spec.parameters if isinstance(p, Mistuning)), None)
    if m is None:
        return
    if "frf" not in outputs:
        raise InputError(
            "[outputs.frf]",
            "is missing: a mistuning sweep summarises each sample's frequency response",
            'add [outputs.frf] with frequencies_Hz (or start_Hz, stop_Hz, num) and solver = "hbm"',
        )
    dofs = response_dofs(base, m)
    cfg = outputs["frf"]
    if cfg["responses"] is None:
        cfg["responses"] = dofs
    missing = [d for d in dofs if d not in cfg["responses"]]
    if missing:
        raise InputError("[outputs.frf] responses", f"lacks the blade DOFs {missing}", "add them (or remove responses)")
    outputs["mistuning"] = {"responses": dofs}


def case_hash(case: dict, extra_run: dict, outputs: dict) -> str:
    text = json.dumps(
        {"case": case, "run_options": extra_run, "outputs": outputs},
        sort_keys=True,
        separators=(",", ":"),
        allow_nan=True,
    )
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def make_plan(spec: SweepSpec) -> Plan:
    """Resolve the key paths against the base case, draw the points, hash every case."""
    base = base_case(spec)
    kind = case_kind(base)
    names = _names(spec)
    _check_names(names)
    resolved = []
    names = iter(names)
    for i, p in enumerate(spec.parameters):
        if isinstance(p, Mistuning):
            resolved += _mistuning_parameters(base, p, [next(names), next(names)])
            continue
        name = next(names)
        paths = []
        for key in p.keys:
            found = resolve(base, key)
            if not found:
                raise InputError(
                    f"[[parameter]] {i + 1}: key",
                    f"{key!r} matches no entry of the base case",
                    "check the key path against the case file",
                )
            paths.extend(found)
        if len(set(paths)) != len(paths):
            raise InputError(f"[[parameter]] {i + 1}: key", "sets one location twice", "list each key once")
        integer = all(_integer_key(q, kind) for q in paths)
        resolved.append(ResolvedParameter(name, p.unit or unit_of(p.keys[0], kind), p.keys, tuple(paths), integer))
    seen: dict = {}
    for i, rp in enumerate(resolved):
        for q in rp.paths:
            if q in seen:
                raise InputError(
                    f"[[parameter]] {i + 1}: key",
                    f"sets a location parameter {seen[q] + 1} also sets",
                    "sweep each location with one parameter only",
                )
            seen[q] = i
    values, grid = sample_points(spec)
    for j, rp in enumerate(resolved):
        if rp.integer and spec.sampling not in ("latin-hypercube", "sobol"):
            bad = [v for v in values[:, j] if v != round(v)]
            if bad:
                raise InputError(
                    f"[[parameter]] {j + 1}: values",
                    f"{rp.keys[0]} takes whole numbers, got {bad[0]}",
                    "give whole numbers",
                )
        if rp.integer:
            values[:, j] = np.round(values[:, j])
    extra = {k: v for k, v in spec.run.items() if k not in CASE_RUN_KEYS}
    outputs = {"histories": list(spec.outputs.histories), "history_points": spec.outputs.history_points}
    if spec.outputs.frf is not None:
        from slipstep.sweep.spec import frf_config

        outputs["frf"] = frf_config(spec.outputs.frf)
    if not spec.outputs.time_summary:
        outputs["time_summary"] = False
    _mistuning_outputs(base, spec, outputs)
    plan_params = tuple(resolved)
    hashes = tuple(case_hash(apply_values(base, plan_params, row), extra, outputs) for row in values)
    if len(set(hashes)) != len(hashes):
        raise InputError(
            "[[parameter]]",
            "two cases of the sweep are identical (repeated points)",
            "remove the repeated values or samples",
        )
    return Plan(spec, base, kind, plan_params, values, grid, hashes, extra, outputs, base_dir_of(spec))

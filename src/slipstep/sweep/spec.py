"""The sweep specification (TOML or Python) and its validation.

A sweep file has a ``[sweep]`` table (base case, sampling), a ``[run]`` table (the method and
run options, as in a case file; they win over the base case's), one ``[[parameter]]`` table per
swept quantity and an optional ``[outputs]`` table::

    [sweep]
    name = "amplitude_sweep"
    base = "paper"                 # built-in case name or TOML file (relative to this file)
    sampling = "grid"              # grid | zip | latin-hypercube | sobol
    # samples = 256 ; seed = 0     # latin-hypercube / sobol only
    # batch_size = 50              # cases per task (default: automatic)

    [run]
    method = "quasi-static"
    periods = 3

    [[parameter]]
    key = "damper.centrifugal_force_N"      # the key path as written in the case file
    values = [100.0, 200.0, 300.0]

    [[parameter]]
    key = "motion.1.amplitude"               # list entries: 1-based index, name, component or *
    start = 1.0                              # or a range: start, stop, num, scale = "linear" | "log"
    stop = 70.0
    num = 12
    scale = "log"

    [outputs]
    histories = ["tangential_force"]         # last period resampled on history_points points
    history_points = 64

    [outputs.frf]                            # optional: slipstep.frequency.frf of every case
    frequencies_Hz = [250.0, 275.0, 300.0]   # or start_Hz, stop_Hz, num
    solver = "march"                         # march | shoot; direction = "up" | "down"
    harmonics = 3                            # responses = ["8.x", ...] (default: every DOF)

A ``[[parameter]]`` of ``kind = "mistuning"`` (grid sampling) scatters the blades of an
assembly (the built-in ``ring`` or any assembly case): blade j's stiffness times 1 + delta_j,
delta = level * u with u drawn per sample (slipstep.sweep.mistuning)::

    [[parameter]]
    kind = "mistuning"
    distribution = "normal"        # normal (std = ...) | uniform (half_width = ...) | list (deltas = [[...], ...])
    std = [0.01, 0.02, 0.04]       # one level or a list of levels: the grid's mistuning levels
    samples = 50                   # samples per level, drawn with seed (sample k alone is reproducible)
    seed = 1
    # blades = ["b1", "b2", ...]   # an assembly without [chain]: the blade substructures in order
    # response = "8.x"             # the blade DOF of the amplitude (default: the engine-order force's)

Sampled sweeps (latin-hypercube, sobol) give each parameter ``low`` and ``high`` (and an
optional ``scale = "log"``) and draw ``samples`` points with ``seed`` (scipy.stats.qmc).
Every error names the key the user wrote, as the case files' messages do (slipstep.casefile.check):
``[[parameter]] 2 (amplitude): stop``, ``[sweep] sampling``, ``[outputs.frf] solver``.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

from slipstep.errors import InputError
from slipstep.output.frf_schema import FRF_SOLVERS as ALL_FRF_SOLVERS

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

SAMPLINGS = ("grid", "zip", "latin-hypercube", "sobol")
SCALES = ("linear", "log")
# run options beyond a case file's [run] table, passed to slipstep.RunOptions as they are
EXTRA_RUN_OPTIONS = {
    "tolerance": float,
    "state_tolerance": float,
    "max_iterations": int,
    "max_state_iterations": int,
    "linear_solver": str,
}
CASE_RUN_KEYS = (
    "method",
    "periods",
    "duration_s",
    "step_ratio",
    "steps_per_period",
    "step_rule",
    "ramp_time_s",
    "save",
)
HISTORY_VARIABLES = (
    "displacement",
    "velocity",
    "acceleration",
    "prescribed_motion",
    "tangential_displacement",
    "normal_displacement",
    "tangential_force",
    "normal_force",
    "slider",
    "contact_state",
)


@dataclass(frozen=True)
class Parameter:
    """One swept quantity: ``key`` (a key path of the case file, or several set together),
    and either ``values``, a range (start, stop, num, scale) or bounds (low, high, scale)
    for sampled sweeps. ``name`` labels it in the store (default: from the key), ``unit``
    overrides the unit read from the key name."""

    key: str | tuple[str, ...]
    values: tuple[float, ...] | None = None
    start: float | None = None
    stop: float | None = None
    num: int | None = None
    low: float | None = None
    high: float | None = None
    scale: str = "linear"
    name: str | None = None
    unit: str | None = None

    @property
    def keys(self) -> tuple[str, ...]:
        return (self.key,) if isinstance(self.key, str) else tuple(self.key)


DISTRIBUTIONS = {"normal": "std", "uniform": "half_width", "list": "scale"}  # distribution -> its level key
MISTUNING_KEYS = (
    "kind",
    "name",
    "distribution",
    "std",
    "half_width",
    "scale",
    "samples",
    "seed",
    "deltas",
    "blades",
    "response",
)


@dataclass(frozen=True)
class Mistuning:
    """Random blade mistuning, a parameter of two store coordinates (``<name>_level``,
    ``<name>_sample``): blade j's stiffness times 1 + delta_j with delta = level * u_k, where
    u_k is the unit draw of sample k: normal u_j ~ N(0, 1) (level: the standard deviation),
    uniform u_j ~ U(-1, 1) (level: the half-width), list u_k = deltas[k] as given (level: a
    scale, default 1). ``blades`` names the blade substructures of an assembly without
    [chain]; ``response`` the blade DOF whose amplitude is summarised."""

    distribution: str = "normal"
    levels: tuple[float, ...] = ()
    samples: int | None = None
    seed: int = 0
    deltas: tuple[tuple[float, ...], ...] | None = None
    blades: tuple[str, ...] | None = None
    response: str | None = None
    name: str = "mistuning"
    kind = "mistuning"

    @property
    def n_samples(self) -> int:
        return len(self.deltas) if self.deltas is not None else int(self.samples or 0)

    @property
    def keys(self) -> tuple[str, ...]:
        return ("mistuning",)

    def to_dict(self) -> dict:
        d = {"kind": "mistuning", "name": self.name, "distribution": self.distribution, "seed": self.seed}
        d[DISTRIBUTIONS.get(self.distribution, "std")] = list(self.levels)
        if self.samples is not None:
            d["samples"] = self.samples
        if self.deltas is not None:
            d["deltas"] = [list(v) for v in self.deltas]
        for k in ("blades", "response"):
            if getattr(self, k) is not None:
                d[k] = list(getattr(self, k)) if k == "blades" else getattr(self, k)
        return d


@dataclass(frozen=True)
class Outputs:
    """What each case returns besides its summary."""

    histories: tuple[str, ...] = ()
    history_points: int = 64
    frf: dict | None = None  # the frequency response of each case (FRF_KEYS), see frf_config
    time_summary: bool = True  # False: no time-domain run per case (an FRF-only sweep)


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep. ``base`` is a built-in case name, a TOML path or a case dict;
    ``run`` holds the case-file [run] keys and the extra run options."""

    base: str | dict
    parameters: tuple[Parameter, ...]
    sampling: str = "grid"
    run: dict = field(default_factory=dict)
    outputs: Outputs = Outputs()
    samples: int | None = None
    seed: int = 0
    batch_size: int | None = None
    name: str = "sweep"
    description: str = ""
    source: str = "sweep"

    def __post_init__(self):
        validate(self)

    def to_dict(self) -> dict:
        """The spec as plain data (the store keeps it in its attrs)."""
        params = []
        for p in self.parameters:
            if isinstance(p, Mistuning):
                params.append(p.to_dict())
                continue
            d = {
                k: getattr(p, k)
                for k in ("key", "values", "start", "stop", "num", "low", "high", "name", "unit")
                if getattr(p, k) is not None
            }
            d["scale"] = p.scale
            if isinstance(d["key"], tuple):
                d["key"] = list(d["key"])
            if "values" in d:
                d["values"] = list(d["values"])
            params.append(d)
        sweep = {
            "name": self.name,
            "description": self.description,
            "base": self.base,
            "sampling": self.sampling,
            "seed": self.seed,
        }
        for k in ("samples", "batch_size"):
            if getattr(self, k) is not None:
                sweep[k] = getattr(self, k)
        outputs = {
            "histories": list(self.outputs.histories),
            "history_points": self.outputs.history_points,
            "frf": self.outputs.frf,
        }
        if not self.outputs.time_summary:
            outputs["time_summary"] = False
        if self.outputs.frf is None:
            del outputs["frf"]
        return {"sweep": sweep, "run": dict(self.run), "parameter": params, "outputs": outputs}


# -- reading -------------------------------------------------------------------------------------


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a sweep TOML file; a relative ``base`` path is relative to it."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise InputError("spec", f"file {str(path)!r} not found", "give the path of a sweep TOML file") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError("spec", f"{path} is not valid TOML ({exc})", "fix the TOML syntax") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError("spec", f"{str(path)!r} cannot be read ({exc})", "give a readable TOML text file") from None
    return spec_from_dict(data, source=str(path), root=path.parent)


def spec_from_dict(data: dict, source: str = "sweep", root: Path | None = None) -> SweepSpec:
    """A SweepSpec from the TOML layout (module docstring); errors name the keys."""
    _known(data, "", ("sweep", "run", "parameter", "outputs"), "a sweep file")
    sweep = _table(data, "sweep", required=True)
    _known(sweep, "[sweep] ", ("name", "description", "base", "sampling", "samples", "seed", "batch_size"), "[sweep]")
    if "base" not in sweep:
        raise InputError(
            "[sweep] base",
            f"is required in {source} but missing",
            'name the base case: a built-in case ("paper") or a TOML case file',
        )
    base = sweep["base"]
    if isinstance(base, str) and root is not None and Path(base).suffix:
        base = str((root / base).resolve()) if not Path(base).is_absolute() else base
    params = data.get("parameter")
    if not isinstance(params, list) or not params:
        raise InputError(
            "[[parameter]]",
            f"no [[parameter]] table in {source}",
            'add one per swept quantity: [[parameter]] key = "damper.centrifugal_force_N" values = [...]',
        )
    parsed = tuple(_parameter(p, i) for i, p in enumerate(params))
    outputs = _table(data, "outputs")
    _known(outputs, "[outputs] ", ("summary", "histories", "history_points", "frf", "time_summary"), "[outputs]")
    if outputs.get("summary", True) is not True:
        raise InputError(
            "[outputs] summary", "cannot be switched off", "remove the key: every case returns its summary"
        )
    out = Outputs(
        histories=tuple(_str_list(outputs.get("histories", []), "[outputs] histories")),
        history_points=outputs.get("history_points", 64),
        frf=outputs.get("frf"),
        time_summary=outputs.get("time_summary", True),
    )
    return SweepSpec(
        base=base,
        parameters=parsed,
        sampling=sweep.get("sampling", "grid"),
        run=dict(_table(data, "run")),
        outputs=out,
        samples=sweep.get("samples"),
        seed=sweep.get("seed", 0),
        batch_size=sweep.get("batch_size"),
        name=sweep.get("name", Path(source).stem if source != "sweep" else "sweep"),
        description=sweep.get("description", ""),
        source=source,
    )


def _parameter(p, i: int) -> Parameter | Mistuning:
    where = f"[[parameter]] {i + 1}"
    if not isinstance(p, dict):
        raise InputError(where, "is not a table", "write each parameter as a [[parameter]] table")
    kind = p.get("kind", "value")
    if kind == "mistuning":
        return _mistuning(p, where)
    if kind != "value":
        raise InputError(f"{where}: kind", f"is {kind!r}", 'use "value" (the default) or "mistuning"')
    p = {k: v for k, v in p.items() if k != "kind"}
    _known(
        p,
        f"{where}: ",
        ("key", "values", "start", "stop", "num", "low", "high", "scale", "name", "unit"),
        "a [[parameter]] table",
    )
    if "key" not in p:
        raise InputError(
            f"{where}: key",
            "is required but missing",
            'give the key path of the case file, e.g. key = "damper.centrifugal_force_N"',
        )
    key = p["key"]
    if isinstance(key, list):
        key = tuple(_str_list(key, f"{where}: key"))
    values = p.get("values")
    if values is not None:
        if not isinstance(values, list):
            raise InputError(f"{where}: values", f"is {values!r}", "give a list of numbers, e.g. values = [1.0, 2.0]")
        values = tuple(values)
    return Parameter(
        key=key,
        values=values,
        start=p.get("start"),
        stop=p.get("stop"),
        num=p.get("num"),
        low=p.get("low"),
        high=p.get("high"),
        scale=p.get("scale", "linear"),
        name=p.get("name"),
        unit=p.get("unit"),
    )


def _mistuning(p: dict, where: str) -> Mistuning:
    """A Mistuning from its [[parameter]] table (the TOML keys MISTUNING_KEYS)."""
    _known(p, f"{where}: ", MISTUNING_KEYS, 'a [[parameter]] table of kind = "mistuning"')
    distribution = p.get("distribution", "normal")
    if distribution not in DISTRIBUTIONS:
        raise InputError(f"{where}: distribution", f"is {distribution!r}", f"use one of {', '.join(DISTRIBUTIONS)}")
    level_key = DISTRIBUTIONS[distribution]
    for other in set(DISTRIBUTIONS.values()) - {level_key}:
        if other in p:
            raise InputError(
                f"{where}: {other}", f"is not the level of a {distribution} distribution", f"give {level_key} = ..."
            )
    if level_key not in p and distribution != "list":
        raise InputError(f"{where}: {level_key}", "is required but missing", f"give {level_key} = 0.02 (or a list)")
    levels = p.get(level_key, 1.0)
    levels = tuple(levels) if isinstance(levels, list) else (levels,)
    deltas = p.get("deltas")
    if deltas is not None:
        if not isinstance(deltas, list) or not all(isinstance(v, list) for v in deltas):
            raise InputError(f"{where}: deltas", f"is {deltas!r}", "give a list of delta vectors, one per sample")
        deltas = tuple(tuple(v) for v in deltas)
    blades = p.get("blades")
    if blades is not None:
        blades = tuple(_str_list(blades, f"{where}: blades"))
    return Mistuning(
        distribution=distribution,
        levels=levels,
        samples=p.get("samples"),
        seed=p.get("seed", 0),
        deltas=deltas,
        blades=blades,
        response=p.get("response"),
        name=p.get("name", "mistuning"),
    )


def _check_mistuning(m: Mistuning, where: str, sampling: str) -> None:
    if sampling != "grid":
        raise InputError(
            f"{where}: kind",
            f"a mistuning parameter needs grid sampling, not {sampling}",
            'use sampling = "grid" (the samples are the mistuning parameter\'s own)',
        )
    level_key = DISTRIBUTIONS[m.distribution]
    if not m.levels:
        raise InputError(f"{where}: {level_key}", "is empty", "give at least one level")
    for j, v in enumerate(m.levels):
        if _number(f"{where}: {level_key}[{j}]", v) <= 0:
            raise InputError(f"{where}: {level_key}[{j}]", f"is {v}", "give a level > 0")
    if len(set(m.levels)) != len(m.levels):
        raise InputError(f"{where}: {level_key}", f"repeats a level ({list(m.levels)})", "give each level once")
    _integer(f"{where}: seed", m.seed, minimum=0)
    if m.distribution == "list":
        if m.deltas is None or not m.deltas:
            raise InputError(
                f"{where}: deltas", "is missing or empty", "give deltas = [[d1, d2, ...], ...], one per sample"
            )
        if m.samples is not None:
            raise InputError(f"{where}: samples", "is given with deltas", "remove it: each delta vector is a sample")
        widths = {len(v) for v in m.deltas}
        if len(widths) != 1:
            raise InputError(f"{where}: deltas", f"has vectors of lengths {sorted(widths)}", "give one delta per blade")
        for k, vec in enumerate(m.deltas):
            for j, v in enumerate(vec):
                _number(f"{where}: deltas[{k}][{j}]", v)
    else:
        if m.deltas is not None:
            raise InputError(
                f"{where}: deltas", f"is given with distribution {m.distribution!r}", 'use distribution = "list"'
            )
        _integer(f"{where}: samples", m.samples, minimum=1, hint="the number of samples per level")
    if m.response is not None and (not isinstance(m.response, str) or not m.response):
        raise InputError(f"{where}: response", f"is {m.response!r}", 'give a blade DOF such as "8.x"')
    if not isinstance(m.name, str) or not m.name:
        raise InputError(f"{where}: name", f"is {m.name!r}", "give a non-empty text")


# -- validation ----------------------------------------------------------------------------------


def validate(spec: SweepSpec) -> None:
    """Check the spec's own consistency (the key paths are checked against the base case when
    the plan is made, slipstep.sweep.cases.make_plan)."""
    if not isinstance(spec.base, (str, dict)) or (isinstance(spec.base, str) and not spec.base):
        raise InputError(
            "[sweep] base", f"is {spec.base!r}", "give a built-in case name, a TOML case path or a case dict"
        )
    if spec.sampling not in SAMPLINGS:
        raise InputError("[sweep] sampling", f"is {spec.sampling!r}", f"use one of {', '.join(SAMPLINGS)}")
    _integer("[sweep] seed", spec.seed, minimum=0)
    if spec.batch_size is not None:
        _integer("[sweep] batch_size", spec.batch_size, minimum=1)
    if not isinstance(spec.name, str) or not spec.name:
        raise InputError("[sweep] name", f"is {spec.name!r}", "give a non-empty text")
    if not spec.parameters:
        raise InputError("[[parameter]]", "no parameter is swept", "add at least one [[parameter]]")
    sampled = spec.sampling in ("latin-hypercube", "sobol")
    if sampled:
        n = _integer("[sweep] samples", spec.samples, minimum=1, hint=f"the number of {spec.sampling} points")
        if spec.sampling == "sobol" and n & (n - 1):
            raise InputError(
                "[sweep] samples",
                f"is {n}: Sobol points are balanced only in powers of 2",
                f"use {2 ** math.ceil(math.log2(n))} (or {2 ** int(math.log2(n))})",
            )
    elif spec.samples is not None:
        raise InputError(
            "[sweep] samples",
            f"is set but sampling is {spec.sampling!r}",
            "remove it (the lists and ranges give the cases) or use latin-hypercube / sobol",
        )
    for i, p in enumerate(spec.parameters):
        if isinstance(p, Mistuning):
            _check_mistuning(p, _param_where(i, p), spec.sampling)
        else:
            _check_parameter(p, _param_where(i, p), sampled, spec.sampling)
    if sum(isinstance(p, Mistuning) for p in spec.parameters) > 1:
        raise InputError("[[parameter]] kind", "two parameters are of kind mistuning", "give one mistuning parameter")
    if spec.sampling == "zip":
        lengths = {len(parameter_values(p)) for p in spec.parameters}
        if len(lengths) > 1:
            raise InputError(
                "[[parameter]]",
                f"zip sampling needs lists of one length, got lengths {sorted(lengths)}",
                'give every parameter as many values, or use sampling = "grid"',
            )
    _check_run(spec.run)
    _check_outputs(spec.outputs)


def _check_parameter(p: Parameter, where: str, sampled: bool, sampling: str) -> None:
    keys = p.keys
    if not keys or not all(isinstance(k, str) and k.strip() for k in keys):
        raise InputError(f"{where}: key", f"is {p.key!r}", 'give a key path such as "damper.centrifugal_force_N"')
    if p.scale not in SCALES:
        raise InputError(f"{where}: scale", f"is {p.scale!r}", f"use one of {', '.join(SCALES)}")
    for attr in ("name", "unit"):
        value = getattr(p, attr)
        if value is not None and (not isinstance(value, str) or not value):
            raise InputError(f"{where}.{attr}", f"is {value!r}", "give a non-empty text")
    given = {k for k in ("values", "start", "stop", "num", "low", "high") if getattr(p, k) is not None}
    if sampled:
        if given != {"low", "high"}:
            raise InputError(
                f"{where}",
                f"has {sorted(given) or 'nothing'} but {sampling} sampling needs low and high",
                "give the bounds low = ... and high = ... (and no values or range)",
            )
        low, high = _number(f"{where}: low", p.low), _number(f"{where}: high", p.high)
        if not low < high:
            raise InputError(f"{where}: high", f"is {high}, not above low = {low}", "give low < high")
        if p.scale == "log" and low <= 0:
            raise InputError(f"{where}: low", f"is {low}: a log scale needs positive bounds", "give low > 0")
        return
    if given == {"values"}:
        if not p.values:
            raise InputError(f"{where}: values", "is empty", "give at least one value")
        for j, v in enumerate(p.values):
            _number(f"{where}: values[{j}]", v)
        if len(set(p.values)) != len(p.values):
            raise InputError(f"{where}: values", f"repeats a value ({list(p.values)})", "give each value once")
        return
    if given == {"start", "stop", "num"}:
        a, b = _number(f"{where}: start", p.start), _number(f"{where}: stop", p.stop)
        n = _integer(f"{where}: num", p.num, minimum=1)
        if n > 1 and a == b:
            raise InputError(f"{where}: stop", f"equals start ({a}) with num = {n}", "give different start and stop")
        if p.scale == "log" and (a <= 0 or b <= 0):
            raise InputError(
                f"{where}: start" if a <= 0 else f"{where}: stop",
                "is not positive: a log range needs positive ends",
                "give start > 0 and stop > 0",
            )
        return
    if {"low", "high"} & given:
        raise InputError(
            f"{where}: low",
            f"is for latin-hypercube / sobol sampling, not {sampling}",
            "give values = [...] or start, stop, num",
        )
    raise InputError(
        f"{where}",
        f"has {sorted(given) or 'no values'}",
        "give either values = [...] or a range start = ..., stop = ..., num = ...",
    )


def _check_run(run: dict) -> None:
    if not isinstance(run, dict):
        raise InputError("[run]", f"is {run!r}", "give a [run] table")
    for key, value in run.items():
        if key in CASE_RUN_KEYS:
            continue  # validated with the case ([run] of a case file)
        if key not in EXTRA_RUN_OPTIONS:
            raise InputError(
                f"[run] {key}",
                "is not a known run option",
                f"use the case-file [run] keys ({', '.join(CASE_RUN_KEYS)}) or {', '.join(EXTRA_RUN_OPTIONS)}",
            )
        kind = EXTRA_RUN_OPTIONS[key]
        ok = (isinstance(value, kind) and not isinstance(value, bool)) or (kind is float and _is_number(value))
        if not ok:
            raise InputError(f"[run] {key}", f"is {value!r}", f"give a {kind.__name__}")


def _check_outputs(out: Outputs) -> None:
    for j, name in enumerate(out.histories):
        if name not in HISTORY_VARIABLES:
            raise InputError(
                f"[outputs] histories[{j}]",
                f"is {name!r}, not a time history of the result",
                f"use some of {', '.join(HISTORY_VARIABLES)}",
            )
    _integer("[outputs] history_points", out.history_points, minimum=2)
    if not isinstance(out.time_summary, bool):
        raise InputError("[outputs] time_summary", f"is {out.time_summary!r}", "give true or false")
    if not out.time_summary and out.frf is None:
        raise InputError(
            "[outputs] time_summary", "is false without [outputs.frf]", "keep the time summary or add [outputs.frf]"
        )
    if not out.time_summary and out.histories:
        raise InputError(
            "[outputs] histories",
            "need the time-domain run (time_summary = false)",
            "remove them or the time_summary key",
        )
    if out.frf is not None:
        frf_config(out.frf)


FRF_KEYS = (
    "frequencies_Hz",
    "start_Hz",
    "stop_Hz",
    "num",
    "solver",
    "direction",
    "harmonics",
    "responses",
    "tolerance",
    "check",
    "adequacy",
)
FRF_SOLVERS = tuple(s for s in ALL_FRF_SOLVERS if s != "auto")  # a sweep names its solver
HBM_CHECKS = ("auto", "peak", "all", "none")


def frf_config(table) -> dict:
    """The [outputs.frf] table checked and completed: the frequencies [Hz] (a list, or start_Hz,
    stop_Hz, num), solver (march | shoot | hbm), direction (up | down), harmonics H (hbm: H or a
    list of retained harmonics such as [1, 3, 5]), responses (DOF names, default all), the
    steady-state tolerance, and for hbm its time-marching cross-check (check: auto | peak | all | none, as slipstep.hbm.frf)
    and truncation estimate (adequacy: true | false); slipstep.frequency.frf runs it per case."""
    import numpy as np

    where = "[outputs.frf]"
    if not isinstance(table, dict):
        raise InputError(where, f"is {table!r}", "give a table: [outputs.frf] frequencies_Hz = [...]")
    _known(table, f"{where} ", FRF_KEYS, "[outputs.frf]")
    if "frequencies_Hz" in table:
        if {"start_Hz", "stop_Hz", "num"} & set(table):
            raise InputError(f"{where} frequencies_Hz", "is given with a range", "give a list or start/stop/num")
        freqs = (
            [_number(f"{where} frequencies_Hz[{j}]", v) for j, v in enumerate(table["frequencies_Hz"])]
            if isinstance(table["frequencies_Hz"], list)
            else None
        )
        if not freqs:
            raise InputError(f"{where} frequencies_Hz", f"is {table['frequencies_Hz']!r}", "give a list of frequencies")
    elif {"start_Hz", "stop_Hz", "num"} <= set(table):
        a, b = _number(f"{where} start_Hz", table["start_Hz"]), _number(f"{where} stop_Hz", table["stop_Hz"])
        freqs = [float(v) for v in np.linspace(a, b, _integer(f"{where} num", table["num"], minimum=1))]
    else:
        raise InputError(where, "has no frequencies", "give frequencies_Hz = [...] or start_Hz, stop_Hz, num")
    if min(freqs) <= 0 or len(set(freqs)) != len(freqs):
        raise InputError(
            f"{where} frequencies_Hz",
            f"is {freqs[:6]}: frequencies must be distinct and positive",
            "give distinct positive frequencies [Hz]",
        )
    solver, direction = table.get("solver", "march"), table.get("direction", "up")
    if solver not in FRF_SOLVERS:
        raise InputError(f"{where} solver", f"is {solver!r}", f"use one of {', '.join(FRF_SOLVERS)}")
    for key in ("check", "adequacy"):
        if key in table and solver != "hbm":
            raise InputError(f"{where} {key}", f"is an option of solver hbm, not {solver}", "remove it or use hbm")
    check, adequacy = table.get("check", "auto"), table.get("adequacy", True)
    if check not in HBM_CHECKS:
        raise InputError(f"{where} check", f"is {check!r}", f"use one of {', '.join(HBM_CHECKS)}")
    if not isinstance(adequacy, bool):
        raise InputError(f"{where} adequacy", f"is {adequacy!r}", "give true or false")
    if direction not in ("up", "down"):
        raise InputError(
            f"{where} direction",
            f"is {direction!r}",
            "use up or down (a sweep stores one direction; run a second sweep for the other)",
        )
    responses = table.get("responses")
    if responses is not None:
        responses = _str_list(responses, f"{where} responses")
    out = {
        "frequencies_Hz": sorted(freqs),
        "solver": solver,
        "direction": direction,
        "harmonics": _harmonics(f"{where} harmonics", table.get("harmonics", 3), solver),
        "responses": responses,
        "tolerance": _number(f"{where} tolerance", table.get("tolerance", 1e-6)),
    }
    if solver == "hbm":
        out.update(check=check, adequacy=adequacy)
    return out


def _harmonics(where: str, value, solver: str):
    """H >= 0, or (harmonic balance) a list of distinct retained harmonics >= 1."""
    if solver == "hbm" and isinstance(value, list):
        if not value or any(isinstance(h, bool) or not isinstance(h, int) or h < 1 for h in value):
            raise InputError(where, f"is {value!r}", "give H or a list of harmonics >= 1, e.g. [1, 3, 5]")
        if len(set(value)) != len(value):
            raise InputError(where, f"repeats a harmonic ({value})", "give each harmonic once")
        return sorted(value)
    return _integer(where, value, minimum=0)


def parameter_values(p: Parameter) -> list[float]:
    """The values of a listed or ranged parameter, in order (linear: numpy.linspace,
    log: numpy.geomspace)."""
    import numpy as np

    if p.values is not None:
        return [float(v) if isinstance(v, float) else v for v in p.values]
    if p.scale == "log":
        return [float(v) for v in np.geomspace(p.start, p.stop, p.num)]
    return [float(v) for v in np.linspace(p.start, p.stop, p.num)]


# -- small helpers -------------------------------------------------------------------------------


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _param_where(i: int, p: Parameter) -> str:
    """How messages name a [[parameter]] table: its position from 1, and its name if it has one
    (the case files' convention, slipstep.casefile.check)."""
    return f"[[parameter]] {i + 1}" + (f" ({p.name})" if p.name else "")


def _number(where: str, value) -> float:
    if not _is_number(value) or not math.isfinite(value):
        raise InputError(where, f"is {value!r}", "give a finite number")
    return float(value)


def _integer(where: str, value, minimum: int, hint: str = "a whole number") -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise InputError(where, f"is {value!r}", f"give {hint} >= {minimum}")
    return value


def _table(data: dict, key: str, required: bool = False) -> dict:
    value = data.get(key)
    if value is None:
        if required:
            raise InputError(key, "is required but missing", f"add a [{key}] table")
        return {}
    if not isinstance(value, dict):
        raise InputError(key, f"is {value!r}, not a table", f"write it as a [{key}] table")
    return value


def _known(table: dict, prefix: str, keys: tuple[str, ...], where: str) -> None:
    for key in table:
        if key not in keys:
            raise InputError(f"{prefix}{key}", f"is not a known key of {where}", f"use one of {', '.join(keys)}")


def _str_list(value, where: str) -> list[str]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise InputError(where, f"is {value!r}", 'give a list of texts, e.g. ["a", "b"]')
    return value

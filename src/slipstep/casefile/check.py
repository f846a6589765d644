"""Checks of a TOML case in the user's terms: key paths as written, values in the user's units.

Every message names the key path of the case file: ``period_s`` (top level), ``[damper] mass_kg``
(a table), ``[[damper.contacts]] 2 (P3): friction_coefficient`` (the second element of an array
of tables, with its name). Values are printed in the unit of the key (``_N_per_um`` -> N/um).
:func:`spec_error` turns a pydantic error into such a message (an unknown key gets the closest
valid one: "did you mean friction_coefficient?"); :func:`check_case` closes the holes a schema
cannot: names (empty, control characters, duplicates of every kind), duplicate harmonics and
tables, numbers out of range or absurd, ragged or mis-sized matrices.
"""

from __future__ import annotations

import difflib
import math
import typing

from slipstep.errors import InputError
from slipstep.model.validate import MAX_MAGNITUDE
from slipstep.model.text import check_name, escape_text

UNITS = (  # key suffix -> unit as printed (longest first)
    ("_N_s_per_m", "N s/m"),
    ("_N_per_um", "N/um"),
    ("_N_per_m", "N/m"),
    ("_kg_m2", "kg m^2"),
    ("_kg", "kg"),
    ("_Hz", "Hz"),
    ("_deg", "deg"),
    ("_mm", "mm"),
    ("_N", "N"),
    ("_m", "m"),
    ("_s", "s"),
)
FIX_FORMAT = "check the spelling against the case-file keys of the documentation (Reference: Case-file keys; units are part of key names)"


def unit_of(key: str, kind: str = "damper", table: str = "") -> str:
    """The unit of a key from its suffix; ``amplitude`` / ``values`` depend on the table."""
    if key in ("amplitude", "values"):
        if table.startswith("force"):
            return "N"
        return "um" if kind == "damper" else "m"
    for suffix, unit in UNITS:
        if key.endswith(suffix):
            return unit
    return ""


def _element(name_table: str, index: int, item) -> str:
    label = f"[[{name_table}]] {index + 1}"
    if isinstance(item, dict) and isinstance(item.get("name"), str) and item["name"]:
        label += f" ({_short(item['name'])})"
    return label


def key_path(loc, data) -> str:
    """The TOML key path of a pydantic location within ``data`` (union tags skipped), with
    control characters escaped."""
    return escape_text(_key_path(loc, data))


def _key_path(loc, data) -> str:
    tables: list[str] = []  # keys of the enclosing tables (dotted in the header)
    element = ""  # '[[a.b]] 2 (P3)' inside an element of an array of tables
    keys: list[str] = []  # keys below the current table or element
    index = ""  # '[0]' into a list value
    node = data
    for i, seg in enumerate(loc):
        last = i == len(loc) - 1
        if isinstance(node, dict) and isinstance(seg, str):
            if seg not in node:
                if last:  # a missing key
                    keys.append(seg)
                continue  # else a union member tag ('float', 'list[float]')
            node = node[seg]
            if isinstance(node, dict):
                tables, keys = tables + keys + [seg], []
            else:
                keys.append(seg)
        elif isinstance(node, list) and isinstance(seg, int) and 0 <= seg < len(node):
            if isinstance(node[seg], dict) and keys:
                element, tables, keys = _element(".".join(tables + keys), seg, node[seg]), [], []
            else:
                index += f"[{seg}]"
            node = node[seg]
        # anything else: a union member tag or a position past the data
    if element:
        prefix = element + (f" [{'.'.join(tables)}]" if tables else "")
        return f"{prefix}: {'.'.join(keys)}{index}" if keys else prefix
    if tables:
        return f"[{'.'.join(tables)}] {'.'.join(keys)}{index}".rstrip()
    return ".".join(keys) + index or "case"


def _short(value, limit: int = 60) -> str:
    text = repr(value) if not isinstance(value, str) else value
    return text if len(text) <= limit else text[: limit - 3] + "..."


def describe(value) -> str:
    """A TOML value as the user wrote it (true, "text", [1, 2], 1e300)."""
    if isinstance(value, bool):
        return "true (a boolean)" if value else "false (a boolean)"
    if isinstance(value, str):
        return f"{_short(repr(value))} (text)"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, list):
        return f"{_short(value)} (a list)"
    if isinstance(value, dict):
        return "a table"
    return _short(value)


_EXPECTED = {
    "float_type": "a number",
    "float_parsing": "a number",
    "int_type": "a whole number",
    "int_from_float": "a whole number",
    "int_parsing": "a whole number",
    "string_type": "text in quotes",
    "list_type": "a list [...]",
    "model_type": "a table",
    "dict_type": "a table",
    "bool_type": "true or false",
    "model_attributes_type": "a table",
}


def _model_at(model, loc):
    """The pydantic model class that holds the last key of ``loc``."""
    for seg in loc[:-1]:
        if isinstance(seg, int) or model is None or seg not in getattr(model, "model_fields", {}):
            continue
        model = _inner_model(model.model_fields[seg].annotation)
    return model


def _inner_model(annotation):
    if isinstance(annotation, type) and hasattr(annotation, "model_fields"):
        return annotation
    for arg in typing.get_args(annotation):
        found = _inner_model(arg)
        if found is not None:
            return found
    return None


def suggestion(key: str, valid) -> str:
    """' (did you mean X?)' for the closest valid key, '' when none is close."""
    valid = list(valid)
    lower = {v.lower(): v for v in valid}
    if key.lower() in lower:
        return f" (did you mean {lower[key.lower()]}?)"
    close = difflib.get_close_matches(key, valid, n=1, cutoff=0.6)
    return f" (did you mean {close[0]}?)" if close else ""


def spec_error(errors: list[dict], data: dict, model, source: str) -> InputError:
    """One InputError for pydantic's errors: unknown keys first (with a suggestion), then
    wrong types, then missing keys."""
    order = {"extra_forbidden": 0, "missing": 2}
    first = sorted(errors, key=lambda e: order.get(e["type"], 1))[0]
    loc = first["loc"]
    field = key_path(loc, data)
    if first["type"] == "extra_forbidden":
        holder = _model_at(model, loc)
        valid = list(getattr(holder, "model_fields", {}))
        key = str(loc[-1])
        return InputError(
            field,
            f"is not a known key in {source}{suggestion(key, valid)}",
            f"{FIX_FORMAT}; valid keys here: {', '.join(valid)}" if valid else FIX_FORMAT,
        )
    if first["type"] == "missing":
        return InputError(field, f"is required in {source} but missing", "add it")
    if first["type"] == "finite_number":
        return InputError(field, f"is {describe(first.get('input'))}, not a finite number", "give a finite number")
    expected = _EXPECTED.get(first["type"])
    if expected is None:
        return InputError(
            field, f"{first['msg']} (got {describe(first.get('input'))})", "give a value of the right type"
        )
    return InputError(field, f"is {describe(first.get('input'))}, expected {expected}", f"give {expected}")


# -- semantic checks (after the schema) -----------------------------------------------------------


class _Checker:
    """Walks the raw TOML data of a validated case; raises the first problem found."""

    def __init__(self, data: dict, kind: str):
        self.data, self.kind = data, kind

    def path(self, *loc) -> str:
        return key_path(loc, self.data)

    def number(self, loc, bound: str | None = None, table: str = "") -> None:
        """A present scalar: finite, |x| <= MAX_MAGNITUDE, and > 0 / >= 0 when asked."""
        value = _get(self.data, loc)
        if value is None:
            return
        unit = unit_of(str(loc[-1]), self.kind, table)
        shown = f"{value:g}{' ' + unit if unit else ''}"
        if not math.isfinite(value):
            raise InputError(self.path(*loc), f"is {shown}, not a finite number", "give a finite number")
        if abs(value) > MAX_MAGNITUDE:
            raise InputError(
                self.path(*loc),
                f"is {shown}, beyond any physical value (|x| > {MAX_MAGNITUDE:g})",
                f"check the value and its unit ({unit or 'dimensionless'})",
            )
        if bound == ">0" and not value > 0:
            raise InputError(self.path(*loc), f"is {shown}, must be > 0", "give a value > 0")
        if bound == ">=0" and not value >= 0:
            raise InputError(self.path(*loc), f"is {shown}, must be >= 0", "give a value >= 0")

    def numbers(self, loc, table: str = "") -> None:
        """Every entry of a (nested) list of numbers is finite and not absurd."""
        value = _get(self.data, loc)
        if value is None:
            return
        unit = unit_of(str(loc[-1]), self.kind, table)
        for where, x in _flat(value):
            if not math.isfinite(x) or abs(x) > MAX_MAGNITUDE:
                what = (
                    "not a finite number"
                    if not math.isfinite(x)
                    else f"beyond any physical value (|x| > {MAX_MAGNITUDE:g})"
                )
                raise InputError(
                    self.path(*loc),
                    f"entry {where} is {x:g}{' ' + unit if unit else ''}, {what}",
                    "give finite numbers of physical size",
                )

    def matrix(self, loc, rows: int | None, cols: int | None, what: str) -> int | None:
        """A present list of lists: rectangular, ``rows`` x ``cols`` where given; returns its rows."""
        value = _get(self.data, loc)
        if value is None:
            return None
        lengths = [len(r) for r in value]
        if not value:
            raise InputError(self.path(*loc), "is empty", f"give {what}")
        if len(set(lengths)) > 1:
            bad = next(i for i, n in enumerate(lengths) if n != lengths[0])
            raise InputError(
                self.path(*loc),
                f"is ragged: row 1 has {lengths[0]} entries, row {bad + 1} has {lengths[bad]}",
                f"give rows of equal length ({what})",
            )
        if rows is not None and len(value) != rows:
            raise InputError(self.path(*loc), f"has {len(value)} rows", f"give {what}")
        if cols is not None and lengths[0] != cols:
            raise InputError(self.path(*loc), f"has {lengths[0]} columns", f"give {what}")
        return len(value)

    def vector(self, loc, size: int, what: str) -> None:
        value = _get(self.data, loc)
        if value is not None and len(value) != size:
            raise InputError(self.path(*loc), f"has {len(value)} entries", f"give {what}")

    def names(self, loc, what: str) -> None:
        """A list of names: each valid, no duplicates."""
        value = _get(self.data, loc)
        if value is None:
            return
        for name in value:
            check_name(self.path(*loc), name)
        seen = set()
        for name in value:
            if name in seen:
                raise InputError(self.path(*loc), f"names {name!r} twice", f"give every {what} its own name")
            seen.add(name)

    def element_names(self, table_loc, what: str) -> None:
        """The ``name`` of every element of an array of tables: valid and unique."""
        items = _get(self.data, table_loc) or []
        first: dict[str, int] = {}
        for i, item in enumerate(items):
            name = item.get("name")
            if name is None:
                continue
            check_name(self.path(*table_loc, i, "name"), name)
            if name in first:
                raise InputError(
                    self.path(*table_loc, i, "name"),
                    f"{name!r} is already the name of {self.path(*table_loc, first[name]).split(':')[0]}",
                    f"give every {what} its own name",
                )
            first[name] = i


def _get(data, loc):
    node = data
    for seg in loc:
        if isinstance(node, dict) and seg in node:
            node = node[seg]
        elif isinstance(node, list) and isinstance(seg, int) and seg < len(node):
            node = node[seg]
        else:
            return None
    return node


def _flat(value, where: tuple = ()):
    """(position, number) of every number of a nested list: position '3' or '(2, 1)', 1-based."""
    if isinstance(value, list):
        for i, v in enumerate(value):
            yield from _flat(v, where + (i + 1,))
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        yield (str(where[0]) if len(where) == 1 else str(where) if where else "1"), float(value)


def check_case(data: dict) -> None:
    """The checks a schema cannot make, on the raw data of a case that passed the schema."""
    kind = "damper" if "damper" in data else "structure"
    c = _Checker(data, kind)
    check_name(c.path("name"), data.get("name", "case"))
    c.number(("period_s",), ">0")
    if kind == "damper":
        _check_damper(c, data)
    else:
        _check_structure(c, data)
    _check_excitation(c, data, kind)
    _check_run(c, data)


def _check_damper(c: _Checker, data: dict) -> None:
    c.number(("damper", "mass_kg"), ">0")
    c.number(("damper", "inertia_kg_m2"), ">0")
    c.number(("damper", "centrifugal_force_N"), ">=0")
    c.number(("damper", "centrifugal_angle_deg"))
    c.element_names(("damper", "platforms"), "platform")
    for i, _ in enumerate(data["damper"].get("platforms", [])):
        c.number(("damper", "platforms", i, "angle_deg"))
    c.element_names(("damper", "contacts"), "contact")
    for i, _ in enumerate(data["damper"].get("contacts", [])):
        c.vector(("damper", "contacts", i, "position_mm"), 2, "[a, b]: 2 coordinates [mm]")
        c.numbers(("damper", "contacts", i, "position_mm"))
        for key in ("normal_stiffness_N_per_um", "tangential_stiffness_N_per_um"):
            c.number(("damper", "contacts", i, key), ">0")
        c.number(("damper", "contacts", i, "friction_coefficient"), ">=0")


def _check_structure(c: _Checker, data: dict) -> None:
    s = data.get("structure", {})
    n = c.matrix(("structure", "mass_kg"), None, None, "a square n x n mass matrix")
    if n is None:  # the matrices come from files (mass_file_kg): checked when read (slipstep.casefile.case)
        return
    c.matrix(("structure", "mass_kg"), n, n, f"a square {n} x {n} matrix (one row per DOF)")
    for key in ("mass_kg", "damping_N_s_per_m", "stiffness_N_per_m"):
        c.matrix(("structure", key), n, n, f"a {n} x {n} matrix, like mass_kg")
        c.numbers(("structure", key))
    c.vector(("structure", "constant_force_N"), n, f"{n} forces, one per DOF")
    c.numbers(("structure", "constant_force_N"))
    c.vector(("structure", "dof_names"), n, f"{n} names, one per DOF")
    c.vector(("structure", "dof_units"), n, f"{n} units, one per DOF")
    c.names(("structure", "dof_names"), "DOF")
    for unit in s.get("dof_units") or []:
        check_name(c.path("structure", "dof_units"), unit)
    c.names(("motion_names",), "motion component")
    m = len(data.get("motion_names") or [])
    c.element_names(("contacts",), "contact")
    for i, contact in enumerate(data.get("contacts") or []):
        rows = c.matrix(("contacts", i, "dof_gather"), None, n, f"{n} columns, one per DOF")
        c.numbers(("contacts", i, "dof_gather"))
        if "motion_gather" in contact:
            c.matrix(
                ("contacts", i, "motion_gather"),
                rows,
                m,
                f"the rows of dof_gather and {m} column(s), one per component of motion_names",
            )
            c.numbers(("contacts", i, "motion_gather"))
        kt = contact.get("tangential_stiffness_N_per_m")
        if isinstance(kt, list):
            c.numbers(("contacts", i, "tangential_stiffness_N_per_m"))
            for x in kt:
                if not x > 0:
                    raise InputError(
                        c.path("contacts", i, "tangential_stiffness_N_per_m"),
                        f"holds {x:g} N/m, must be > 0",
                        "give values > 0",
                    )
        else:
            c.number(("contacts", i, "tangential_stiffness_N_per_m"), ">0")
        c.number(("contacts", i, "normal_stiffness_N_per_m"), ">0")
        c.number(("contacts", i, "friction_coefficient"), ">=0")
        c.number(("contacts", i, "normal_offset_m"))


def _components(data: dict, kind: str, table: str) -> list[str] | None:
    if kind == "damper":
        return [f"{p['name']}.{ax}" for p in data["damper"].get("platforms", []) for ax in ("x", "y")]
    if table.startswith("force"):
        s = data.get("structure", {})
        names = s.get("dof_names")
        if not names and "mass_kg" not in s and ("mass_file_kg" in s or "file" in s):
            return None  # the DOFs of a matrix file: checked when it is read (slipstep.casefile.case)
        n = len(s.get("mass_kg") or [])
        return list(names) if names else [f"x{i}" for i in range(n)]
    return list(data.get("motion_names") or [])


def _check_excitation(c: _Checker, data: dict, kind: str) -> None:
    for table in ("motion", "force", "motion_table", "force_table"):
        items = data.get(table) or []
        if items and kind == "damper" and table.startswith("force"):
            raise InputError(
                c.path(table, 0),
                f"[[{table}]] is not supported for [damper] cases",
                "drive the damper through platform motions ([[motion]], [[motion_table]])",
            )
        components = _components(data, kind, table)
        seen: dict = {}
        for i, item in enumerate(items):
            comp = item.get("component")
            check_name(c.path(table, i, "component"), comp)
            if components is not None and comp not in components:
                if not components and table.startswith("motion"):
                    raise InputError(
                        c.path(table, i, "component"),
                        f"{comp!r} is not a prescribed motion component: motion_names is empty",
                        "list the prescribed motion components in motion_names (top level)",
                    )
                raise InputError(
                    c.path(table, i, "component"),
                    f"{comp!r} is not a known component{suggestion(comp, components)}",
                    f"use one of {components}",
                )
            if table in ("motion", "force"):
                c.number((table, i, "frequency_Hz"), ">0")
                c.number((table, i, "amplitude"), table=table)
                c.number((table, i, "phase_deg"))
                key = (comp, item.get("frequency_Hz"))
                what = f"{comp!r} at {item.get('frequency_Hz'):g} Hz"
            else:
                c.numbers((table, i, "times_s"))
                c.numbers((table, i, "values"), table=table)
                times, values = item.get("times_s", []), item.get("values", [])
                if len(values) != len(times):
                    raise InputError(
                        c.path(table, i, "values"),
                        f"has {len(values)} values for {len(times)} times",
                        "give one value per time",
                    )
                if len(times) < 2 or any(b <= a for a, b in zip(times, times[1:])):
                    raise InputError(
                        c.path(table, i, "times_s"),
                        "must hold at least 2 strictly increasing times",
                        "sort the table and remove repeated times",
                    )
                key, what = comp, f"{comp!r}"
            if key in seen:
                raise InputError(
                    c.path(table, i, "component"),
                    f"{what} is already given by [[{table}]] {seen[key] + 1}",
                    "give each component"
                    + (" and frequency" if table in ("motion", "force") else "")
                    + " once (merge the two entries)",
                )
            seen[key] = i


def _check_run(c: _Checker, data: dict) -> None:
    run = data.get("run") or {}
    if "method" in run:
        from slipstep.methods.registry import get_method

        check_name(c.path("run", "method"), run["method"])
        try:
            get_method(run["method"])
        except InputError as exc:
            raise InputError(c.path("run", "method"), exc.problem, exc.fix) from None
    for key in ("periods", "duration_s", "step_ratio"):
        c.number(("run", key), ">0")
    c.number(("run", "ramp_time_s"), ">=0")
    c.number(("run", "tolerance"), ">0")
    if "tolerance" in run and run["tolerance"] >= 1:
        raise InputError(
            c.path("run", "tolerance"), f"is {run['tolerance']:g}", "give a small relative tolerance (e.g. 1e-11)"
        )
    if "step_rule" in run:
        from slipstep.methods.options import STEP_RULES

        if run["step_rule"] not in STEP_RULES:
            raise InputError(
                c.path("run", "step_rule"), f"is {run['step_rule']!r}", "use 'accuracy' or 't-min' (or leave it out)"
            )
    if "steps_per_period" in run and run["steps_per_period"] < 1:
        raise InputError(c.path("run", "steps_per_period"), f"is {run['steps_per_period']}", "give a whole number >= 1")
    save = run.get("save") or {}
    if "every" in save and save["every"] < 1:
        raise InputError(c.path("run", "save", "every"), f"is {save['every']}", "give a whole number of steps >= 1")
    c.number(("run", "save", "last_periods"), ">0")
    c.numbers(("run", "save", "times_s"))
    for key in ("dofs", "contacts", "response"):
        for i, name in enumerate([save[key]] if isinstance(save.get(key), str) else save.get(key) or []):
            check_name(c.path("run", "save", key) + ("" if isinstance(save.get(key), str) else f"[{i + 1}]"), name)

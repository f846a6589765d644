"""The documentation cannot fall behind the code: the generated reference pages (docs/gen_pages.py)
list every key of the case-file specs with a meaning and a unit, every variable of the result and
FRF schemas, every attribute and coordinate of a real run, every registered method and scheme,
every CLI command and every module; the start page reaches the three pages a new user looks for
first; the Python examples of the hand-written pages run.

(The site itself is built by CI: ``mkdocs build --strict``, which also fails on broken links.)
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _load(name):
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, DOCS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


gen = _load("gen_pages")


@pytest.fixture(scope="module")
def samples():
    return gen.sample_results()


@pytest.fixture(scope="module")
def pages(samples):
    return gen.all_pages(samples)


def _section(page: str, start: str, end: str | None = None) -> str:
    text = page.split(start, 1)[1]
    return text.split(end, 1)[0] if end else text


def _rows(section: str) -> dict[str, list[str]]:
    """{key: cells} of the Markdown table rows in ``section`` whose first cell is `code`."""
    rows = {}
    for line in section.splitlines():
        m = re.match(r"^\| `([^`]+)` \|(.*)\|$", line)
        if m:
            rows[m.group(1)] = [c.strip() for c in m.group(2).split(" | ")]
    return rows


def test_every_spec_key_has_a_meaning():
    missing = [q for q in gen.all_spec_keys() if q not in gen.KEY_DOCS]
    assert not missing, f"give these case-file keys a Field(description=...) in slipstep.casefile: {missing}"


@pytest.mark.parametrize("kind", [k for k, _, _, _ in gen.case_kinds()])
def test_case_file_page_lists_every_key_of_each_kind_with_its_unit(pages, kind):
    page = pages["reference/case_file.md"]
    root = {k: r for k, r, _, _ in gen.case_kinds()}[kind]
    section = _section(page, f"{{ #{kind}-case }}").split("\n## ", 1)[0]
    expected = [(t, k, q) for t, k, q, _, is_table in gen.key_rows(root, skip=gen.KIND_SKIPS[kind]) if not is_table]
    assert len(expected) > 10
    for table, key, qual in expected:
        heading = f"### `{table}`" if table else "### Top level"
        block = _section(section, heading).split("\n### ", 1)[0]
        cells = _rows(block).get(key)
        assert cells is not None, f"{kind}: {table} {key} missing from the case-file page"
        unit, meaning = cells[2], cells[3]
        assert meaning and "undocumented" not in meaning, (table, key)
        suffix_unit = gen.unit_of_key(key)
        if suffix_unit is not None:  # a key that names its unit shows exactly that unit
            assert unit.split(" (")[0] == suffix_unit, (table, key, unit)
        else:
            assert unit, (table, key)
    # a kind lists only its own tables: the damper kind never shows [structure], and so on
    assert ("### `[structure]`" in section) == (kind == "structure")
    assert ("### `[damper]`" in section) == (kind == "damper")


def test_case_file_page_lists_every_contact_law(pages):
    contact = pytest.importorskip("slipstep.model.contact")
    if not hasattr(contact, "CONTACT_LAWS"):
        pytest.skip("no contact-law table in this tree")
    rows = _rows(_section(pages["reference/case_file.md"], "{ #contact-laws }", "## Complete example"))
    assert set(rows) == set(contact.CONTACT_LAWS)
    for name, law in contact.CONTACT_LAWS.items():
        assert rows[name][1] == law.bounds and rows[name][2] == law.description


def test_unit_suffixes():
    assert gen.unit_of_key("normal_stiffness_N_per_um") == "N/um"
    assert gen.unit_of_key("damping_N_s_per_m") == "N s/m"
    assert gen.unit_of_key("inertia_kg_m2") == "kg m^2"
    assert gen.unit_of_key("centrifugal_force_N") == "N"
    assert gen.unit_of_key("times_s") == "s"
    assert gen.unit_of_key("friction_coefficient") is None
    assert gen.unit_of_key("rayleigh_alpha_per_s") == "1/s" and gen.unit_of_key("rayleigh_beta_s") == "s"
    assert gen.unit_of_key("density_kg_per_m3") == "kg/m^3" and gen.unit_of_key("area_mm2") == "mm^2"


def test_results_page_is_the_schema_with_units(pages):
    from slipstep.output.results import SCHEMA

    rows = _rows(_section(pages["reference/results.md"], "## Variables", "## Dimensions"))
    assert set(rows) == set(SCHEMA)
    for name, (dims, units, long_name) in SCHEMA.items():
        assert rows[name] == [f"({', '.join(dims)})", units, long_name]


def test_every_attribute_and_coordinate_of_a_run_is_documented(pages, samples):
    attrs = gen.result_attributes(samples)
    assert {"status", "steps", "solves", "dt_s", "t_min_s"} <= set(attrs)
    missing = [a for a in attrs if a not in gen.ATTR_DOCS]
    assert not missing, f"add these result attributes to ATTRS in slipstep.output.results: {missing}"
    coords = [c for ds in samples for c in ds.coords]
    missing = sorted({c for c in coords if c not in gen.COORD_DOCS})
    assert not missing, f"add these coordinates to COORDS in slipstep.output.results: {missing}"
    page = pages["reference/results.md"]
    assert set(_rows(_section(page, "## Attributes", "## Reading"))) == set(attrs)
    coord_rows = _rows(_section(page, "## Dimensions and coordinates", "## Attributes"))
    assert set(coord_rows) == set(coords)
    for name, cells in coord_rows.items():  # a coordinate's unit attribute wins over the table
        unit = samples[0][name].attrs.get("units")
        if unit:
            assert cells[1] == unit


def test_frf_page_is_the_frf_schema(pages):
    schema = pytest.importorskip("slipstep.output.frf_schema")
    rows = _rows(_section(pages["reference/frequency_response.md"], "## Variables", "## Attributes"))
    assert {name: [f"({', '.join(d)})", u, m] for name, (d, u, m) in schema.FRF_SCHEMA.items()} == rows


def test_sweep_summary_page_lists_every_summary_field(pages):
    summary = pytest.importorskip("slipstep.post.summary")
    rows = _rows(pages["reference/sweep_summary.md"])
    for base, (unit, _) in summary.FIELDS.items():
        per = summary.dimension_of(base)
        key = f"{base}[{per}]" if per else base
        assert key in rows and rows[key][1] == unit, key
        assert rows[key][3] != "-", key  # a value computed on the paper case


def test_methods_page_lists_every_method_and_scheme(pages):
    from slipstep.integrators import INTEGRATORS
    from slipstep.methods.registry import ALIASES, METHODS

    page = pages["reference/methods.md"]
    rows = _rows(_section(page, "# Methods", "## Which one"))
    for name, method in METHODS.items():
        assert name in rows and rows[name][0] == method.paper_label and rows[name][3] == method.description
        assert name in gen.METHOD_ADVICE and rows[name][2] == gen.METHOD_ADVICE[name]  # the advice column
    for alias, name in ALIASES.items():
        assert f"`{alias}`" in rows[name][1]
    schemes = _rows(_section(page, "## Time-integration schemes", "## The advisor"))
    assert set(schemes) == set(INTEGRATORS)
    assert "Recommendation:" in page  # the advisor's report on the paper case


def test_cli_page_lists_every_command_and_option(pages):
    page = pages["reference/cli.md"]
    commands = gen.cli_commands()
    assert {"run", "compare", "cases", "methods"} <= set(commands)
    group = gen._cli_command()
    for name in commands:
        assert f"## `slipstep {name}`" in page
        block = _section(page, f"## `slipstep {name}`").split("\n## ", 1)[0]
        for param in group.commands[name].params:
            if param.name != "help" and param.param_type_name == "option":
                assert f"`{param.opts[0]}`" in block, (name, param.opts)


def test_every_module_has_an_api_page_in_the_nav(pages):
    modules = gen.module_names()
    assert {"slipstep", "slipstep.casefile.case", "slipstep.methods.simulation", "slipstep.output.results"} <= set(
        modules
    )
    for module in modules:
        assert pages[f"api/{module}.md"].startswith(f"::: {module}")

    def leaves(nav):
        for item in nav:
            for value in item.values() if isinstance(item, dict) else [item]:
                yield from leaves(value) if isinstance(value, list) else [value]

    assert sorted(leaves(gen.api_nav())) == sorted(["api/index.md"] + [f"api/{m}.md" for m in modules])


def test_equation_index_finds_the_docstrings_that_cite_the_paper():
    index = gen.equation_index()
    assert "slipstep.methods.step_control.state_t_min" in index["paper Eq.", 8]  # T_min (paper Eq. 8)
    assert "slipstep.study.advise.inertia_ratio" in index["paper Eq.", 9]
    assert all(not part.startswith("_") for objs in index.values() for o in objs for part in o.split("."))


def test_start_page_reaches_methods_damper_keys_and_result_variables_in_one_click(pages):
    index = (DOCS / "index.md").read_text()
    for target in ("reference/methods.md", "reference/case_file.md#damper-case", "reference/results.md"):
        assert f"]({target})" in index, target
    assert "{ #damper-case }" in pages["reference/case_file.md"]


def _python_blocks():
    """The Python blocks of the site's own pages (physics.md and integrators.md show fragments)."""
    for path in [DOCS / "index.md", DOCS / "getting_started.md", *sorted(DOCS.glob("guide/*.md"))]:
        for i, block in enumerate(re.findall(r"```python\n(.*?)```", path.read_text(), flags=re.S)):
            yield pytest.param(block, id=f"{path.relative_to(DOCS)}-{i}")


@pytest.mark.parametrize("code", list(_python_blocks()))
def test_python_examples_of_the_pages_run(code, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "<docs>", "exec"), {"__name__": "__docs__"})


def test_api_reference_sees_the_lazily_exported_public_names():
    """The top-level API page is rendered from a static analysis of the package (griffe); the
    package exports its names lazily, so docs/griffe_roles.py adds them: every name of
    ``slipstep.__all__`` must resolve to its definition."""
    griffe = pytest.importorskip("griffe")
    import slipstep

    roles = _load("griffe_roles")
    extensions = griffe.load_extensions(roles.LazyExports, roles.SphinxRoles)
    pkg = griffe.load("slipstep", search_paths=[str(ROOT / "src")], extensions=extensions)
    for name in slipstep.__all__:
        if name.startswith("__"):
            continue
        assert name in pkg.members, name
        obj = pkg[name]
        target = obj.final_target if obj.is_alias else obj  # an alias resolves to its definition
        assert target.path.startswith("slipstep."), name
    assert pkg["run"].final_target.path == "slipstep.methods.simulation.run"
    # Sphinx roles became autorefs links
    assert (
        "[`RunOptions`][slipstep.methods.options.RunOptions]" in pkg["run"].docstring.value
    )  # (moved from simulation)


def test_sweep_file_of_the_guide_is_a_valid_spec():
    spec_module = pytest.importorskip("slipstep.sweep.spec")
    try:
        import tomllib
    except ImportError:  # Python 3.10
        import tomli as tomllib

    text = (DOCS / "guide" / "forced_response.md").read_text()
    block = text.split("## Design sweeps", 1)[1].split("```toml\n", 1)[1].split("```", 1)[0]
    spec = spec_module.spec_from_dict(tomllib.loads(block), source="guide")
    spec_module.validate(spec)
    assert [p.key for p in spec.parameters] == ["damper.centrifugal_force_N", "motion.1.amplitude"]
    assert len(spec_module.parameter_values(spec.parameters[1])) == 12

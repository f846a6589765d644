"""The README stays true: its set-up commands are the ones .ci/run executes. What it used to hold
is checked where it now lives: the schema table of the generated result page is
slipstep.output.results.SCHEMA, the TOML example of the case-file guide runs."""

from __future__ import annotations

import re
from pathlib import Path

import slipstep as ss
from docs_pages import gen_pages
from slipstep.output.results import SCHEMA

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
CASE_FILES = (ROOT / "docs" / "guide" / "case_files.md").read_text()


def test_schema_table_is_the_declared_schema():
    page = gen_pages().results_reference()  # the site's result page (reference/results.md)
    variables = page.split("## Variables")[1].split("\n## ")[0]
    rows = re.findall(r"^\| `(\w+)` \| \(([^)]*)\) \| ([^|]+) \|", variables, flags=re.M)
    table = {name: (tuple(d.strip() for d in dims.split(",")), units.strip()) for name, dims, units in rows}
    assert {name: (dims, units) for name, (dims, units, _) in SCHEMA.items()} == table


def test_structure_toml_example_loads_and_runs(tmp_path):
    block = CASE_FILES.split("## Kind 2")[1].split("```toml\n")[1].split("```")[0]
    path = tmp_path / "example.toml"
    path.write_text(block)
    system, spec = ss.load_case(path)
    assert system.structure.dof_names == ("x", "y") and system.contact_names == ("C1",)
    ds = ss.run(system, "quasi-static", periods=1, steps_per_period=50)
    assert ds.attrs["status"] == "OK" and ds.attrs["steps"] == 50


def _ci_steps() -> list[str]:
    """The commands .ci/run executes after activating its fresh venv (pip flags dropped)."""
    lines = (ROOT / ".ci" / "run").read_text().split(". .venv/bin/activate\n", 1)[1].splitlines()
    steps = []
    for line in lines:
        line = line.strip()
        if not line or line.startswith("#") or "--upgrade pip" in line:
            continue
        steps.append(re.sub(r"^python -m pip install -q ", "pip install ", line))
    return steps


def test_readme_starts_with_the_two_commands_and_ci_runs_the_test_command():
    commands = re.findall(r"```bash\n(.*?)\n```", README, flags=re.S)
    assert commands[0].endswith("pip install -e . && slipstep compare paper")
    readme_steps = commands[1].split(" && ")
    assert readme_steps[:2] == ["python3 -m venv .venv", ". .venv/bin/activate"]
    assert readme_steps[2:] == _ci_steps()
    assert 'pip install -e ".[test,docs]"' in readme_steps and "python -m pytest -q" in readme_steps
    assert README.index("slipstep compare paper") < README.index("## What slipstep is")

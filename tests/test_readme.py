"""The README stays true: its schema table is slipstep.results.SCHEMA, its TOML example runs,
its set-up commands are the ones .ci/run executes."""

from __future__ import annotations

import re
from pathlib import Path

import slipstep as ss
from slipstep.results import SCHEMA

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def test_schema_table_is_the_declared_schema():
    rows = re.findall(r"^\| `(\w+)` \| \(([^)]*)\) \| ([^|]+) \|", README, flags=re.M)
    table = {name: (tuple(d.strip() for d in dims.split(",")), units.strip()) for name, dims, units in rows}
    assert {name: (dims, units) for name, (dims, units, _) in SCHEMA.items()} == table


def test_structure_toml_example_loads_and_runs(tmp_path):
    block = README.split("### Kind 2")[1].split("```toml\n")[1].split("```")[0]
    path = tmp_path / "example.toml"
    path.write_text(block)
    system, spec = ss.load_case(path)
    assert system.structure.dof_names == ("x", "y") and system.contact_names == ("C1",)
    ds = ss.run(system, "quasi-static", periods=1, steps_per_period=50)
    assert ds.attrs["status"] == "OK" and ds.attrs["steps"] == 50


def test_readme_starts_with_the_two_commands_and_ci_runs_the_test_command():
    commands = re.findall(r"```bash\n(.*?)\n```", README, flags=re.S)
    assert commands[0].endswith("pip install -e . && slipstep compare paper")
    assert commands[1].endswith('pip install -e ".[test]" && python -m pytest -q')
    ci = (ROOT / ".ci" / "run").read_text()
    assert "python -m pytest -q" in ci and '-e ".[test]"' in ci
    assert README.index("slipstep compare paper") < README.index("## What slipstep is")

"""Bad input -> InputError naming the field (Python API), exit code 2 with one red line and no
traceback (CLI). Every row of docs/bad_input.md is a case here, and the test
``test_docs_table_is_exact`` checks that the documented message is the one produced.

Run ``python tests/test_bad_input.py`` to print the Markdown table for docs/bad_input.md.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from typer.testing import CliRunner

import slipstep as ss
from slipstep.cli.main import app
from slipstep.casefile.case import CASES_DIR

DOCS = Path(__file__).resolve().parents[1] / "docs" / "bad_input.md"
PAPER = (CASES_DIR / "paper.toml").read_text()

# A valid general-structure case: 2 DOFs (x tangential, y normal), one 2D contact, base motion.
STRUCTURE = """\
name = "two-dof"
motion_names = ["base.x"]

[structure]
dof_names = ["x", "y"]
mass_kg = [[1.0, 0.0], [0.0, 1.0]]
stiffness_N_per_m = [[1.0e4, 0.0], [0.0, 0.0]]
constant_force_N = [0.0, 10.0]

[[contacts]]
name = "C1"
dof_gather = [[1.0, 0.0], [0.0, 1.0]]
motion_gather = [[1.0], [0.0]]
normal_stiffness_N_per_m = 1.0e6
tangential_stiffness_N_per_m = 1.0e6
friction_coefficient = 0.3

[[motion]]
component = "base.x"
amplitude = 1.0e-5
frequency_Hz = 50.0
"""


def _sparse_chain(n: int):
    """A sparse fixed-free chain with one Jenkins contact (the banded backend's input)."""
    import scipy.sparse as sp

    K = sp.diags([np.full(n, 2.0), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr") * 1e5
    A = sp.csr_matrix(([1.0], ([0], [n // 2])), shape=(2, n))
    contact = ss.ContactElement("J", A, 1e5, 1e5, 0.3, normal_offset=1e-5)
    amp = np.zeros(n)
    amp[-1] = 1.0
    force = ss.Signal(tuple(f"x{i}" for i in range(n)), (ss.Harmonic(50.0, amp),))
    return ss.System(ss.Structure(sp.identity(n, format="csr"), None, K), (contact,), ss.Excitation(force=force))


def edit(text: str, old: str, new: str) -> str:
    """Replace the first ``old`` (which must exist) by ``new``."""
    assert old in text, old
    return text.replace(old, new, 1)


def two_dof_contact(**changes):
    kwargs = dict(
        name="C1",
        dof_gather=[[1.0, 0.0], [0.0, 1.0]],
        tangential_stiffness=1e6,
        normal_stiffness=1e6,
        friction_coefficient=0.3,
    )
    kwargs.update(changes)
    return ss.ContactElement(**kwargs)


def paper_damper(contact_platform="right", motion_component="right.x"):
    deg = math.radians
    return ss.rigid_damper(
        mass=0.012,
        inertia=1.2e-7,
        platforms=[ss.Platform("left", deg(45)), ss.Platform("right", deg(-45))],
        contacts=[
            ss.DamperContact("P1", "left", (-3.914e-3, -0.414e-3), 13e6, 13e6, 0.4),
            ss.DamperContact("P3", contact_platform, (2.5e-3, 1.0e-3), 26e6, 26e6, 0.25),
        ],
        centrifugal_force=200.0,
        motion=ss.Signal((motion_component,), (ss.Harmonic(200.0, [25e-6]),)),
    )


def _foreign_netcdf(directory: Path) -> None:
    """A valid netCDF-4 file that is not a slipstep result."""
    import xarray as xr

    xr.Dataset({"temperature": ("x", np.arange(3.0))}).to_netcdf(directory / "foreign.nc", engine="h5netcdf")


def _external_storage_netcdf(directory: Path) -> None:
    """A netCDF-4 file whose dataset is stored in an external file (here the case file itself)."""
    import h5py

    secret = directory / "secret.txt"
    secret.write_bytes(b"root:x:0:0:root:/root:/bin/bash\n" * 4)
    with h5py.File(directory / "crafted.nc", "w") as f:
        f.create_dataset(
            "displacement",
            shape=(secret.stat().st_size,),
            dtype="u1",
            external=[(str(secret), 0, secret.stat().st_size)],
        )


def _netcdf3(directory: Path) -> None:
    import xarray as xr

    (directory / "old.nc").write_bytes(xr.Dataset({"a": ("x", [1.0, 2.0])}).to_netcdf(engine="scipy"))


def _remove_motion_names(text: str) -> str:
    text = edit(text, 'motion_names = ["base.x"]\n', "")
    return edit(text, "motion_gather = [[1.0], [0.0]]\n", "")


@dataclass(frozen=True)
class Bad:
    id: str
    input: str  # what the user did, for the docs table
    field: str  # the field the message must name
    api: Callable[[], object] | None = None  # Python call that must raise InputError
    toml: str | None = None  # case file text: load_case (+ Simulation) must raise, CLI `run` exits 2
    cli: tuple[str, ...] | None = None  # CLI arguments that must exit 2
    files: tuple[tuple[str, bytes], ...] = ()  # (name, content) written to the working directory first
    setup: Callable[[Path], None] | None = None  # writes further files into the working directory


SECOND_MOTION = '[[motion]]\ncomponent = "right.x"\namplitude = 5.0\nfrequency_Hz = 200.0\n\n[run]'
MOTION_TABLE = '[[motion_table]]\ncomponent = "base.x"\ntimes_s = [0.0, 1.0]\nvalues = [0.0, 1.0e-6]\n'

CASE_FILE = "bad_case.toml"

# a case driven by a motion table only (no period) asking for the 'accuracy' step rule
TABLES_ONLY_ACCURACY = (
    STRUCTURE.split("[[motion]]")[0]
    + MOTION_TABLE
    + '\n[run]\nmethod = "piecewise-linear"\nduration_s = 0.5\nstep_rule = "accuracy"\n'
)

CASES = [
    # -- Python API: model -----------------------------------------------------------------
    Bad("negative-mass", "`Structure(mass=[[-1.0]])`", "structure.mass", api=lambda: ss.Structure(mass=[[-1.0]])),
    Bad(
        "zero-mass",
        "`Structure(mass=[[1, 0], [0, 0]])` (singular M)",
        "structure.mass",
        api=lambda: ss.Structure(mass=[[1.0, 0.0], [0.0, 0.0]]),
    ),
    Bad(
        "non-symmetric-mass",
        "`Structure(mass=[[1, 0.5], [0, 1]])`",
        "structure.mass",
        api=lambda: ss.Structure(mass=[[1.0, 0.5], [0.0, 1.0]]),
    ),
    Bad(
        "nan-in-matrix",
        "`Structure(mass=I, stiffness=[[nan, 0], [0, 1]])`",
        "structure.stiffness",
        api=lambda: ss.Structure(mass=np.eye(2), stiffness=[[np.nan, 0.0], [0.0, 1.0]]),
    ),
    Bad(
        "ragged-matrix",
        "`Structure(mass=[[1.0, 0.0], [0.0]])` (ragged)",
        "structure.mass",
        api=lambda: ss.Structure(mass=[[1.0, 0.0], [0.0]]),
    ),
    Bad(
        "gather-columns",
        "2-DOF structure, contact `dof_gather` with 3 columns",
        "contacts[C1].dof_gather",
        api=lambda: ss.System(ss.Structure(np.eye(2)), (two_dof_contact(dof_gather=[[1, 0, 0], [0, 1, 0]]),)),
    ),
    Bad(
        "gather-rows",
        "contact `dof_gather` with 4 rows",
        "contacts[C1].dof_gather",
        api=lambda: two_dof_contact(dof_gather=np.eye(4, 2)),
    ),
    Bad(
        "gather-absurd",
        "contact `dof_gather` entry 1e300",
        "contacts[C1].dof_gather",
        api=lambda: two_dof_contact(dof_gather=[[1e300, 0.0], [0.0, 1.0]]),
    ),
    Bad(
        "motion-gather-columns",
        "`motion_gather` with 2 columns for 1 motion component",
        "contacts[C1].motion_gather",
        api=lambda: ss.System(
            ss.Structure(np.eye(2)),
            (two_dof_contact(motion_gather=[[1.0, 0.0], [0.0, 0.0]]),),
            motion_names=("base.x",),
        ),
    ),
    Bad(
        "duplicate-motion-names",
        "`System(..., motion_names=('base.x', 'base.x'))`",
        "motion_names",
        api=lambda: ss.System(
            ss.Structure(np.eye(2)),
            (two_dof_contact(motion_gather=[[1.0, 0.0], [0.0, 0.0]]),),
            motion_names=("base.x", "base.x"),
        ),
    ),
    Bad(
        "control-character-name",
        "`ContactElement('P1\\x1b[2J', ...)` in a System (an ANSI escape)",
        "contacts",
        api=lambda: ss.System(ss.Structure(np.eye(2)), (two_dof_contact(name="P1\x1b[2J"),)),
    ),
    Bad(
        "negative-friction",
        "`ContactElement(..., friction_coefficient=-0.1)`",
        "contacts[C1].friction_coefficient",
        api=lambda: two_dof_contact(friction_coefficient=-0.1),
    ),
    Bad(
        "bool-friction",
        "`ContactElement(..., friction_coefficient=True)`",
        "contacts[C1].friction_coefficient",
        api=lambda: two_dof_contact(friction_coefficient=True),
    ),
    Bad(
        "zero-normal-stiffness",
        "`ContactElement(..., normal_stiffness=0)`",
        "contacts[C1].normal_stiffness",
        api=lambda: two_dof_contact(normal_stiffness=0.0),
    ),
    Bad("zero-period", "`Excitation(period=0)`", "excitation.period", api=lambda: ss.Excitation(period=0.0)),
    Bad(
        "unknown-motion-component",
        "`rigid_damper(..., motion=Signal(('right.z',), ...))`",
        "motion.component",
        api=lambda: paper_damper(motion_component="right.z"),
    ),
    Bad(
        "unknown-platform",
        "`DamperContact('P3', 'middle', ...)` with platforms left/right",
        "damper.contacts[P3].platform",
        api=lambda: paper_damper(contact_platform="middle"),
    ),
    # -- Python API: run options -----------------------------------------------------------
    Bad(
        "api-unknown-option",
        "`ss.run(system, time_step=1e-5)`",
        "options",
        api=lambda: ss.run(ss.load_system("paper"), time_step=1e-5),
    ),
    Bad(
        "api-unknown-method",
        "`ss.run(system, 'runge-kutta')`",
        "method",
        api=lambda: ss.run(ss.load_system("paper"), "runge-kutta"),
    ),
    Bad(
        "api-negative-step-ratio",
        "`ss.run(system, step_ratio=-1)`",
        "step_ratio",
        api=lambda: ss.run(ss.load_system("paper"), step_ratio=-1.0),
    ),
    Bad(
        "api-zero-periods",
        "`ss.run(system, periods=0)`",
        "periods",
        api=lambda: ss.run(ss.load_system("paper"), periods=0),
    ),
    Bad(
        "api-bool-periods",
        "`ss.run(system, periods=True)`",
        "periods",
        api=lambda: ss.run(ss.load_system("paper"), periods=True),
    ),
    Bad(
        "api-text-periods",
        "`ss.run(system, periods='3')` (text for a number)",
        "periods",
        api=lambda: ss.run(ss.load_system("paper"), periods="3"),
    ),
    Bad(
        "api-memory",
        "`ss.run(system, periods=1e6)` (2 GB of outputs; limit 1 GB)",
        "periods",
        api=lambda: ss.run(ss.load_system("paper"), periods=1e6, max_memory=2**30),
    ),
    Bad(
        "api-bad-max-memory",
        "`ss.run(system, max_memory='lots')`",
        "max_memory",
        api=lambda: ss.run(ss.load_system("paper"), max_memory="lots"),
    ),
    Bad("api-not-a-system", "`ss.run('paper')` (a name, not a System)", "system", api=lambda: ss.run("paper")),
    Bad(
        "api-result-not-a-path",
        "`ss.load_result(3)` (a number: open(3) would read file descriptor 3)",
        "result",
        api=lambda: ss.load_result(3),
    ),
    Bad(
        "api-foreign-result",
        "`ss.load_result('foreign.nc')` (a netCDF file, not a result)",
        "result",
        api=lambda: ss.load_result("foreign.nc"),
        setup=_foreign_netcdf,
    ),
    Bad(
        "api-external-storage",
        "`ss.load_result('crafted.nc')` (HDF5 external storage of another file)",
        "result",
        api=lambda: ss.load_result("crafted.nc"),
        setup=_external_storage_netcdf,
    ),
    # -- TOML case files (load_case raises; `slipstep run FILE` exits 2) --------------------
    Bad(
        "toml-unknown-key",
        "`[damper]` with `damping_ratio = 0.01`",
        "[damper] damping_ratio",
        toml=edit(PAPER, "mass_kg = 0.012", "mass_kg = 0.012\ndamping_ratio = 0.01"),
    ),
    Bad(
        "toml-misspelt-key",
        "`friction_coeficient = 0.40` at P1 (misspelt)",
        "[[damper.contacts]] 1 (P1): friction_coeficient",
        toml=edit(PAPER, "friction_coefficient = 0.40", "friction_coeficient = 0.40"),
    ),
    Bad("toml-misspelt-table", "`[dampr]` for `[damper]`", "[dampr]", toml=edit(PAPER, "[damper]\n", "[dampr]\n")),
    Bad(
        "toml-unit-of-other-kind",
        "`normal_stiffness_N_per_m` in a `[damper]` contact",
        "[[damper.contacts]] 1 (P1): normal_stiffness_N_per_m",
        toml=edit(PAPER, "normal_stiffness_N_per_um = 13.0", "normal_stiffness_N_per_m = 13.0e6"),
    ),
    Bad(
        "toml-missing-key",
        "`[damper]` without `inertia_kg_m2`",
        "[damper] inertia_kg_m2",
        toml=edit(PAPER, "inertia_kg_m2 = 1.2e-7", ""),
    ),
    Bad(
        "toml-wrong-type",
        '`mass_kg = "twelve grams"`',
        "[damper] mass_kg",
        toml=edit(PAPER, "mass_kg = 0.012", 'mass_kg = "twelve grams"'),
    ),
    Bad(
        "toml-bool-for-number",
        "`mass_kg = true`",
        "[damper] mass_kg",
        toml=edit(PAPER, "mass_kg = 0.012", "mass_kg = true"),
    ),
    Bad(
        "toml-negative-mass",
        "`mass_kg = -0.012`",
        "[damper] mass_kg",
        toml=edit(PAPER, "mass_kg = 0.012", "mass_kg = -0.012"),
    ),
    Bad(
        "toml-nan-in-matrix",
        "`[structure] mass_kg = [[nan, 0.0], [0.0, 1.0]]`",
        "[structure] mass_kg",
        toml=edit(STRUCTURE, "mass_kg = [[1.0, 0.0]", "mass_kg = [[nan, 0.0]"),
    ),
    Bad(
        "toml-ragged-matrix",
        "`[structure] mass_kg = [[1.0, 0.0], [0.0]]`",
        "[structure] mass_kg",
        toml=edit(STRUCTURE, "mass_kg = [[1.0, 0.0], [0.0, 1.0]]", "mass_kg = [[1.0, 0.0], [0.0]]"),
    ),
    Bad(
        "toml-not-positive-definite",
        "`[structure] mass_kg = [[1.0, 0.0], [0.0, -1.0]]`",
        "[structure] mass_kg",
        toml=edit(STRUCTURE, "mass_kg = [[1.0, 0.0], [0.0, 1.0]]", "mass_kg = [[1.0, 0.0], [0.0, -1.0]]"),
    ),
    Bad(
        "toml-constant-force-size",
        "`constant_force_N = [10.0]` for 2 DOFs",
        "[structure] constant_force_N",
        toml=edit(STRUCTURE, "constant_force_N = [0.0, 10.0]", "constant_force_N = [10.0]"),
    ),
    Bad(
        "toml-zero-normal-stiffness",
        "`normal_stiffness_N_per_um = 0.0` at P1",
        "[[damper.contacts]] 1 (P1): normal_stiffness_N_per_um",
        toml=edit(PAPER, "normal_stiffness_N_per_um = 13.0", "normal_stiffness_N_per_um = 0.0"),
    ),
    Bad(
        "toml-negative-stiffness-user-unit",
        "`tangential_stiffness_N_per_um = -13.0` at P1 (the value in N/um)",
        "[[damper.contacts]] 1 (P1): tangential_stiffness_N_per_um",
        toml=edit(PAPER, "tangential_stiffness_N_per_um = 13.0", "tangential_stiffness_N_per_um = -13.0"),
    ),
    Bad(
        "toml-negative-friction",
        "`friction_coefficient = -0.25` (structure case)",
        "[[contacts]] 1 (C1): friction_coefficient",
        toml=edit(STRUCTURE, "friction_coefficient = 0.3", "friction_coefficient = -0.25"),
    ),
    Bad(
        "toml-gather-columns",
        "`dof_gather = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]` for 2 DOFs",
        "[[contacts]] 1 (C1): dof_gather",
        toml=edit(
            STRUCTURE, "dof_gather = [[1.0, 0.0], [0.0, 1.0]]", "dof_gather = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]"
        ),
    ),
    Bad(
        "toml-gather-ragged",
        "`dof_gather = [[1.0, 0.0], [0.0]]`",
        "[[contacts]] 1 (C1): dof_gather",
        toml=edit(STRUCTURE, "dof_gather = [[1.0, 0.0], [0.0, 1.0]]", "dof_gather = [[1.0, 0.0], [0.0]]"),
    ),
    Bad(
        "toml-gather-absurd",
        "`dof_gather = [[1.0e300, 0.0], [0.0, 1.0]]`",
        "[[contacts]] 1 (C1): dof_gather",
        toml=edit(STRUCTURE, "dof_gather = [[1.0, 0.0], [0.0, 1.0]]", "dof_gather = [[1.0e300, 0.0], [0.0, 1.0]]"),
    ),
    Bad(
        "toml-contact-never-closes",
        "`dof_gather = [[1.0, 0.0], [0.0, 0.0]]` (no normal motion, no interference)",
        "[[contacts]] 1 (C1): dof_gather",
        toml=edit(STRUCTURE, "dof_gather = [[1.0, 0.0], [0.0, 1.0]]", "dof_gather = [[1.0, 0.0], [0.0, 0.0]]"),
    ),
    Bad(
        "toml-unknown-motion-component",
        '`[[motion]] component = "right.z"`',
        "[[motion]] 1: component",
        toml=edit(PAPER, 'component = "right.x"', 'component = "right.z"'),
    ),
    Bad(
        "toml-no-motion-names",
        "`[[motion]]` on `base.x` without `motion_names`",
        "[[motion]] 1: component",
        toml=_remove_motion_names(STRUCTURE),
    ),
    Bad(
        "toml-empty-component",
        '`[[motion]] component = ""`',
        "[[motion]] 1: component",
        toml=edit(PAPER, 'component = "right.x"', 'component = ""'),
    ),
    Bad(
        "toml-duplicate-harmonic",
        "two `[[motion]]` on `right.x` at 200 Hz (the last would win)",
        "[[motion]] 2: component",
        toml=edit(PAPER, "[run]", SECOND_MOTION),
    ),
    Bad(
        "toml-duplicate-force",
        "two `[[force]]` on `x` at 50 Hz",
        "[[force]] 2: component",
        toml=STRUCTURE + '[[force]]\ncomponent = "x"\namplitude = 1.0\nfrequency_Hz = 50.0\n' * 2,
    ),
    Bad(
        "toml-duplicate-table",
        "two `[[motion_table]]` on `base.x`",
        "[[motion_table]] 2: component",
        toml=STRUCTURE + MOTION_TABLE * 2,
    ),
    Bad(
        "toml-table-unsorted",
        "`[[motion_table]] times_s = [1.0, 0.0]`",
        "[[motion_table]] 1: times_s",
        toml=STRUCTURE + MOTION_TABLE.replace("[0.0, 1.0]\nvalues", "[1.0, 0.0]\nvalues"),
    ),
    Bad(
        "toml-force-on-damper",
        "`[[force]]` in a `[damper]` case",
        "[[force]] 1",
        toml=edit(PAPER, "[run]", '[[force]]\ncomponent = "x_G"\namplitude = 1.0\nfrequency_Hz = 10.0\n\n[run]'),
    ),
    Bad(
        "toml-duplicate-motion-names",
        '`motion_names = ["base.x", "base.x"]` (the motion would go to the other column)',
        "motion_names",
        toml=edit(STRUCTURE, 'motion_names = ["base.x"]', 'motion_names = ["base.x", "base.x"]'),
    ),
    Bad(
        "toml-duplicate-dof-names",
        '`dof_names = ["x", "x"]`',
        "[structure] dof_names",
        toml=edit(STRUCTURE, 'dof_names = ["x", "y"]', 'dof_names = ["x", "x"]'),
    ),
    Bad(
        "toml-duplicate-platform",
        "two platforms named `left`",
        "[[damper.platforms]] 2 (left): name",
        toml=edit(PAPER, 'name = "right"                   #', 'name = "left"                   #'),
    ),
    Bad(
        "toml-duplicate-contact",
        "two contacts named `P1`",
        "[[damper.contacts]] 2 (P1): name",
        toml=edit(PAPER, 'name = "P2"', 'name = "P1"'),
    ),
    Bad(
        "toml-empty-name",
        'a contact `name = ""`',
        "[[damper.contacts]] 1: name",
        toml=edit(PAPER, 'name = "P1"', 'name = ""'),
    ),
    Bad(
        "toml-nul-in-name",
        'a contact `name = "C\\u0000"` (a NUL)',
        "[[contacts]] 1 (C\\x00): name",
        toml=edit(STRUCTURE, 'name = "C1"', 'name = "C\\u0000"'),
    ),
    Bad(
        "toml-escape-in-name",
        'the case `name = "\\u001b]0;owned\\u0007"` (an OSC escape)',
        "name",
        toml=edit(PAPER, 'name = "paper"', 'name = "\\u001b]0;owned\\u0007"'),
    ),
    Bad(
        "toml-unknown-platform",
        '`platform = "middle"` at P3',
        "[[damper.contacts]] 3 (P3): platform",
        toml=edit(PAPER, 'name = "P3"\nplatform = "right"', 'name = "P3"\nplatform = "middle"'),
    ),
    Bad(
        "toml-zero-period",
        "`period_s = 0`",
        "period_s",
        toml=edit(STRUCTURE, 'name = "two-dof"', 'name = "two-dof"\nperiod_s = 0.0'),
    ),
    Bad(
        "toml-nan-period",
        "`period_s = nan`",
        "period_s",
        toml=edit(STRUCTURE, 'name = "two-dof"', 'name = "two-dof"\nperiod_s = nan'),
    ),
    Bad(
        "toml-inf-period",
        "`period_s = inf`",
        "period_s",
        toml=edit(STRUCTURE, 'name = "two-dof"', 'name = "two-dof"\nperiod_s = inf'),
    ),
    Bad("toml-invalid-syntax", "`mass_kg = = 0.012`", "case", toml=edit(PAPER, "mass_kg = 0.012", "mass_kg = = 0.012")),
    Bad(
        "toml-run-unknown-method",
        '`[run] method = "rk4"`',
        "[run] method",
        toml=edit(PAPER, "periods = 3", 'periods = 3\nmethod = "rk4"'),
    ),
    Bad(
        "toml-run-empty-method",
        '`[run] method = ""`',
        "[run] method",
        toml=edit(PAPER, "periods = 3", 'periods = 3\nmethod = ""'),
    ),
    Bad(
        "toml-run-zero-periods", "`[run] periods = 0`", "[run] periods", toml=edit(PAPER, "periods = 3", "periods = 0")
    ),
    Bad(
        "toml-run-bool-periods",
        "`[run] periods = true`",
        "[run] periods",
        toml=edit(PAPER, "periods = 3", "periods = true"),
    ),
    Bad(
        "toml-run-float-steps",
        "`[run] steps_per_period = 300.5`",
        "[run] steps_per_period",
        toml=edit(PAPER, "periods = 3", "periods = 3\nsteps_per_period = 300.5"),
    ),
    # -- command line ----------------------------------------------------------------------
    Bad("cli-missing-file", "`slipstep run no_such_case.toml`", "case", cli=("run", "no_such_case.toml")),
    Bad("cli-empty-case", '`slipstep run ""`', "case", cli=("run", "")),
    Bad("cli-case-is-directory", "`slipstep run .` (a directory)", "case", cli=("run", ".")),
    Bad(
        "cli-case-not-text",
        "`slipstep run binary.toml` (not UTF-8)",
        "case",
        cli=("run", "binary.toml"),
        files=(("binary.toml", bytes(range(128, 256))),),
    ),
    Bad(
        "cli-output-dir-is-file",
        "`slipstep run paper --output-dir notes.txt` (an existing file)",
        "--output-dir",
        cli=("run", "paper", "--output-dir", "notes.txt"),
        files=(("notes.txt", b"x"),),
    ),
    Bad(
        "cli-empty-output-dir",
        '`slipstep run paper --output-dir ""`',
        "--output-dir",
        cli=("run", "paper", "--output-dir", ""),
    ),
    Bad("cli-unknown-method", "`slipstep run paper --method rk4`", "--method", cli=("run", "paper", "--method", "rk4")),
    Bad("cli-empty-method", '`slipstep run paper --method ""`', "--method", cli=("run", "paper", "--method", "")),
    Bad(
        "cli-zero-step-ratio",
        "`slipstep run paper --step-ratio 0`",
        "--step-ratio",
        cli=("run", "paper", "--step-ratio", "0"),
    ),
    Bad(
        "cli-negative-step-ratio",
        "`slipstep run paper --step-ratio -2`",
        "--step-ratio",
        cli=("run", "paper", "--step-ratio", "-2"),
    ),
    Bad("cli-zero-periods", "`slipstep run paper --periods 0`", "--periods", cli=("run", "paper", "--periods", "0")),
    Bad(
        "cli-tables-without-period",
        "`slipstep run tables.toml`: only `[[motion_table]]`, no `period_s`, no `duration_s`",
        "[run] duration_s",
        cli=("run", "tables.toml"),
        files=(
            (
                "tables.toml",
                edit(
                    STRUCTURE,
                    '[[motion]]\ncomponent = "base.x"\namplitude = 1.0e-5\nfrequency_Hz = 50.0\n',
                    MOTION_TABLE,
                ).encode(),
            ),
        ),
    ),
    Bad(
        "cli-zero-duration", "`slipstep run paper --duration 0`", "--duration", cli=("run", "paper", "--duration", "0")
    ),
    Bad("cli-nan-periods", "`slipstep run paper --periods nan`", "--periods", cli=("run", "paper", "--periods", "nan")),
    Bad(
        "cli-absurd-periods",
        "`slipstep run paper --periods 1e300`",
        "--periods",
        cli=("run", "paper", "--periods", "1e300"),
    ),
    Bad(
        "cli-memory",
        "`slipstep run paper --periods 1e7 --max-memory 8GB` (the memory estimate)",
        "--periods",
        cli=("run", "paper", "--periods", "1e7", "--max-memory", "8GB"),
    ),
    Bad(
        "cli-memory-quasi-static",
        "`slipstep run paper -m 4 --steps-per-period 1000000000 --max-memory 8GB`",
        "[run] periods",
        cli=("run", "paper", "-m", "4", "--steps-per-period", "1000000000", "--max-memory", "8GB"),
    ),
    Bad(
        "cli-max-memory",
        "`slipstep run paper --max-memory 1MB --periods 100`",
        "--periods",
        cli=("run", "paper", "--max-memory", "1MB", "--periods", "100"),
    ),
    Bad(
        "cli-bad-max-memory",
        "`slipstep run paper --max-memory lots`",
        "--max-memory",
        cli=("run", "paper", "--max-memory", "lots"),
    ),
    Bad(
        "cli-zero-steps-per-period",
        "`slipstep run paper -m 4 --steps-per-period 0`",
        "--steps-per-period",
        cli=("run", "paper", "-m", "4", "--steps-per-period", "0"),
    ),
    Bad(
        "cli-compare-unknown-method",
        "`slipstep compare paper --methods 1,9`",
        "--methods",
        cli=("compare", "paper", "--methods", "1,9"),
    ),
    Bad(
        "cli-compare-empty-methods",
        '`slipstep compare paper --methods ""`',
        "--methods",
        cli=("compare", "paper", "--methods", ""),
    ),
    Bad(
        "cli-compare-zero-repeats",
        "`slipstep compare paper --repeats 0`",
        "--repeats",
        cli=("compare", "paper", "--repeats", "0"),
    ),
    Bad(
        "cli-schemes-overflow",
        '`slipstep compare paper --schemes "hht(1e400)"`',
        "--schemes",
        cli=("compare", "paper", "--schemes", "hht(1e400)"),
    ),
    Bad(
        "cli-schemes-huge-exponent",
        '`slipstep compare paper --schemes "hht(1e100000000)"` (used to hang)',
        "--schemes",
        cli=("compare", "paper", "--schemes", "hht(1e100000000)"),
    ),
    Bad("cli-plot-missing", "`slipstep plot missing.nc`", "RESULT", cli=("plot", "missing.nc")),
    Bad(
        "cli-plot-empty",
        "`slipstep plot empty.nc` (0 bytes, an interrupted write of old versions)",
        "RESULT",
        cli=("plot", "empty.nc"),
        files=(("empty.nc", b""),),
    ),
    Bad(
        "cli-plot-corrupt",
        "`slipstep plot cut.nc` (an HDF5 file cut short)",
        "RESULT",
        cli=("plot", "cut.nc"),
        files=(("cut.nc", b"\x89HDF\r\n\x1a\n" + bytes(300)),),
    ),
    Bad(
        "cli-plot-netcdf3", "`slipstep plot old.nc` (a netCDF-3 file)", "RESULT", cli=("plot", "old.nc"), setup=_netcdf3
    ),
    Bad(
        "cli-plot-foreign",
        "`slipstep plot foreign.nc` (netCDF-4, not a result)",
        "RESULT",
        cli=("plot", "foreign.nc"),
        setup=_foreign_netcdf,
    ),
    Bad(
        "cli-plot-external-storage",
        "`slipstep plot crafted.nc` (HDF5 external storage)",
        "RESULT",
        cli=("plot", "crafted.nc"),
        setup=_external_storage_netcdf,
    ),
    # -- matrix files and sparse gathers in case files (issue 10) -------------------------------
    Bad(
        "toml-matrix-file-type",
        '`mass_file_kg = "M.txt"` (not .npz / .mtx / .npy)',
        "[structure] mass_file_kg",
        toml=edit(STRUCTURE, "mass_kg = [[1.0, 0.0], [0.0, 1.0]]", 'mass_file_kg = "M.txt"'),
    ),
    Bad(
        "toml-matrix-file-missing",
        '`mass_file_kg = "missing.npz"` (no such file)',
        "[structure] mass_file_kg",
        toml=edit(STRUCTURE, "mass_kg = [[1.0, 0.0], [0.0, 1.0]]", 'mass_file_kg = "missing.npz"'),
    ),
    Bad(
        "toml-matrix-twice",
        "`mass_kg` and `mass_file_kg` both given",
        "[structure] mass_file_kg",
        toml=edit(
            STRUCTURE,
            "mass_kg = [[1.0, 0.0], [0.0, 1.0]]",
            'mass_kg = [[1.0, 0.0], [0.0, 1.0]]\nmass_file_kg = "M.npz"',
        ),
    ),
    Bad(
        "toml-gather-entries-row",
        "`dof_gather_entries = [[2, 0, 1.0]]` in a 2-row contact",
        "[[contacts]] 1 (C1): dof_gather_entries",
        toml=edit(STRUCTURE, "dof_gather = [[1.0, 0.0], [0.0, 1.0]]", "dof_gather_entries = [[2, 0, 1.0]]"),
    ),
    Bad(
        "sparse-events-method",
        '`Simulation(sparse 400-DOF chain, "quasi-static-events")`',
        "method",
        api=lambda: ss.Simulation(_sparse_chain(400), "quasi-static-events", periods=1),
    ),
    Bad(
        "cli-report-output-is-directory", "`slipstep report paper -o .`", "--output", cli=("report", "paper", "-o", ".")
    ),
    # -- the save option (slipstep.methods.save) ---------------------------------------------
    Bad(
        "api-save-unknown-dof",
        "`ss.run(system, save={'dofs': ['x_g']})` (a DOF name that does not exist)",
        "save.dofs",
        api=lambda: ss.run(ss.load_system("paper"), periods=1, save={"dofs": ["x_g"]}),
    ),
    Bad(
        "api-save-unknown-contact",
        "`ss.run(system, save=ss.Save(contacts=['P9']))`",
        "save.contacts",
        api=lambda: ss.run(ss.load_system("paper"), periods=1, save=ss.Save(contacts=["P9"])),
    ),
    Bad(
        "api-save-unknown-key",
        "`ss.run(system, save={'step': 10})` (not a save key)",
        "save.step",
        api=lambda: ss.run(ss.load_system("paper"), periods=1, save={"step": 10}),
    ),
    Bad(
        "api-save-every-zero",
        "`ss.run(system, save=ss.Save(every=0))`",
        "save.every",
        api=lambda: ss.run(ss.load_system("paper"), periods=1, save=ss.Save(every=0)),
    ),
    Bad(
        "api-save-times-outside",
        "`ss.run(system, periods=1, save={'times': [0.0, 1.0]})` (beyond the run)",
        "save.times",
        api=lambda: ss.run(ss.load_system("paper"), periods=1, save={"times": [0.0, 1.0]}),
    ),
    Bad(
        "api-save-energy-balance",
        "`energy_balance(ds, system)` of a run with `save={'dofs': ['x_G']}`",
        "save",
        api=lambda: ss.post.energy_balance(
            ss.run(ss.load_system("paper"), periods=1, save={"dofs": ["x_G"]}), ss.load_system("paper")
        ),
    ),
    Bad(
        "toml-save-unknown-key",
        "`[run.save]` with `every_k = 10`",
        "[run.save] every_k",
        toml=edit(PAPER, "[run]\n", "[run.save]\nevery_k = 10\n\n[run]\n"),
    ),
    Bad(
        "toml-save-no-match",
        '`[run.save]` with `dofs = ["blade*"]` (matches no DOF)',
        "[run.save] dofs",
        cli=("run", "save.toml"),
        files=(("save.toml", edit(PAPER, "[run]\n", '[run.save]\ndofs = ["blade*"]\n\n[run]\n').encode()),),
    ),
    Bad(
        "cli-save-dofs-no-match",
        "`slipstep run paper --save-dofs 'blade*'`",
        "--save-dofs",
        cli=("run", "paper", "--save-dofs", "blade*"),
    ),
    Bad(
        "cli-save-last-periods",
        "`slipstep run paper --save-last-periods 0.5` (P < 1)",
        "--save-last-periods",
        cli=("run", "paper", "--save-last-periods", "0.5"),
    ),
    Bad(
        "cli-save-times",
        "`slipstep run paper --save-times 0:0.01` (no count)",
        "--save-times",
        cli=("run", "paper", "--save-times", "0:0.01"),
    ),
    # -- the step rule (issue 26) ----------------------------------------------------------
    Bad(
        "toml-run-unknown-step-rule",
        '`[run] step_rule = "cfl"`',
        "[run] step_rule",
        toml=edit(PAPER, 'step_rule = "t-min"', 'step_rule = "cfl"'),
    ),
    Bad(
        "cli-case-accuracy-newton",
        '`[run] step_rule = "accuracy"` with the default method newmark (it iterates)',
        "[run] step_rule",
        cli=("run", CASE_FILE),
        files=((CASE_FILE, edit(PAPER, 'step_rule = "t-min"', 'step_rule = "accuracy"').encode()),),
    ),
    Bad(
        "cli-unknown-step-rule",
        "`slipstep run paper --step-rule cfl`",
        "--step-rule",
        cli=("run", "paper", "--step-rule", "cfl"),
    ),
    Bad(
        "cli-accuracy-newton",
        "`slipstep run paper -m 1 --step-rule accuracy`",
        "--step-rule",
        cli=("run", "paper", "-m", "1", "--step-rule", "accuracy"),
    ),
    Bad(
        "cli-case-accuracy-tables-only",
        '`[run] step_rule = "accuracy"` on a case driven by tables only (no period, no max_step)',
        "[run] step_rule",
        cli=("run", CASE_FILE),
        files=((CASE_FILE, TABLES_ONLY_ACCURACY.encode()),),
    ),
    # -- the Newton tolerance and the load-sensitivity twin (issue 29 item 3) ---------------------
    Bad(
        "toml-run-zero-tolerance",
        "`[run] tolerance = 0`",
        "[run] tolerance",
        toml=edit(PAPER, 'step_rule = "t-min"', 'step_rule = "t-min"\ntolerance = 0'),
    ),
    Bad(
        "toml-run-tolerance-above-one",
        "`[run] tolerance = 1.5`",
        "[run] tolerance",
        toml=edit(PAPER, 'step_rule = "t-min"', 'step_rule = "t-min"\ntolerance = 1.5'),
    ),
    Bad(
        "toml-run-nan-tolerance",
        "`[run] tolerance = nan`",
        "[run] tolerance",
        toml=edit(PAPER, 'step_rule = "t-min"', 'step_rule = "t-min"\ntolerance = nan'),
    ),
    Bad(
        "toml-run-text-tolerance",
        '`[run] tolerance = "tight"`',
        "[run] tolerance",
        toml=edit(PAPER, 'step_rule = "t-min"', 'step_rule = "t-min"\ntolerance = "tight"'),
    ),
    Bad(
        "cli-zero-tolerance",
        "`slipstep run paper --tolerance 0`",
        "--tolerance",
        cli=("run", "paper", "--tolerance", "0"),
    ),
    Bad(
        "cli-negative-tolerance",
        "`slipstep run paper --tolerance -1e-3`",
        "--tolerance",
        cli=("run", "paper", "--tolerance", "-1e-3"),
    ),
    Bad(
        "cli-tolerance-one",
        "`slipstep run paper --tolerance 1`",
        "--tolerance",
        cli=("run", "paper", "--tolerance", "1"),
    ),
    Bad(
        "cli-inf-tolerance",
        "`slipstep run paper --tolerance inf`",
        "--tolerance",
        cli=("run", "paper", "--tolerance", "inf"),
    ),
    Bad(
        "api-sensitivity-check",
        "`ss.run(system, sensitivity_check='yes')`",
        "sensitivity_check",
        api=lambda: ss.run(ss.load_system("paper"), sensitivity_check="yes"),
    ),
]


def api_message(case: Bad, directory: Path) -> str:
    """The InputError message of a case's Python call (TOML cases: load the file and build the run)."""
    if case.setup is not None:
        case.setup(directory)
    with pytest.raises(ss.InputError) as info:
        if case.api is not None:
            case.api()
        else:
            path = directory / CASE_FILE
            path.write_text(case.toml)
            system, spec = ss.load_case(path)
            given = (("periods", spec.periods), ("step_ratio", spec.step_ratio), ("step_rule", spec.step_rule))
            given += (("tolerance", spec.tolerance),)
            options = {k: v for k, v in given + (("duration", spec.duration_s),) if v is not None}
            ss.Simulation(system, spec.method or "newmark", **options)
    return str(info.value)


def cli_result(case: Bad, directory: Path):
    for name, content in case.files:
        (directory / name).write_bytes(content)
    if case.setup is not None:
        case.setup(directory)
    args = list(case.cli)
    if "--output-dir" not in args and args[0] in ("run", "compare"):
        args += ["--output-dir", str(directory / "out")]
    return CliRunner().invoke(app, args)


@pytest.mark.parametrize("case", [c for c in CASES if c.cli is None], ids=lambda c: c.id)
def test_api_raises_input_error_naming_field(case, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    message = api_message(case, Path("."))
    assert message.startswith(case.field + ":"), message
    assert "Fix:" in message and "\n" not in message


@pytest.mark.parametrize("case", [c for c in CASES if c.cli is not None or c.toml is not None], ids=lambda c: c.id)
def test_cli_exit_2_one_line_no_traceback(case, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    if case.cli is None:
        Path(CASE_FILE).write_text(case.toml)
        case = Bad(case.id, case.input, case.field, cli=("run", CASE_FILE))
    result = cli_result(case, Path("."))
    text = result.output
    assert result.exit_code == 2, text
    assert "Traceback" not in text and not isinstance(result.exception, Exception)
    lines = [line for line in text.splitlines() if line.strip()]
    assert len(lines) == 1, text
    assert lines[0].startswith(f"input error: {case.field}:"), text
    assert not Path("out").exists() or not any(Path("out").glob("*.nc"))


def produced_message(case: Bad, directory: Path) -> str:
    if case.cli is None:
        return api_message(case, directory)
    text = cli_result(case, directory).output.strip()
    return text.removeprefix("input error: ")


def markdown_table(directory: Path) -> str:
    lines = ["| # | input | field | message |", "|---|---|---|---|"]
    for i, case in enumerate(CASES, 1):
        message = produced_message(case, directory).replace("|", "\\|")
        lines.append(f"| {i} | {case.input} | `{case.field}` | {message} |")
    return "\n".join(lines)


def documented_messages() -> dict[str, str]:
    rows = {}
    for line in DOCS.read_text().splitlines():
        match = re.match(r"\| (\d+) \| .* \| `([^`]*)` \| (.*) \|$", line)
        if match:
            rows[int(match.group(1))] = match.group(3).replace("\\|", "|")
    return rows


def test_docs_table_is_exact(tmp_path, monkeypatch):
    """docs/bad_input.md lists every case, in order, with the message actually produced."""
    monkeypatch.chdir(tmp_path)
    documented = documented_messages()
    assert len(documented) == len(CASES) >= 15
    for i, case in enumerate(CASES, 1):
        assert documented[i] == produced_message(case, Path(".")), case.id


if __name__ == "__main__":  # print the table for docs/bad_input.md (run from a scratch directory)
    import os
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        os.chdir(tmp)
        with pytest.MonkeyPatch.context():
            print(markdown_table(Path(".")))

"""Issue 29 item 4: the API and file-input edges a new user hits, each an InputError naming the
key the user wrote and the fix (each was accepted silently or raised a raw exception before)."""

import numpy as np
import pytest
import scipy.io
import scipy.sparse as sp

import slipstep as ss
from slipstep.casefile.case import load_case
from slipstep.errors import InputError
from slipstep.model.substructure import load_npz, read_mtx


def _contact(n=2):
    return ss.ContactElement(
        name="c",
        dof_gather=np.eye(2, n),
        normal_stiffness=1e6,
        tangential_stiffness=(1e6,),
        friction_coefficient=0.3,
        normal_offset=1e-5,
    )


def _system():
    return ss.System(ss.Structure(np.eye(2), stiffness=1e6 * np.eye(2)), (_contact(),))


API_EDGES = [
    ("complex mass", lambda: ss.Structure(np.eye(2) * (1 + 1e-3j)), "structure.mass", "complex"),
    ("complex sparse", lambda: ss.Structure(sp.csr_matrix(np.eye(2) * (1 + 1j))), "structure.mass", "complex"),
    ("strings in a matrix", lambda: ss.Structure([["1", 0], [0, "1"]]), "structure.mass", "text"),
    ("string array", lambda: ss.Structure(np.array([["1", "0"], ["0", "1"]])), "structure.mass", "text"),
    ("strings in a load", lambda: ss.Harmonic(10.0, ["1.0", "2.0"]), "harmonic.amplitude", "text"),
    ("unknown unit", lambda: ss.Structure(np.eye(2), dof_units=("m", "furlong")), "structure.dof_units", "furlong"),
    ("non-string DOF name", lambda: ss.Structure(np.eye(2), dof_names=(1, 2)), "structure.dof_names", "not text"),
    ("DOF names a string", lambda: ss.Structure(np.eye(2), dof_names="xy"), "structure.dof_names", "sequence"),
    ("2D harmonic amplitude", lambda: ss.Harmonic(10.0, np.ones((2, 1))), "harmonic.amplitude", "shape (2, 1)"),
    ("2D harmonic phase", lambda: ss.Harmonic(10.0, [1.0], [[0.0]]), "harmonic.phase", "shape (1, 1)"),
    (
        "duplicate components",
        lambda: ss.Signal(("a", "a"), (ss.Harmonic(1.0, [1.0, 2.0]),)),
        "signal.components",
        "more than once",
    ),
    ("non-string component", lambda: ss.Signal((0,), (ss.Harmonic(1.0, [1.0]),)), "signal.components", "not text"),
    (
        "state vector of the wrong length",
        lambda: ss.state_t_min(_system().compile(), np.ones(5, np.int8)),
        "state",
        "1 tangential directions",
    ),
    ("state codes out of range", lambda: ss.state_t_min(_system().compile(), [9]), "state", "contact-state codes"),
    ("System from a string", lambda: ss.System("paper", ()), "structure", "load_system"),
    ("contacts one element", lambda: ss.System(ss.Structure(np.eye(2)), _contact()), "contacts", "tuple or list"),
    ("contacts a number", lambda: ss.System(ss.Structure(np.eye(2)), 5), "contacts", "not a sequence"),
    ("contacts of other things", lambda: ss.System(ss.Structure(np.eye(2)), ("c",)), "contacts[0]", "ContactElement"),
    (
        "excitation not an Excitation",
        lambda: ss.System(ss.Structure(np.eye(2)), (_contact(),), excitation={"force": 1}),
        "excitation",
        "Excitation(",
    ),
    (
        "motion names a string",
        lambda: ss.System(ss.Structure(np.eye(2)), (_contact(),), motion_names="p"),
        "motion_names",
        "sequence",
    ),
    (
        "huge max_iterations",
        lambda: ss.run(ss.load_system("paper"), "newmark", periods=0.01, max_iterations=10**30),
        "max_iterations",
        "at most 1e9",
    ),
]


@pytest.mark.parametrize("what, make, field, problem", API_EDGES, ids=[e[0] for e in API_EDGES])
def test_api_edge_is_an_input_error(what, make, field, problem):
    with pytest.raises(InputError) as err:
        make()
    assert err.value.field == field
    assert problem in str(err.value) and err.value.fix


CASE = """name = "f"
[structure]
{mass}
stiffness_N_per_m = [[1e6, 0], [0, 1e6]]
[[contacts]]
name = "c"
{gather}
normal_stiffness_N_per_m = 1e6
tangential_stiffness_N_per_m = 1e6
friction_coefficient = 0.3
normal_offset_m = 1e-5
"""
GATHER = "dof_gather = [[1, 0], [0, 1]]"
INLINE_MASS = "mass_kg = [[1, 0], [0, 1]]"


def _write_files(d):
    np.save(d / "text.npy", np.array([["1", "0"], ["0", "1"]]))
    np.save(d / "complex.npy", np.eye(2) * (1 + 1j))
    scipy.io.mmwrite(str(d / "complex.mtx"), sp.coo_matrix(np.eye(2) * (1 + 1j)))
    (d / "pattern.mtx").write_text("%%MatrixMarket matrix coordinate pattern general\n2 2 2\n1 1\n2 2\n")
    (d / "notzip.npz").write_text("this is not a zip file")
    (d / "badzip.npz").write_bytes(b"PK\x03\x04" + bytes(40))
    with open(d / "array.npz", "wb") as fh:  # an .npy under an .npz name
        np.save(fh, np.eye(2))


FILE_EDGES = [
    ("npy of text", 'mass_file_kg = "text.npy"', GATHER, "mass_file_kg", "text"),
    ("complex npy", 'mass_file_kg = "complex.npy"', GATHER, "mass_file_kg", "complex"),
    ("complex mtx", 'mass_file_kg = "complex.mtx"', GATHER, "mass_file_kg", "complex"),
    ("pattern mtx", 'mass_file_kg = "pattern.mtx"', GATHER, "mass_file_kg", "pattern"),
    ("npz not a zip", 'mass_file_kg = "notzip.npz"', GATHER, "mass_file_kg", "cannot be read"),
    ("npz a broken zip", 'mass_file_kg = "badzip.npz"', GATHER, "mass_file_kg", "cannot be read"),
    ("npz holding an npy", 'mass_file_kg = "array.npz"', GATHER, "mass_file_kg", "cannot be read"),
    (
        "negative dof_gather_rows",
        INLINE_MASS,
        "dof_gather_entries = [[0, 0, 1.0], [1, 1, 1.0]]\ndof_gather_rows = -2",
        "dof_gather_rows",
        "is -2",
    ),
    (
        "duplicate dof_gather_entries",
        INLINE_MASS,
        "dof_gather_entries = [[0, 0, 1.0], [0, 0, 1.0], [1, 1, 1.0]]",
        "dof_gather_entries",
        "more than once",
    ),
]


@pytest.mark.parametrize("what, mass, gather, key, problem", FILE_EDGES, ids=[e[0] for e in FILE_EDGES])
def test_case_file_edge_is_an_input_error(tmp_path, what, mass, gather, key, problem):
    _write_files(tmp_path)
    path = tmp_path / "case.toml"
    path.write_text(CASE.format(mass=mass, gather=gather))
    with pytest.raises(InputError) as err:
        load_case(path)
    assert err.value.field.endswith(key), err.value.field
    assert problem in str(err.value)


@pytest.mark.parametrize("name", ["notzip.npz", "badzip.npz", "array.npz"])
def test_assembly_npz_that_is_not_a_zip_is_an_input_error(tmp_path, name):
    _write_files(tmp_path)
    with pytest.raises(InputError) as err:
        load_npz(tmp_path / name, "blade", field_name="[[substructures]] 1.file")
    assert err.value.field == "[[substructures]] 1.file"


def test_assembly_npz_with_complex_matrices_is_an_input_error(tmp_path):
    np.savez(tmp_path / "c.npz", M=np.eye(2) * (1 + 1j), K=np.eye(2))
    with pytest.raises(InputError, match="complex"):
        load_npz(tmp_path / "c.npz", "blade")


@pytest.mark.parametrize("name, problem", [("pattern.mtx", "pattern"), ("complex.mtx", "complex")])
def test_assembly_mtx_without_real_values_is_an_input_error(tmp_path, name, problem):
    _write_files(tmp_path)
    with pytest.raises(InputError, match=problem) as err:
        read_mtx(tmp_path / name, "mass_file")
    assert err.value.field == "mass_file"


def test_valid_inputs_still_pass(tmp_path):
    """The checks refuse only what they name: real arrays, 'm'/'rad', tuples of names, a list of contacts."""
    s = ss.Structure(np.eye(3), dof_names=["a", "b", "c"], dof_units=("m", "m", "rad"))
    assert s.dof_units == ("m", "m", "rad")
    system = ss.System(ss.Structure(np.eye(2), stiffness=1e6 * np.eye(2)), [_contact()])
    assert np.isfinite(ss.state_t_min(system.compile(), [1]))
    np.save(tmp_path / "m.npy", np.eye(2))
    path = tmp_path / "case.toml"
    path.write_text(
        CASE.format(mass='mass_file_kg = "m.npy"', gather="dof_gather_entries = [[0, 0, 1.0], [1, 1, 1.0]]")
    )
    system, _ = load_case(path)
    assert system.n_dofs == 2

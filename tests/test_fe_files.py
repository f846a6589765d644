"""Matrices from FE codes (issue 26, item 4): Nastran OP4 and DMIG, Abaqus matrix output.

The fixture files of tests/data/fe are written by pyNastran's own writers (Nastran) and to
Abaqus's documented text format (tests/data/fe/make_fixtures.py); each is read back against
the numpy arrays it was written from, and, where pyNastran imports, against pyNastran's
readers. Two of them are marched as case files and compared with the same system built
from numpy arrays.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

import slipstep as ss
from slipstep.errors import InputError
from slipstep.model import fe_files as fe

DATA = Path(__file__).parent / "data" / "fe"
sys.path.insert(0, str(DATA))
from make_fixtures import DOFS, matrices  # noqa: E402

sys.path.remove(str(DATA))

M, C, K = matrices()
NAMES = tuple(f"{g}.{c}" for g, c in DOFS)
HAS_PYNASTRAN = importlib.util.find_spec("pyNastran") is not None
needs_pynastran = pytest.mark.skipif(not HAS_PYNASTRAN, reason="pyNastran is not installed (an optional cross-check)")


@pytest.mark.parametrize("name", ["chain_dense.op4", "chain_sparse.op4", "chain_bigmat.op4"])
def test_op4_forms_read_the_matrices_written(name):
    """Dense columns, sparse strings (IS = IROW + 65536 (L + 1)) and BIGMAT strings."""
    got = fe.read_op4(DATA / name, "file")
    assert set(got) >= {"MAA", "KAA"}
    np.testing.assert_array_equal(got["MAA"].toarray(), M)
    np.testing.assert_array_equal(got["KAA"].toarray(), K)
    if "BAA" in got:
        np.testing.assert_array_equal(got["BAA"].toarray(), C)


@pytest.mark.parametrize("name", ["chain_dmig_small.bdf", "chain_dmig_large.bdf", "chain_dmig_free.bdf"])
def test_dmig_fields_read_the_matrices_written(name):
    """Small, large and free field; IFO 6 given as the upper triangle, BAAX (IFO 1) square."""
    got, dofs = fe.read_dmig(DATA / name, "file")
    assert dofs == NAMES
    for key, A in (("MAAX", M), ("KAAX", K), ("BAAX", C)):
        np.testing.assert_allclose(got[key].toarray(), A, rtol=1e-7, atol=0)  # small field: 8 characters


@needs_pynastran
@pytest.mark.parametrize("name", ["chain_dense.op4", "chain_sparse.op4", "chain_bigmat.op4"])
def test_op4_equals_pynastrans_reader(name):
    from pyNastran.op4.op4 import read_op4

    theirs = read_op4(str(DATA / name))
    ours = fe.read_op4(DATA / name, "file")
    assert set(theirs) == set(ours)
    for key, matrix in theirs.items():
        data = matrix.data
        dense = data.toarray() if hasattr(data, "toarray") else np.asarray(data)
        np.testing.assert_array_equal(ours[key].toarray(), dense)


@needs_pynastran
@pytest.mark.parametrize("name", ["chain_dmig_small.bdf", "chain_dmig_large.bdf", "chain_dmig_free.bdf"])
def test_dmig_equals_pynastrans_reader(name, monkeypatch):
    if not hasattr(np, "in1d"):  # pyNastran 1.4's BDF module still calls numpy.in1d (gone in numpy 2.4)
        monkeypatch.setattr(np, "in1d", np.isin, raising=False)
    from pyNastran.bdf.bdf import BDF

    model = BDF(debug=None)
    model.read_bdf(str(DATA / name), punch=True, xref=False)
    ours, dofs = fe.read_dmig(DATA / name, "file")
    for key, dmig in model.dmig.items():
        theirs, rows, cols = dmig.get_matrix(is_sparse=False, apply_symmetry=True)
        order = [dofs.index(f"{g}.{c}") for _, (g, c) in sorted(rows.items())]  # {index: (grid, component)}
        corder = [dofs.index(f"{g}.{c}") for _, (g, c) in sorted(cols.items())]
        # pyNastran keeps TIN 1 (single precision) values as float32
        np.testing.assert_allclose(ours[key].toarray()[np.ix_(order, corder)], theirs, rtol=2e-7, atol=0)


def test_abaqus_labelled_and_coordinate_forms():
    files = {
        r: (DATA / f"chain_{t}.mtx", r) for r, t in (("mass", "MASS1"), ("stiffness", "STIF1"), ("damping", "DMPV1"))
    }
    got = fe.abaqus_matrices(files)
    assert got.dofs == NAMES and got.dof_units == ("m",) * 9
    for A, B in ((got.mass, M), (got.stiffness, K), (got.damping, C)):
        np.testing.assert_array_equal(A.toarray(), B)
    coord = fe.abaqus_matrices(
        {"mass": (DATA / "chain_coord_MASS2.mtx", "m"), "stiffness": (DATA / "chain_coord_STIF2.mtx", "k")}
    )
    assert coord.dofs == ()
    np.testing.assert_array_equal(coord.stiffness.toarray(), K)


def test_nastran_reals():
    assert [fe.nastran_float(t) for t in ("1.5+3", "-.75", "2.0D-01", "3.", "-4.-2", "7")] == [
        1500.0,
        -0.75,
        0.2,
        3.0,
        -0.04,
        7.0,
    ]


def test_ansys_reader_maps_dof_reference_to_names():
    """ansys-mapdl-reader's (dof_ref, k, m): DOF index 0, 1, 2 -> components 1, 2, 3; one
    triangle mirrored (as load_km returns it)."""
    import scipy.sparse as sp

    ref = np.array([[g, c - 1] for g, c in DOFS])
    got = fe.ansys_matrices(ref, sp.triu(K), sp.triu(M), "ansys: x", "file")
    assert got.dofs == NAMES
    np.testing.assert_array_equal(got.stiffness.toarray(), K)
    np.testing.assert_array_equal(got.mass.toarray(), M)


FACE = """
[[contacts]]
name = "tip"
{face}
dof_gather_rows = 3
normal_stiffness_N_per_m = 2e4
tangential_stiffness_N_per_m = 1e4
friction_coefficient = 0.3
normal_offset_m = 1e-4

[[force]]
component = "103.1"
frequency_Hz = 8.0
amplitude = 6.0
"""


def _case(tmp_path: Path, structure: str, face: str) -> Path:
    path = tmp_path / "case.toml"
    path.write_text('name = "fe"\n[structure]\n' + structure + FACE.format(face=face))
    return path


def _case_ref(tmp_path: Path) -> Path:
    rows = np.zeros((3, 9))
    rows[0, 6], rows[1, 7], rows[2, 8] = 1.0, 1.0, 1.0
    inline = (
        "dof_names = ["
        + ", ".join(f'"{n}"' for n in NAMES)
        + "]\n"
        + f"mass_kg = {M.tolist()}\nstiffness_N_per_m = {K.tolist()}\ndamping_N_s_per_m = {C.tolist()}\n"
    )
    path = tmp_path / "ref.toml"
    path.write_text(
        'name = "fe"\n[structure]\n'
        + inline
        + FACE.format(face=f"dof_gather = {rows.tolist()}").replace('name = "tip"', 'name = "tip.103"')
    )
    return path


def _march(path: Path):
    return ss.run(ss.load_system(path), "piecewise-linear", periods=2)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    return _march(_case_ref(tmp_path_factory.mktemp("ref")))


@pytest.mark.parametrize(
    "structure",
    [
        f'file = "{DATA / "chain_dense.op4"}"\ndamping_matrix = "BAA"\ndof_names = ['
        + ", ".join(f'"{n}"' for n in NAMES)
        + "]\n",
        f'format = "abaqus"\nmass_file_kg = "{DATA / "chain_MASS1.mtx"}"\n'
        f'stiffness_file_N_per_m = "{DATA / "chain_STIF1.mtx"}"\ndamping_file_N_s_per_m = "{DATA / "chain_DMPV1.mtx"}"\n',
        f'file = "{DATA / "chain_dmig_large.bdf"}"\ndamping_matrix = "BAAX"\n',
    ],
    ids=["op4", "abaqus", "dmig"],
)
def test_fe_case_marches_as_the_numpy_system(tmp_path, reference, structure):
    """An FE file named in [structure], the contact face as nodes + normal: the march equals
    the one of the same system from numpy arrays to round-off."""
    ds = _march(_case(tmp_path, structure, "nodes = [103]\nnormal = [0, 0, 1]\ntangent = [1, 0, 0]"))
    assert ds.attrs["status"] == reference.attrs["status"] == "OK"
    assert list(ds["contact"].values) == list(reference["contact"].values) == ["tip.103"]
    for var in ("displacement", "normal_force"):
        a, b = ds[var].values, reference[var].values
        assert a.shape == b.shape
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * np.abs(b).max())
    assert np.abs(reference["displacement"].values).max() > 1e-5  # it moved


BAD = [
    ("missing matrix", str(DATA / "chain_dense.op4"), 'mass_matrix = "MXX"', "[structure] mass_matrix", "not a matrix"),
    ("no stiffness", "only_mass.op4", "", "[structure] file", "no stiffness"),
    ("wrong header", "bad_header.op4", "", "[structure] file", "not an OP4 matrix header"),
    ("non-square", "rect.op4", "", "[structure] stiffness_matrix", "not square"),
    ("asymmetric mass", "asym.op4", "", "[structure] mass_matrix", "not symmetric"),
    ("unknown format", "model.xyz", "", "[structure] file", "not known"),
    ("binary", "binary.op4", "", "[structure] file", "binary"),
    ("not found", "absent.op4", "", "[structure] file", "not found"),
]


def _bad_files(d: Path) -> None:
    """Broken copies of the dense OP4 fixture (MAA, BAA, KAA in that order)."""
    text = (DATA / "chain_dense.op4").read_text()
    mass_at = text.index("MAA") - 32
    (d / "only_mass.op4").write_text(text[mass_at:])
    (d / "bad_header.op4").write_text("this is not an op4 file\n" + text)
    (d / "rect.op4").write_text(
        text.replace("       9       9       2       2KAA", "       8       9       2       2KAA")
    )
    (d / "asym.op4").write_text(
        text[:mass_at] + text[mass_at:].replace("5.0000000000000000E-01", "5.1000000000000000E-01", 1)
    )
    (d / "model.xyz").write_text("x")
    (d / "binary.op4").write_bytes(b"\x18\x00\x00\x00" + bytes(40))


@pytest.mark.parametrize("label, name, extra, field, problem", BAD, ids=[b[0] for b in BAD])
def test_bad_fe_files_are_input_errors(tmp_path, label, name, extra, field, problem):
    _bad_files(tmp_path)
    path = _case(
        tmp_path,
        f'file = "{name}"\ndof_names = [' + ", ".join(f'"{n}"' for n in NAMES) + "]\n" + extra + "\n",
        "nodes = [103]\nnormal = [0, 0, 1]",
    )
    with pytest.raises(InputError) as err:
        ss.load_system(path)
    assert err.value.field == field
    assert problem in err.value.problem


def test_unknown_face_node_and_bad_normal_are_input_errors(tmp_path):
    structure = f'file = "{DATA / "chain_dmig_large.bdf"}"\n'
    with pytest.raises(InputError) as err:
        ss.load_system(_case(tmp_path, structure, "nodes = [104]\nnormal = [0, 0, 1]"))
    assert err.value.field == "[[contacts]] 1 (tip): nodes" and "104.1" in err.value.problem
    with pytest.raises(InputError) as err:
        ss.load_system(_case(tmp_path, structure, "nodes = [103]\nnormal = [0, 0, 0]"))
    assert err.value.field == "[[contacts]] 1 (tip): normal"


def test_cli_exit_2_on_a_bad_fe_file(tmp_path):
    from typer.testing import CliRunner

    from slipstep.cli.main import app

    path = _case(tmp_path, 'file = "absent.op4"\n', "nodes = [103]\nnormal = [0, 0, 1]")
    result = CliRunner().invoke(app, ["run", str(path), "--output-dir", str(tmp_path / "out")])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and "absent.op4" in result.output


def test_ansys_full_file_through_ansys_mapdl_reader():
    """The example .full file that ansys-mapdl-reader ships, read by slipstep and by the
    reader's dense load_km: the same matrices (one triangle mirrored), DOFs '<node>.<1..3>'."""
    reader = pytest.importorskip("ansys.mapdl.reader", reason="ansys-mapdl-reader is not installed (optional)")
    from ansys.mapdl.reader import examples

    got = fe.read_fe_file(Path(examples.fullfile), "[structure] file")
    dof_ref, k, m = reader.read_binary(examples.fullfile).load_km(as_sparse=False, sort=True)
    full = np.triu(m) + np.triu(m, 1).T
    np.testing.assert_array_equal(got.mass.toarray(), full)
    assert got.dofs[:3] == tuple(f"{dof_ref[0][0]}.{d}" for d in (1, 2, 3))


def test_ansys_full_without_the_reader_says_how_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "ansys.mapdl.reader", None)
    (tmp_path / "m.full").write_bytes(b"\x00" * 64)
    with pytest.raises(InputError) as err:
        fe.read_fe_file(tmp_path / "m.full", "[structure] file")
    assert "ansys-mapdl-reader" in err.value.fix or "ansys-mapdl-reader" in err.value.problem

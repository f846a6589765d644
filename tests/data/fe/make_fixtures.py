"""Regenerate the FE-code fixture files of this folder (issue 26, item 4).

The model: three grids (101, 102, 103), translational components 1, 2, 3 each (9 DOFs,
named "<grid>.<component>"), a consistent-like mass, a Rayleigh damping C = 0.5 M + 1e-4 K
and a chain stiffness grounded at grid 101. Run from the repository root:

    python tests/data/fe/make_fixtures.py

Nastran files are written by pyNastran's own writers (pip install pyNastran; the OP4 writer
for the .op4 files, the BDF writer for the DMIG cards; the free-field file joins the
fields pyNastran's cards give, comma-separated). The Abaqus files are written here to the
documented text format of *MATRIX GENERATE / *MATRIX OUTPUT (FORMAT=MATRIX INPUT: "row
node, row dof, column node, column dof, value", lower triangle of a symmetric matrix;
FORMAT=COORDINATE: "row, column, value" with 1-based equation numbers).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
GRIDS = (101, 102, 103)
COMPONENTS = (1, 2, 3)
DOFS = [(g, c) for g in GRIDS for c in COMPONENTS]


def matrices() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M [kg], C [N s/m], K [N/m] of the 9-DOF fixture model, in DOFS order."""
    chain_m = np.array([[2.0, 0.5, 0.0], [0.5, 3.0, 0.4], [0.0, 0.4, 1.6]])
    chain_k = np.array([[2.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.0]])
    direction = 1.0e4 * np.array([[1.0, 0.2, 0.0], [0.2, 1.5, 0.1], [0.0, 0.1, 2.0]])
    M = np.kron(chain_m, np.eye(3))
    K = np.kron(chain_k, direction)
    C = 0.5 * M + 1.0e-4 * K
    return M, C, K


def write_op4() -> None:
    from pyNastran.op4.op4 import write_op4
    from scipy.sparse import coo_matrix

    M, C, K = matrices()
    write_op4(HERE / "chain_dense.op4", {"MAA": (2, M), "BAA": (2, C), "KAA": (2, K)}, is_binary=False)
    write_op4(
        HERE / "chain_sparse.op4",
        {"MAA": (2, coo_matrix(M)), "KAA": (2, coo_matrix(K))},
        is_binary=False,
    )
    # BIGMAT string headers: the sparse writer with a negative row count
    from pyNastran.op4 import op4 as op4_module

    with open(HERE / "chain_bigmat.op4", "w") as f:
        for name, A in (("MAA", M), ("KAA", K)):
            op4_module._write_sparse_matrix_ascii(f, name, coo_matrix(A), form=6, is_big_mat=True)


def _dmig_entries(A: np.ndarray, ifo: int) -> tuple[list, list, list]:
    """(GCj, GCi, values) of the nonzero entries of A, column by column; of a symmetric
    matrix (IFO 6) the upper triangle only."""
    gcj, gci, real = [], [], []
    for j, col in enumerate(DOFS):
        for i, row in enumerate(DOFS):
            if A[i, j] != 0.0 and (ifo != 6 or i <= j):
                gcj.append(col)
                gci.append(row)
                real.append(float(A[i, j]))
    return gcj, gci, real


def write_dmig() -> None:
    if not hasattr(np, "in1d"):  # pyNastran 1.4's BDF module still calls numpy.in1d (gone in numpy 2.4)
        np.in1d = np.isin  # noqa: NPY201 (a shim for pyNastran, not a call)
    from pyNastran.bdf.bdf import BDF

    M, C, K = matrices()
    mats = (("MAAX", M, 6), ("KAAX", K, 6), ("BAAX", C, 1))
    for tin, size, fname in ((1, 8, "chain_dmig_small.bdf"), (2, 16, "chain_dmig_large.bdf")):
        model = BDF(debug=False)  # TIN 1 (single precision) is written small field, TIN 2 large field
        for name, A, ifo in mats:
            gcj, gci, real = _dmig_entries(A, ifo)
            model.add_dmig(name, ifo, tin, tin, 0, None, gcj, gci, real)
        model.write_bdf(HERE / fname, size=size, is_double=tin == 2)
    # free field, one card per column with continuation lines (8 data fields a line)
    lines = ["$ DMIG cards in free field (a punch file: bulk data only, as the two above)"]
    for name, A, ifo in mats:
        lines.append(f"DMIG,{name},0,{ifo},2,2,0,,9")
        gcj, gci, real = _dmig_entries(A, ifo)
        for col in dict.fromkeys(map(tuple, gcj)):
            entries = [(r, v) for c, r, v in zip(gcj, gci, real) if tuple(c) == col]
            fields = [str(col[0]), str(col[1]), ""]
            for (g, c), v in entries:
                fields += [str(g), str(c), repr(v), ""]
            first, rest = fields[:7], fields[7:]
            lines.append(f"DMIG,{name}," + ",".join(first) + (",+" if rest else ""))
            while rest:
                chunk, rest = rest[:8], rest[8:]
                lines.append("+," + ",".join(chunk) + (",+" if rest else ""))
    (HERE / "chain_dmig_free.bdf").write_text("\n".join(lines) + "\n")


def write_abaqus() -> None:
    M, C, K = matrices()
    for tag, A in (("MASS1", M), ("DMPV1", C), ("STIF1", K)):
        rows = [
            f"{DOFS[i][0]},{DOFS[i][1]}, {DOFS[j][0]},{DOFS[j][1]}, {A[i, j]:.16e}"
            for i in range(9)
            for j in range(i + 1)
            if A[i, j] != 0.0
        ]
        (HERE / f"chain_{tag}.mtx").write_text("\n".join(rows) + "\n")
    for tag, A in (("MASS2", M), ("STIF2", K)):
        rows = [f"{i + 1} {j + 1} {A[i, j]:.16e}" for i in range(9) for j in range(9) if A[i, j] != 0.0]
        (HERE / f"chain_coord_{tag}.mtx").write_text("\n".join(rows) + "\n")


if __name__ == "__main__":
    write_op4()
    write_dmig()
    write_abaqus()

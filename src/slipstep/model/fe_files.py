"""Matrices from FE codes (issue 26, item 4): Nastran OP4 and DMIG, Abaqus matrix output, ANSYS .full.

Each reader returns :class:`FEMatrices`: M, K and an optional C as scipy.sparse CSR in one DOF
order, the DOF names ``"<node>.<component>"`` of that order (components 1-3 translations, 4-6
rotations, 0 a scalar point) and the source (file and format). The files are read as the codes
document them:

* **OP4 text** (Nastran OUTPUT4, ``FORMAT``ted): per matrix a header ``NCOL NROW FORM TYPE NAME
  FMT`` (4I8, A8, the Fortran format of the values such as ``1P,3E23.16``), then columns: a
  column header ``ICOL IROW NW``; ``IROW > 0`` starts a dense run of values from row IROW,
  ``IROW = 0`` a sparse column of strings, each introduced by ``IS = IROW + 65536 (L + 1)``
  (one integer) or, in BIGMAT form (``NROW < 0``), by ``L IROW`` (two integers). A column
  number ``ICOL > NCOL`` closes the matrix. OP4 holds no DOF numbering: the DOFs are named by
  the case (``dof_names``) or ``x0, x1, ...``.
* **DMIG** in a bulk-data file: a header card ``DMIG NAME 0 IFO TIN TOUT POLAR - NCOL`` and
  column cards ``DMIG NAME GJ CJ - G1 C1 A1 B1 G2 C2 A2 B2 ...`` in small (8-character),
  large (``DMIG*``, 16-character) or free (comma) field, with continuations; IFO 6 (symmetric)
  gives one triangle, mirrored here.
* **Abaqus** ``*MATRIX GENERATE`` / ``*MATRIX OUTPUT`` text: ``FORMAT=MATRIX INPUT`` lines
  ``row node, row dof, column node, column dof, value`` (one triangle of a symmetric matrix),
  or ``FORMAT=COORDINATE`` lines ``row, column, value`` (1-based equation numbers, no node
  numbering: DOFs named as for OP4); one file per matrix; ``**`` lines are comments.
* **ANSYS .full** through ansys-mapdl-reader where it is installed (``load_km``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from slipstep.errors import InputError

FORMATS = ("op4", "dmig", "abaqus", "ansys")
_SUFFIXES = {".op4": "op4", ".bdf": "dmig", ".dat": "dmig", ".nas": "dmig", ".blk": "dmig", ".full": "ansys"}
_DEFAULT_NAMES = {  # the matrix names tried, in order, when the case names none
    "mass": ("MAA", "MGG", "MHH", "MAAX", "MXX", "M", "MASS"),
    "stiffness": ("KAA", "KGG", "KHH", "KAAX", "KXX", "K", "STIF", "STIFFNESS"),
    "damping": ("BAA", "BGG", "BHH", "BAAX", "BXX", "B", "C", "DAMPING"),
}


@dataclass(frozen=True)
class FEMatrices:
    """M [kg], K [N/m], optional C [N s/m] (scipy.sparse CSR, n x n) of an FE file.

    ``dofs``: the DOF names ``"<node>.<component>"`` in row order, or ``()`` when the file has
    no DOF numbering (OP4, Abaqus COORDINATE). ``source``: ``"<format>: <file>"``.
    """

    mass: sp.csr_matrix
    stiffness: sp.csr_matrix
    damping: sp.csr_matrix | None
    dofs: tuple[str, ...]
    source: str

    @property
    def dof_units(self) -> tuple[str, ...]:
        """m for translations (components 1-3, 0), rad for rotations (4-6)."""
        return tuple("rad" if name.rsplit(".", 1)[-1] in ("4", "5", "6") else "m" for name in self.dofs)


def format_of(path: Path, given: str | None, key: str) -> str:
    """The format of an FE file: ``given`` (one of FORMATS) or its suffix."""
    if given is not None:
        if given not in FORMATS:
            raise InputError(key.rsplit(" ", 1)[0] + " format", f"is {given!r}", f"give one of {', '.join(FORMATS)}")
        return given
    fmt = _SUFFIXES.get(path.suffix.lower())
    if fmt is None:
        raise InputError(
            key,
            f"is {str(path)!r}: its format is not known from the suffix",
            f"set format = one of {', '.join(FORMATS)} (suffixes {', '.join(_SUFFIXES)})",
        )
    return fmt


# ----------------------------------------------------------------------------- numbers


_NASTRAN_EXPONENT = re.compile(r"^([+-]?[0-9.]+)([+-][0-9]+)$")


def nastran_float(text: str) -> float:
    """A Nastran real: ``1.5+3`` = 1.5e3, ``-.75``, ``2.0D-01``, ``3.``."""
    t = text.strip().upper().replace("D", "E")
    m = _NASTRAN_EXPONENT.match(t)
    if m:
        t = f"{m.group(1)}E{m.group(2)}"
    return float(t)


# ----------------------------------------------------------------------------- OP4


def read_op4(path: Path, key: str) -> dict[str, sp.csr_matrix]:
    """The real matrices of an OP4 text file by name (see the module docstring)."""
    lines = _read_text(path, key).splitlines()
    if lines and _is_binary(path):
        raise InputError(key, f"{str(path)!r} is a binary OP4 file", "write it as text: OUTPUT4 with FORMATTED")
    out: dict[str, sp.csr_matrix] = {}
    i = 0
    while i < len(lines):
        if not lines[i].strip():
            i += 1
            continue
        name, A, i = _op4_matrix(lines, i, path, key)
        out[name] = A
    if not out:
        raise InputError(key, f"{str(path)!r} holds no OP4 matrix", "give an OP4 text file (OUTPUT4 FORMATTED)")
    return out


def _op4_header(line: str, lineno: int, path: Path, key: str):
    """(ncols, nrows, bigmat, type, name, value width) of an OP4 matrix header line."""
    try:
        ncols, nrows, _form, mtype = (int(v) for v in line[0:32].split())
        width = int(re.search(r"E(\d+)\.\d+", line[40:].upper()).group(1))
    except (ValueError, AttributeError):
        raise InputError(
            key,
            f"{str(path)!r} line {lineno}: {line.strip()[:60]!r} is not an OP4 matrix header",
            "give an OP4 text file: a header NCOL NROW FORM TYPE NAME FMT (4I8, A8, e.g. 1P,3E23.16)",
        ) from None
    name = line[32:40].strip()
    if mtype not in (1, 2):
        kind = "complex" if mtype in (3, 4) else f"of type {mtype}"
        raise InputError(key, f"{str(path)!r}: matrix {name} is {kind}", "give real matrices (TYPE 1 or 2)")
    if ncols <= 0 or nrows == 0:
        raise InputError(key, f"{str(path)!r}: matrix {name} has shape {abs(nrows)} x {ncols}", "give a square matrix")
    return ncols, abs(nrows), nrows < 0 or abs(nrows) > 65535, name, width


def _op4_is_header(line: str) -> bool:
    """Whether a line is a matrix header: four integers in columns 1-32, then a name."""
    try:
        return len([int(v) for v in line[0:32].split()]) == 4 and bool(line[32:40].strip())
    except ValueError:
        return False


def _op4_ints(line: str) -> list[int] | None:
    """The integers of a record-header line, or None for a line of values."""
    if "E" in line.upper() or "D" in line.upper():
        return None
    try:
        return [int(v) for v in line.split()]
    except ValueError:
        return None


def _op4_matrix(lines: list[str], i: int, path: Path, key: str):
    """(name, CSR matrix, next line) of the OP4 matrix whose header is line i."""
    ncols, nrows, bigmat, name, width = _op4_header(lines[i], i + 1, path, key)
    rows: list[int] = []
    cols: list[int] = []
    vals: list[float] = []
    i += 1
    col = row = None
    while i < len(lines):
        line = lines[i].rstrip()
        ints = _op4_ints(line)
        if ints is None:  # values: consecutive rows of the current column from `row`
            if col is None:
                raise InputError(key, f"{str(path)!r} line {i + 1}: values before a column header", "give an OP4 file")
            for k in range(0, len(line), width):
                text = line[k : k + width]
                if text.strip():
                    rows.append(row)
                    cols.append(col)
                    vals.append(_op4_value(text, i, path, key))
                    row += 1
        elif len(ints) == 3:  # a column header ICOL IROW NW
            col, irow = ints[0] - 1, ints[1]
            if col >= ncols:  # the closing column: skip its dummy value
                i += 1
                while i < len(lines) and not _op4_is_header(lines[i]):
                    i += 1
                break
            row = irow - 1 if irow > 0 else None
        elif len(ints) in (1, 2) and col is not None:  # a sparse string header
            row = (ints[1] if bigmat and len(ints) == 2 else ints[0] % 65536) - 1
        elif ints:
            raise InputError(
                key, f"{str(path)!r} line {i + 1}: {line.strip()[:60]!r} is not an OP4 record", "give an OP4 text file"
            )
        i += 1
    else:
        raise InputError(key, f"{str(path)!r}: matrix {name} has no closing column", "give a complete OP4 file")
    r = np.asarray(rows, dtype=np.int64)
    if r.size and (r.min() < 0 or r.max() >= nrows):
        raise InputError(key, f"{str(path)!r}: matrix {name} has a row outside 1..{nrows}", "give a valid OP4 file")
    A = sp.coo_matrix((np.asarray(vals, dtype=float), (r, np.asarray(cols, dtype=np.int64))), shape=(nrows, ncols))
    A = A.tocsr()
    A.eliminate_zeros()
    return name, A, i


def _op4_value(text: str, i: int, path: Path, key: str) -> float:
    try:
        return nastran_float(text)
    except ValueError:
        raise InputError(
            key, f"{str(path)!r} line {i + 1}: {text.strip()!r} is not a number", "give an OP4 file"
        ) from None


# ----------------------------------------------------------------------------- DMIG


def read_dmig(path: Path, key: str) -> tuple[dict[str, sp.csr_matrix], tuple[str, ...]]:
    """The DMIG matrices of a bulk-data file by name, all in one DOF order (the sorted
    (grid, component) pairs met in any of them), and the DOF names of that order."""
    cards = [c for c in _bulk_cards(_read_text(path, key)) if c[0] == "DMIG"]
    if not cards:
        raise InputError(key, f"{str(path)!r} holds no DMIG card", "give a bulk-data file with DMIG matrices")
    heads: dict[str, dict] = {}
    entries: dict[str, list] = {}
    for fields in cards:
        name = fields[1].strip().upper() if len(fields) > 1 else ""
        if len(fields) > 2 and fields[2].strip() == "0":
            ifo, tin = _int_field(fields, 3, path, key), _int_field(fields, 4, path, key)
            if tin not in (1, 2):
                raise InputError(
                    key, f"{str(path)!r}: DMIG {name} has TIN {tin} (complex)", "give real matrices (TIN 1 or 2)"
                )
            heads[name] = {"ifo": ifo}
            entries.setdefault(name, [])
            continue
        gj, cj = _int_field(fields, 2, path, key), _int_field(fields, 3, path, key)
        data = fields[5:]
        for k in range(0, len(data), 4):
            group = data[k : k + 4]
            if not any(f.strip() for f in group):
                continue
            gi, ci = _int_field(group, 0, path, key), _int_field(group, 1, path, key)
            try:
                a = nastran_float(group[2])
            except (ValueError, IndexError):
                raise InputError(
                    key, f"{str(path)!r}: DMIG {name} has a value {group[2:3]} that is not a number", "give real values"
                ) from None
            entries.setdefault(name, []).append(((gi, ci), (gj, cj), a))
    missing = sorted(set(entries) - set(heads))
    if missing:
        raise InputError(
            key, f"{str(path)!r}: DMIG {missing[0]} has no header card", "give its header: DMIG NAME 0 IFO TIN TOUT"
        )
    dofs = sorted({d for name in entries for e in entries[name] for d in e[:2]})
    index = {d: k for k, d in enumerate(dofs)}
    n = len(dofs)
    out = {}
    for name, items in entries.items():
        r = np.array([index[e[0]] for e in items], dtype=np.int64)
        c = np.array([index[e[1]] for e in items], dtype=np.int64)
        v = np.array([e[2] for e in items], dtype=float)
        A = sp.coo_matrix((v, (r, c)), shape=(n, n)).tocsr()
        if heads[name]["ifo"] == 6:
            A = _mirror(A)
        out[name] = A
    return out, tuple(f"{g}.{c}" for g, c in dofs)


def _int_field(fields: list[str], k: int, path: Path, key: str) -> int:
    text = fields[k].strip() if k < len(fields) else ""
    try:
        return int(text) if text else 0
    except ValueError:
        raise InputError(
            key, f"{str(path)!r}: DMIG field {text!r} is not a whole number", "give grid and component numbers"
        ) from None


def _bulk_cards(text: str) -> list[list[str]]:
    """The cards of a bulk-data text: each a list of fields, the name first (upper case),
    then the data fields of its lines and continuations in order (8 a small-field or free
    line, 4 a large-field line); ``$`` comments and the executive/case sections skipped."""
    cards: list[list[str]] = []
    for raw in text.splitlines():
        line = raw.split("$", 1)[0].rstrip().expandtabs(8)
        if not line.strip():
            continue
        marker, data = _line_fields(line)
        mark = marker.strip()
        if mark.upper().startswith(("BEGIN", "ENDDATA", "CEND")):
            continue
        if mark == "" or mark.startswith(("+", "*")):
            if cards:
                cards[-1].extend(data)
        else:
            cards.append([mark.rstrip("*").upper(), *data])
    return cards


def _line_fields(line: str) -> tuple[str, list[str]]:
    """(field 1, data fields) of one bulk-data line: free (commas), large (a ``*`` in
    field 1: 4 fields of 16 characters) or small field (8 fields of 8 characters)."""
    if "," in line:
        parts = [f.strip() for f in line.split(",")]
        return parts[0], (parts[1:9] + [""] * 8)[:8]
    if line[:8].strip().endswith("*") or line.startswith("*"):
        return line[:8], [line[8 + 16 * k : 24 + 16 * k].strip() for k in range(4)]
    return line[:8], [line[8 * k : 8 * k + 8].strip() for k in range(1, 9)]


def _mirror(A: sp.csr_matrix) -> sp.csr_matrix:
    """The full symmetric matrix of one given triangle (the diagonal counted once); a
    matrix given with both triangles is kept as it is."""
    upper, lower = sp.triu(A, 1), sp.tril(A, -1)
    if upper.nnz and lower.nnz:
        return A.tocsr()
    return (A + (upper + lower).T).tocsr()


# ----------------------------------------------------------------------------- Abaqus


def read_abaqus(path: Path, key: str) -> tuple[dict[tuple[tuple[int, int], tuple[int, int]], float], bool]:
    """The entries of one Abaqus matrix file: {((row node, row dof), (col node, col dof)):
    value} for FORMAT=MATRIX INPUT, or {((row, 0), (col, 0)): value} and coordinate=True."""
    entries: dict = {}
    kinds = set()
    for lineno, raw in enumerate(_read_text(path, key).splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("*"):
            continue
        parts = [p for p in re.split(r"[,\s]+", line) if p]
        try:
            if len(parts) == 5:
                ij = ((int(parts[0]), int(parts[1])), (int(parts[2]), int(parts[3])))
            elif len(parts) == 3:
                ij = ((int(parts[0]), 0), (int(parts[1]), 0))
            else:
                raise ValueError
            value = float(parts[-1].upper().replace("D", "E"))
        except ValueError:
            raise InputError(
                key,
                f"{str(path)!r} line {lineno}: {line[:60]!r} is not a matrix entry",
                "give Abaqus matrix output: 'node, dof, node, dof, value' (FORMAT=MATRIX INPUT) or 'row, column, value' (FORMAT=COORDINATE)",
            ) from None
        kinds.add(len(parts))
        entries[ij] = entries.get(ij, 0.0) + value
    if not entries:
        raise InputError(
            key, f"{str(path)!r} holds no matrix entry", "give an Abaqus matrix file (*MATRIX GENERATE output)"
        )
    if len(kinds) > 1:
        raise InputError(
            key,
            f"{str(path)!r} mixes 'node, dof, node, dof, value' and 'row, column, value' lines",
            "give one format per file",
        )
    return entries, kinds == {3}


def abaqus_matrices(files: dict[str, tuple[Path, str]]) -> FEMatrices:
    """FEMatrices of Abaqus matrix files {"mass" | "stiffness" | "damping": (path, key)}: the
    DOFs are the sorted (node, dof) pairs met in any file; a symmetric matrix given as one
    triangle is mirrored."""
    read = {role: (read_abaqus(p, key), p, key) for role, (p, key) in files.items()}
    coordinate = {c for (_, c), _, _ in read.values()}
    if len(coordinate) > 1:
        role = next(r for r, ((_, c), _, _) in read.items() if c)
        raise InputError(
            files[role][1],
            "is in COORDINATE format and the other files are not",
            "write every matrix with the same FORMAT",
        )
    if coordinate == {True}:
        n = max(max(i[0], j[0]) for (e, _), _, _ in read.values() for i, j in e)
        dofs = [(k, 0) for k in range(1, n + 1)]
    else:
        dofs = sorted({d for (e, _), _, _ in read.values() for ij in e for d in ij})
    index = {d: k for k, d in enumerate(dofs)}
    n = len(dofs)
    out = {}
    for role, ((entries, _), _, _) in read.items():
        r = np.array([index[i] for i, _ in entries], dtype=np.int64)
        c = np.array([index[j] for _, j in entries], dtype=np.int64)
        out[role] = _mirror(sp.coo_matrix((np.array(list(entries.values())), (r, c)), shape=(n, n)).tocsr())
    names = () if coordinate == {True} else tuple(f"{g}.{c}" for g, c in dofs)
    source = "abaqus: " + ", ".join(str(p) for p, _ in files.values())
    return _checked(
        out["mass"], out["stiffness"], out.get("damping"), names, source, {r: k for r, (_, k) in files.items()}
    )


# ----------------------------------------------------------------------------- ANSYS


def read_ansys_full(path: Path, key: str) -> FEMatrices:
    """M and K of an ANSYS .full file through ansys-mapdl-reader (``load_km``, sorted by
    node and DOF); the reader's DOF index 0, 1, 2 (x, y, z) ... becomes component 1, 2, 3 ..."""
    try:
        from ansys.mapdl import reader as mapdl_reader
    except ImportError:
        raise InputError(
            key,
            f"is {str(path)!r}, an ANSYS .full file, and ansys-mapdl-reader is not installed",
            "pip install ansys-mapdl-reader (or export M and K to Matrix Market with HBMAT / APDL Math)",
        ) from None
    try:
        dof_ref, k, m = mapdl_reader.read_binary(str(path)).load_km(as_sparse=True, sort=True)
    except Exception as exc:  # the reader raises plain Exceptions on bad files
        raise InputError(
            key,
            f"{str(path)!r} cannot be read as an ANSYS .full file ({exc})",
            "give a .full file of a modal or harmonic analysis",
        ) from None
    return ansys_matrices(np.asarray(dof_ref), k, m, f"ansys: {path}", key)


def ansys_matrices(dof_ref: np.ndarray, k, m, source: str, key: str) -> FEMatrices:
    """FEMatrices of ansys-mapdl-reader's (dof_ref, k, m); k and m may hold one triangle."""
    names = tuple(f"{int(node)}.{int(d) + 1}" for node, d in dof_ref)
    K, M = (_mirror(sp.csr_matrix(A)) for A in (k, m))
    return _checked(M, K, None, names, source, {"mass": key, "stiffness": key})


# ----------------------------------------------------------------------------- one entry point


def read_fe_file(
    path: Path,
    key: str,
    fmt: str | None = None,
    names: dict[str, str | None] | None = None,
) -> FEMatrices:
    """FEMatrices of one OP4, DMIG or ANSYS file; ``names`` the matrix names inside it
    ({"mass": ..., "stiffness": ..., "damping": ...}, None: the usual names)."""
    if not path.is_file():
        raise InputError(key, f"file {str(path)!r} not found", "give a path relative to the case file")
    fmt = format_of(path, fmt, key)
    if fmt == "ansys":
        return read_ansys_full(path, key)
    if fmt == "abaqus":
        raise InputError(
            key,
            "is for OP4, DMIG and ANSYS files",
            'give Abaqus matrix files as mass_file_kg and stiffness_file_N_per_m with format = "abaqus"',
        )
    if fmt == "op4":
        matrices, dofs = read_op4(path, key), ()
    else:
        matrices, dofs = read_dmig(path, key)
    chosen = {
        role: _pick(matrices, role, (names or {}).get(role), path, key) for role in ("mass", "stiffness", "damping")
    }
    if chosen["stiffness"] is None:
        raise InputError(
            key, f"{str(path)!r} has no stiffness matrix ({', '.join(matrices)})", 'name it: stiffness_matrix = "KAA"'
        )
    base = key.rsplit(" ", 1)[0]
    return _checked(
        chosen["mass"],
        chosen["stiffness"],
        chosen["damping"],
        dofs,
        f"{fmt}: {path}",
        {r: f"{base} {r}_matrix" for r in ("mass", "stiffness", "damping")},
    )


def _pick(matrices: dict, role: str, name: str | None, path: Path, key: str):
    """The matrix of a role: the one named, else the first of the usual names present."""
    base = key.rsplit(" ", 1)[0]
    if name is not None:
        if name.upper() not in matrices:
            raise InputError(
                f"{base} {role}_matrix",
                f"is {name!r}, not a matrix of {str(path)!r} ({', '.join(matrices)})",
                f"give one of {', '.join(matrices)}",
            )
        return matrices[name.upper()]
    for candidate in _DEFAULT_NAMES[role]:
        if candidate in matrices:
            return matrices[candidate]
    if role == "mass":
        raise InputError(
            f"{base} mass_matrix",
            f"is not given and {str(path)!r} has none of the usual names ({', '.join(matrices)})",
            f"name it: mass_matrix = one of {', '.join(matrices)}",
        )
    return None


def _checked(M, K, C, dofs: tuple, source: str, keys: dict) -> FEMatrices:
    """FEMatrices after the checks every file gets: square, one size, symmetric mass."""
    n = M.shape[0]
    for role, A in (("mass", M), ("stiffness", K), ("damping", C)):
        if A is None:
            continue
        if A.shape[0] != A.shape[1]:
            raise InputError(
                keys[role],
                f"{role} matrix of {source} is {A.shape[0]} x {A.shape[1]}, not square",
                "give a square matrix",
            )
        if A.shape[0] != n:
            raise InputError(
                keys[role],
                f"{role} matrix of {source} is {A.shape[0]} x {A.shape[0]}, the mass {n} x {n}",
                "give matrices of the same DOF set",
            )
        asym = abs(A - A.T).max() if A.nnz else 0.0
        scale = abs(A).max() if A.nnz else 0.0
        if asym > 1e-10 * scale:
            raise InputError(
                keys[role],
                f"{role} matrix of {source} is not symmetric (|A - A^T| = {asym:.3g}, |A| = {scale:.3g})",
                "give a symmetric matrix (a structural M, C, K)",
            )
    if dofs and len(dofs) != n:
        raise InputError(keys["mass"], f"of {source} has {n} DOFs and {len(dofs)} DOF names", "give a complete file")
    return FEMatrices(M.tocsr(), K.tocsr(), None if C is None else C.tocsr(), tuple(dofs), source)


def _read_text(path: Path, key: str) -> str:
    if not path.is_file():
        raise InputError(key, f"file {str(path)!r} not found", "give a path relative to the case file")
    try:
        return path.read_text(encoding="utf-8", errors="strict")
    except UnicodeDecodeError:
        raise InputError(
            key, f"{str(path)!r} is not a text file", "give the text (FORMATTED / ASCII) form of the file"
        ) from None


def _is_binary(path: Path) -> bool:
    return b"\x00" in path.read_bytes()[:512]


# ----------------------------------------------------------------------------- contact faces


def face_gathers(nodes, normal, tangent, rows: int, dofs: tuple[str, ...], key: str) -> list[tuple[int, sp.csr_matrix]]:
    """One gather map A per node of a contact face: rows (t1, [t2,] n) of unit directions,
    ``A[r] . x = d_r . u(node)`` with u(node) = (x[node.1], x[node.2], x[node.3]).

    t1 is ``tangent`` made normal to n (or the axis least aligned with n), t2 = n x t1."""
    n = _unit(normal, f"{key}: normal")
    if tangent is None:
        axis = np.eye(3)[int(np.argmin(abs(n)))]
    else:
        axis = np.asarray(tangent, dtype=float)
    t1 = axis - (axis @ n) * n
    if np.linalg.norm(t1) < 1e-9 * max(np.linalg.norm(axis), 1.0):
        raise InputError(f"{key}: tangent", "is parallel to the normal", "give a tangent direction across the normal")
    t1 /= np.linalg.norm(t1)
    directions = [t1, n] if rows == 2 else [t1, np.cross(n, t1), n]
    index = {name: k for k, name in enumerate(dofs)}
    out = []
    for node in nodes:
        cols, vals, rr = [], [], []
        for r, d in enumerate(directions):
            for comp in range(3):
                if abs(d[comp]) < 1e-15:
                    continue
                name = f"{int(node)}.{comp + 1}"
                if name not in index:
                    raise InputError(
                        f"{key}: nodes",
                        f"node {node}: the structure has no DOF {name!r}",
                        "give nodes of the structure's file whose translations the face moves (names '<node>.<component>')",
                    )
                rr.append(r)
                cols.append(index[name])
                vals.append(d[comp])
        out.append((int(node), sp.csr_matrix((vals, (rr, cols)), shape=(rows, len(dofs)))))
    return out


def _unit(v, key: str) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) == 0.0:
        raise InputError(key, f"is {v!r}", "give three numbers, not all zero: the outward normal [nx, ny, nz]")
    return a / np.linalg.norm(a)


# ----------------------------------------------------------------------------- the case file


def case_structure(s, base: Path) -> FEMatrices | None:
    """The FEMatrices a ``[structure]`` table names, or None when it names no FE file.

    ``file`` (+ ``format``, ``mass_matrix``, ``stiffness_matrix``, ``damping_matrix``): an
    OP4, DMIG or ANSYS file; ``format = "abaqus"``: the Abaqus files given as
    ``mass_file_kg``, ``stiffness_file_N_per_m`` (and ``damping_file_N_s_per_m``)."""
    fmt = getattr(s, "format", None)
    if getattr(s, "file", None) is None and fmt != "abaqus":
        for key in ("format", "mass_matrix", "stiffness_matrix", "damping_matrix"):
            if getattr(s, key, None) is not None:
                raise InputError(f"[structure] {key}", "is given without file", "give file = the FE file, or remove it")
        return None
    inline = [k for k in ("mass_kg", "damping_N_s_per_m", "stiffness_N_per_m") if getattr(s, k) is not None]
    if inline:
        raise InputError(
            f"[structure] {inline[0]}",
            "and an FE file are both given",
            "give the matrices once: inline or from the file",
        )
    if fmt == "abaqus":
        if getattr(s, "file", None) is not None:
            raise InputError(
                "[structure] file",
                'is given with format = "abaqus"',
                "give the Abaqus files as mass_file_kg and stiffness_file_N_per_m (one matrix a file)",
            )
        roles = {"mass": "mass_file_kg", "stiffness": "stiffness_file_N_per_m", "damping": "damping_file_N_s_per_m"}
        files = {}
        for role, key in roles.items():
            value = getattr(s, key)
            if value is None:
                if role != "damping":
                    raise InputError(
                        f"[structure] {key}",
                        "is missing",
                        f"give the Abaqus {role} matrix file (*MATRIX GENERATE output)",
                    )
                continue
            path = base / value
            if not path.is_file():
                raise InputError(
                    f"[structure] {key}", f"file {str(path)!r} not found", "give a path relative to the case file"
                )
            files[role] = (path, f"[structure] {key}")
        fe = abaqus_matrices(files)
    else:
        given = [
            k for k in ("mass_file_kg", "damping_file_N_s_per_m", "stiffness_file_N_per_m") if getattr(s, k) is not None
        ]
        if given:
            raise InputError(
                f"[structure] {given[0]}", "and file are both given", "give the matrices once: file or the matrix files"
            )
        names = {role: getattr(s, f"{role}_matrix", None) for role in ("mass", "stiffness", "damping")}
        fe = read_fe_file(base / s.file, "[structure] file", fmt, names)
    if fe.dofs and s.dof_names is not None:
        raise InputError(
            "[structure] dof_names",
            f"is given and {fe.source} names its DOFs",
            "remove dof_names: the DOFs are named '<node>.<component>' from the file",
        )
    return fe


def case_face_contacts(c, i: int, dofs: tuple[str, ...]) -> list[tuple[str, sp.csr_matrix]] | None:
    """The (name, gather map) of each node of a contact face given as ``nodes`` + ``normal``
    (named ``"<name>.<node>"``), or None when the contact gives dof_gather instead."""
    where = f"[[contacts]] {i + 1} ({c.name})"
    if c.nodes is None:
        for key in ("normal", "tangent"):
            if getattr(c, key) is not None:
                raise InputError(
                    f"{where}: {key}", "is given without nodes", "give nodes = [node ids] of the face, or remove it"
                )
        return None
    if c.dof_gather is not None or c.dof_gather_entries is not None:
        raise InputError(
            f"{where}: nodes", "and dof_gather are both given", "give the face once: nodes + normal, or dof_gather"
        )
    if c.normal is None:
        raise InputError(f"{where}: normal", "is missing", "give normal = [nx, ny, nz], the face's outward normal")
    if not c.nodes:
        raise InputError(f"{where}: nodes", "is empty", "give the node ids of the face")
    if len(set(c.nodes)) != len(c.nodes):
        raise InputError(f"{where}: nodes", "lists a node twice", "give each node once")
    rows = c.dof_gather_rows
    if rows not in (2, 3):
        raise InputError(
            f"{where}: dof_gather_rows", f"is {rows!r}", "give 2 (tangent, normal) or 3 (two tangents, normal)"
        )
    gathers = face_gathers(c.nodes, c.normal, c.tangent, rows, dofs, where)
    return [(f"{c.name}.{node}", A) for node, A in gathers]

"""A System is the whole model (structure + contacts + excitation); compile() makes arrays.

The :class:`CompiledSystem` is the only thing kernels see: contiguous float64/int64
arrays, one contact *direction* per tangential direction (each with its own slider and
state), and the signals of :mod:`slipstep.model.excitation` in compiled form.

Legend: n DOFs, m motion components, nq local coordinates (all contacts stacked),
nc contacts, nd tangential directions (= sliders = state entries).

Two backends (``CompiledSystem.banded``):

* dense: M, C, K (n, n) and A (nq, n) as dense arrays, DOFs in the user's order;
* banded (issue 10; sparse structures of at least BANDED_MIN_N DOFs, or on request): the DOFs
  reordered by reverse Cuthill-McKee of the pattern of M + C + K + sum_c A_c^T A_c (each
  contact's rows together, so that the normal-tangential cross terms of a slip tangent stay
  in the band), M, C, K in band storage (kernels/banded.py; kl = ku = the bandwidth) and
  A as CSR; the dense fields are empty placeholders of shape (n, 0) / (nq, 0) (their first
  axis still gives n and nq). Kernel arrays are in the kernel order ``dof_order``
  (kernel DOF k is the user's DOF dof_order[k]); :func:`kernel_dofs` maps user DOF indices
  to kernel ones (the one map: the save plan stores the saved columns in the user's order
  through it, methods/save.py), :func:`to_user_order` puts a DOF-indexed kernel array back.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from slipstep.errors import InputError
from slipstep.kernels.codes import N_LAW_PAR, P_KN, P_MU
from slipstep.model.contact import ContactElement
from slipstep.model.excitation import Excitation, compile_signal
from slipstep.model.structure import Structure
from slipstep.model.validate import check_name, float_array
from slipstep.model.validate import names as name_sequence

#: sparse structures of at least this many DOFs compile to the banded backend ("auto")
BANDED_MIN_N = 300


class CompiledSystem(NamedTuple):
    M: np.ndarray  # (n, n) kg
    C: np.ndarray  # (n, n) N s/m
    K: np.ndarray  # (n, n) N/m
    A: np.ndarray  # (nq, n) gather from DOFs
    AT: np.ndarray  # (n, nq) its transpose, contiguous (scatter A^T f)
    B: np.ndarray  # (nq, m) gather from prescribed motions
    g: np.ndarray  # (nq,) offsets (normal interference)
    normal_row: np.ndarray  # (nc,) int64 row of v in q
    kn: np.ndarray  # (nc,) N/m (= law_par[:, P_KN], for readers of results)
    mu: np.ndarray  # (nc,) (= law_par[:, P_MU])
    first_direction: np.ndarray  # (nc,) int64 index of the contact's first direction
    n_directions: np.ndarray  # (nc,) int64 1 (2D) or 2 (quasi-3D)
    tangential_row: np.ndarray  # (nd,) int64 row of u in q
    direction_contact: np.ndarray  # (nd,) int64 owning contact
    kt: np.ndarray  # (nd,) N/m
    constant_force: np.ndarray  # (n,) N
    force_frequency: np.ndarray
    force_sin: np.ndarray
    force_cos: np.ndarray
    force_table_time: np.ndarray
    force_table_value: np.ndarray
    force_ramp: float
    motion_frequency: np.ndarray
    motion_sin: np.ndarray
    motion_cos: np.ndarray
    motion_table_time: np.ndarray
    motion_table_value: np.ndarray
    motion_ramp: float
    length_scale: float  # m, for tolerances
    law: np.ndarray  # (nc,) int64 contact-law code (kernels/codes.py LAW_*, names in model.contact.CONTACT_LAWS)
    law_par: np.ndarray  # (nc, N_LAW_PAR) the law parameter table: P_KN k_n [N/m], P_MU mu (kernels read these)
    banded: bool  # the banded backend (module docstring): M, C, K in Mb, Cb, Kb; A in the CSR arrays
    kl: int  # sub- and superdiagonals of the band (0 for the dense backend)
    ku: int
    Mb: np.ndarray  # (n, kl + ku + 1) band storage of M (kernels/banded.py), (0, 1) placeholder when dense
    Cb: np.ndarray
    Kb: np.ndarray
    A_ptr: np.ndarray  # int64 (nq + 1) CSR of A (both backends)
    A_idx: np.ndarray  # int64 (nnz)
    A_val: np.ndarray  # (nnz)
    AT_ptr: np.ndarray  # int64 (n + 1) CSR of A^T
    AT_idx: np.ndarray
    AT_val: np.ndarray
    dof_order: np.ndarray  # int64 (n): kernel DOF k is the user's DOF dof_order[k] (identity when dense)


class SparseCompiledSystem(CompiledSystem):
    """The compiled system of the condensed sparse backend (issue 26, kernels/sparse.py): the
    'contacts' layout (M, C, K fields empty (n, 0); A dense and in CSR; the user's DOF order)
    with the structure's matrices as scipy CSR in the attribute ``matrices`` (M, C, K), which
    the kernel's arrays and the Python products are made from (not a field: numba sees the
    fields only)."""

    def _replace(self, **changes):
        new = CompiledSystem._replace(self, **changes)
        new.matrices = self.matrices
        return new


def is_sparse(cs) -> bool:
    """Is ``cs`` compiled for the condensed sparse backend?"""
    return isinstance(cs, SparseCompiledSystem)


@dataclass(frozen=True)
class System:
    """Structure + contact elements + excitation; validated once, then compiled to arrays."""

    structure: Structure
    contacts: tuple[ContactElement, ...]
    excitation: Excitation = field(default_factory=Excitation)
    motion_names: tuple[str, ...] = ()
    name: str = "system"

    def __post_init__(self):
        if not isinstance(self.structure, Structure):
            raise InputError(
                "structure",
                f"is {type(self.structure).__name__} {_shown(self.structure)}, not a Structure",
                "give slipstep.Structure(mass, damping, stiffness); to load a case by name use "
                "slipstep.load_system(name)",
            )
        n = self.structure.n_dofs
        contacts = _contacts(self.contacts)
        if not isinstance(self.excitation, Excitation):
            raise InputError(
                "excitation",
                f"is {type(self.excitation).__name__}, not an Excitation",
                "give slipstep.Excitation(constant_force=..., force=..., motion=...)",
            )
        name_sequence("motion_names", self.motion_names, "motion component", unique=False)
        names = [c.name for c in contacts]
        if len(set(names)) != len(names):
            raise InputError("contacts", f"names are not unique: {names}", "give every contact its own name")
        check_name("name", self.name)
        for kind, values in (
            ("contacts", names),
            ("motion_names", self.motion_names),
            ("structure.dof_names", self.structure.dof_names),
        ):
            for value in values:
                check_name(kind, value)
        motion_names = tuple(self.motion_names)
        if len(set(motion_names)) != len(motion_names):
            raise InputError(
                "motion_names",
                f"are not unique: {list(motion_names)}",
                "give every prescribed motion component its own name",
            )
        if self.excitation.motion is not None:
            if motion_names and motion_names != self.excitation.motion.components:
                raise InputError(
                    "excitation.motion.components",
                    f"{self.excitation.motion.components} differ from motion_names {motion_names}",
                    "use the same component names",
                )
            motion_names = self.excitation.motion.components
        m = len(motion_names)
        for c in contacts:
            if c.dof_gather.shape[1] != n:
                raise InputError(
                    f"contacts[{c.name}].dof_gather",
                    f"has {c.dof_gather.shape[1]} columns, structure has {n} DOFs",
                    f"give {n} columns",
                )
            if c.motion_gather is not None and c.motion_gather.shape[1] != m:
                raise InputError(
                    f"contacts[{c.name}].motion_gather",
                    f"has {c.motion_gather.shape[1]} columns for {m} motion components {motion_names}",
                    f"give {m} columns, one per prescribed motion component",
                )
        exc = self.excitation
        if exc.constant_force is not None:
            object.__setattr__(
                exc, "constant_force", float_array("excitation.constant_force", exc.constant_force, shape=(n,))
            )
        if exc.force is not None and len(exc.force.components) != n:
            raise InputError(
                "excitation.force.components",
                f"has {len(exc.force.components)} components, structure has {n} DOFs",
                "give one force component per DOF",
            )
        object.__setattr__(self, "contacts", contacts)
        object.__setattr__(self, "motion_names", motion_names)

    @property
    def n_dofs(self) -> int:
        return self.structure.n_dofs

    @property
    def contact_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.contacts)

    def local_coordinate_names(self) -> list[tuple[str, str]]:
        """(contact, component) per local row: components u / u1, u2 and v."""
        rows = []
        for c in self.contacts:
            tang = ["u"] if c.n_tangential == 1 else ["u1", "u2"]
            rows += [(c.name, comp) for comp in tang + ["v"]]
        return rows

    def direction_names(self) -> list[str]:
        """One label per tangential direction (slider): 'P1' or 'P1.u1', 'P1.u2'."""
        out = []
        for c in self.contacts:
            out += [c.name] if c.n_tangential == 1 else [f"{c.name}.u1", f"{c.name}.u2"]
        return out

    @property
    def period(self) -> float | None:
        f = self.excitation.fundamental_frequency
        return None if f is None else 1.0 / f

    def compile_for_frequency_domain(self) -> CompiledSystem:
        """The dense backend, or for a sparse structure the 'contacts' backend (its matrices
        stay sparse and are factorised per frequency by the caller)."""
        return self.compile("contacts" if self.structure.sparse else "dense")

    def compile_dense(self, feature: str) -> CompiledSystem:
        """The dense backend for a feature that needs dense n x n matrices (``feature`` names it
        in the refusal: a sparse structure above model.structure.DENSE_MAX_N DOFs)."""
        if self.structure.sparse:
            self.structure.dense_matrices("structure", feature)  # refuses a large sparse model
        return self.compile("dense")

    def compile(self, backend: str = "auto") -> CompiledSystem:
        """The kernel arrays; ``backend`` 'auto' (banded for a sparse structure of at least
        BANDED_MIN_N DOFs whose band is narrow, else dense), 'dense', 'banded' or 'contacts'
        (the contact arrays in the user's DOF order, M, C and K left empty (n, 0): for the
        frequency-domain solvers that factorise the structure's sparse matrices themselves) or
        'sparse' (the 'contacts' layout holding the matrices: :class:`SparseCompiledSystem`)."""
        s = self.structure
        if backend == "sparse":
            cs = SparseCompiledSystem(*self.compile("contacts"))
            cs.matrices = tuple(sp.csr_matrix(X) for X in (s.mass, s.damping, s.stiffness))
            return cs
        n, m = s.n_dofs, len(self.motion_names)
        A_rows, B_rows, g = [], [], []
        normal_row, kn, mu, first_dir, n_dir = [], [], [], [], []
        tan_row, dir_contact, kt = [], [], []
        row = 0
        for ic, c in enumerate(self.contacts):
            nrow = c.dof_gather.shape[0]
            A_rows.append(c.dof_gather)
            B_rows.append(np.zeros((nrow, m)) if c.motion_gather is None else c.motion_gather)
            g += [0.0] * (nrow - 1) + [c.normal_offset]
            first_dir.append(len(tan_row))
            n_dir.append(c.n_tangential)
            for d in range(c.n_tangential):
                tan_row.append(row + d)
                dir_contact.append(ic)
                kt.append(c.tangential_stiffness[d])
            normal_row.append(row + nrow - 1)
            kn.append(c.normal_stiffness)
            mu.append(c.friction_coefficient)
            row += nrow
        if any(sp.issparse(X) for X in A_rows):
            A = sp.vstack([sp.csr_matrix(X) for X in A_rows], format="csr")
        else:
            A = np.vstack(A_rows) if A_rows else np.zeros((0, n))
        exc = self.excitation
        f0 = np.zeros(n) if exc.constant_force is None else np.asarray(exc.constant_force, float)
        fs = compile_signal(exc.force, n)
        ms = compile_signal(exc.motion, m)
        scale = _length_scale(f0, fs, ms, np.concatenate([np.array(kn, float), s.diagonal("stiffness")]))
        banded, order, bw = _choose_backend(s, self.contacts, A, backend)
        as_i = lambda v: np.ascontiguousarray(np.asarray(v, dtype=np.int64))
        as_f = lambda v: np.ascontiguousarray(np.asarray(v, dtype=np.float64))
        if banded:
            A = sp.csr_matrix(A)[:, order].tocsr()
            f0 = f0[order]
            fs = fs._replace(
                sin_coefficient=fs.sin_coefficient[order],
                cos_coefficient=fs.cos_coefficient[order],
                table_value=np.ascontiguousarray(fs.table_value[order]),
            )
            dense = (np.zeros((n, 0)),) * 3
            Ad, ATd = np.zeros((row, 0)), np.zeros((n, 0))
            bands = tuple(_band_storage(X, order, bw) for X in (s.mass, s.damping, s.stiffness))
        elif backend == "contacts":  # the contact arrays only: the caller keeps the structure's own matrices
            dense = (np.zeros((n, 0)),) * 3
            Ad = A.toarray() if sp.issparse(A) else A
            ATd = Ad.T
            bands = (np.zeros((0, 1)),) * 3
        else:
            dense = tuple(X.toarray() if sp.issparse(X) else X for X in (s.mass, s.damping, s.stiffness))
            Ad = A.toarray() if sp.issparse(A) else A
            ATd = Ad.T
            bands = (np.zeros((0, 1)),) * 3
        A, AT = _csr_pair(A)
        return CompiledSystem(
            as_f(dense[0]),
            as_f(dense[1]),
            as_f(dense[2]),
            as_f(Ad),
            as_f(ATd),
            as_f(np.vstack(B_rows) if B_rows else np.zeros((0, m))).reshape(row, m),
            as_f(g),
            as_i(normal_row),
            as_f(kn),
            as_f(mu),
            as_i(first_dir),
            as_i(n_dir),
            as_i(tan_row),
            as_i(dir_contact),
            as_f(kt),
            as_f(f0),
            as_f(fs.frequency),
            as_f(fs.sin_coefficient),
            as_f(fs.cos_coefficient),
            as_f(fs.table_time),
            as_f(fs.table_value),
            float(fs.ramp_time),
            as_f(ms.frequency),
            as_f(ms.sin_coefficient),
            as_f(ms.cos_coefficient),
            as_f(ms.table_time),
            as_f(ms.table_value),
            float(ms.ramp_time),
            scale,
            as_i([c.law_code for c in self.contacts]),
            _law_table(kn, mu),
            bool(banded),
            int(bw),
            int(bw),
            as_f(bands[0]),
            as_f(bands[1]),
            as_f(bands[2]),
            as_i(A.indptr),
            as_i(A.indices),
            as_f(A.data),
            as_i(AT.indptr),
            as_i(AT.indices),
            as_f(AT.data),
            as_i(order),
        )


def _shown(value) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _contacts(value) -> tuple:
    """The contact elements: a list or tuple of ContactElement (one element alone is refused)."""
    if isinstance(value, ContactElement):
        raise InputError(
            "contacts", "is one ContactElement, not a sequence of them", "give a tuple or list: (contact,)"
        )
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise InputError(
            "contacts",
            f"is {type(value).__name__} {_shown(value)}, not a sequence",
            "give a tuple or list of ContactElement",
        )
    contacts = tuple(value)
    for i, c in enumerate(contacts):
        if not isinstance(c, ContactElement):
            raise InputError(
                f"contacts[{i}]", f"is {type(c).__name__} {_shown(c)}, not a ContactElement", "give ContactElement(...)"
            )
    return contacts


def structure_matrix(cs: CompiledSystem, which: str):
    """M, C or K (``which`` 'M', 'C', 'K') in the kernel DOF order: the dense array, or for the
    banded backend a scipy.sparse CSR matrix built from its band storage (for products only), for
    the sparse backend the structure's own CSR matrix."""
    if is_sparse(cs):
        return cs.matrices["MCK".index(which)]
    if not cs.banded:
        return getattr(cs, which)
    ab = getattr(cs, which + "b")
    n, ku = ab.shape[0], cs.ku
    cols, t = np.nonzero(ab)
    rows = cols + t - ku
    return sp.csr_matrix((ab[cols, t], (rows, cols)), shape=(n, n))


def quadratic_form(A, X: np.ndarray) -> np.ndarray:
    """x_t^T A x_t per row of X (nt, n), A dense or sparse (the product X A by BLAS, then a row-wise
    dot: a three-operand einsum loops in C without BLAS, 10x slower at n = 31)."""
    XA = np.asarray((A @ np.ascontiguousarray(X.T)).T) if sp.issparse(A) else X @ A
    return np.einsum("ti,ti->t", XA, X)


def kernel_dofs(cs: CompiledSystem, user_dofs) -> np.ndarray:
    """The kernel indices of user DOF indices (the banded backend reorders the DOFs; identity
    for the dense backend): kernel arrays hold user DOF i at position kernel_dofs(cs, i)."""
    order = np.asarray(cs.dof_order)
    inverse = np.empty_like(order)
    inverse[order] = np.arange(order.size)
    return inverse[np.asarray(user_dofs, dtype=np.int64)]


def to_user_order(cs: CompiledSystem, values: np.ndarray, axis: int = -1) -> np.ndarray:
    """DOF-indexed kernel values (DOFs along ``axis``) in the user's DOF order (itself when the
    backend keeps the order)."""
    if not cs.banded:
        return values
    return np.take(values, kernel_dofs(cs, np.arange(len(cs.dof_order))), axis=axis)


def _csr_pair(A) -> tuple:
    """(A, A^T) as sorted CSR matrices (a dense A converted by its non-zeros)."""
    if not sp.issparse(A):
        rows, cols = np.nonzero(A)
        indptr = np.zeros(A.shape[0] + 1, np.int64)
        np.cumsum(np.bincount(rows, minlength=A.shape[0]), out=indptr[1:])
        A = sp.csr_matrix((A[rows, cols], cols, indptr), shape=A.shape)
    A = sp.csr_matrix(A)
    A.sort_indices()
    AT = A.T.tocsr()
    AT.sort_indices()
    return A, AT


def _pattern(structure: Structure, contacts, A) -> sp.csr_matrix:
    """The sparsity pattern of M + C + K + sum_c S_c^T S_c, S_c the union of contact c's rows
    (every product of two of its rows can enter J(S): a slip tangent couples u and v)."""
    P = sp.csr_matrix((structure.n_dofs, structure.n_dofs))
    for X in (structure.mass, structure.damping, structure.stiffness):
        P = P + abs(sp.csr_matrix(X))
    if A.shape[0]:
        rows = np.repeat(np.arange(len(contacts)), [c.dof_gather.shape[0] for c in contacts])
        G = sp.csr_matrix((np.ones(rows.size), (rows, np.arange(rows.size))), shape=(len(contacts), rows.size))
        S = (G @ abs(sp.csr_matrix(A))).tocsr()
        S.data[:] = 1.0
        P = P + S.T @ S
    P = P.tocsr()
    P.data[:] = 1.0
    return P


def _bandwidth(P: sp.csr_matrix, order: np.ndarray) -> int:
    """max |i - j| over the pattern's non-zeros in the order ``order``."""
    coo = P.tocoo()
    if coo.nnz == 0:
        return 0
    inverse = np.empty_like(order)
    inverse[order] = np.arange(order.size)
    return int(np.abs(inverse[coo.row] - inverse[coo.col]).max())


_ORDER_CACHE: dict = {}


def _choose_backend(structure: Structure, contacts, A, backend: str) -> tuple[bool, np.ndarray, int]:
    """(banded, dof_order, bandwidth) for the backend option (see System.compile)."""
    n = structure.n_dofs
    identity = np.arange(n, dtype=np.int64)
    if backend not in ("auto", "dense", "banded", "contacts"):
        raise InputError("linear_solver", f"backend {backend!r}", "use 'auto', 'dense', 'banded' or 'sparse'")
    if backend in ("dense", "contacts") or (backend == "auto" and (not structure.sparse or n < BANDED_MIN_N)):
        return False, identity, 0
    key = tuple(id(c.dof_gather) for c in contacts)  # the order of these matrices, computed once
    cached = _ORDER_CACHE.get(id(structure))
    if cached is not None and cached[0] is structure and cached[1] == key:
        order, bw = cached[2], cached[3]
    else:
        from scipy.sparse.csgraph import reverse_cuthill_mckee

        P = _pattern(structure, contacts, A)
        order = np.asarray(reverse_cuthill_mckee(P, symmetric_mode=True), dtype=np.int64)
        bw = _bandwidth(P, order)
        _ORDER_CACHE.clear()  # one entry: the last structure compiled (the twins of a run share it)
        _ORDER_CACHE[id(structure)] = (structure, key, order, bw)
    if backend == "auto" and 3 * bw + 1 > n // 4:  # a wide band: the dense backend is no slower
        return False, identity, 0
    return True, order, bw


def _band_storage(X, order: np.ndarray, bw: int) -> np.ndarray:
    """X[order][:, order] in band storage (n, 2 bw + 1): ab[j, bw + i - j] = X[i, j]."""
    n = order.size
    Xp = sp.csr_matrix(X)[order][:, order].tocoo()
    ab = np.zeros((n, 2 * bw + 1))
    np.add.at(ab, (Xp.col, bw + Xp.row - Xp.col), Xp.data)
    return ab


def _law_table(kn, mu) -> np.ndarray:
    """The law parameter table (nc, N_LAW_PAR), columns kernels.codes.P_*."""
    table = np.zeros((len(kn), N_LAW_PAR))
    table[:, P_KN] = kn
    table[:, P_MU] = mu
    return table


def _length_scale(f0, fs, ms, stiffnesses) -> float:
    """A displacement scale [m] for tolerances: the larger of the motion amplitude and the
    static deflection ``|f| / k`` the loads produce (k the largest contact normal or structural
    diagonal stiffness), never below 1 nm."""
    motion = max(
        np.abs(ms.sin_coefficient).sum(initial=0.0) + np.abs(ms.cos_coefficient).sum(initial=0.0),
        np.abs(ms.table_value).max(initial=0.0),
    )
    force = max(
        np.abs(f0).sum(),
        np.abs(fs.sin_coefficient).sum(initial=0.0) + np.abs(fs.cos_coefficient).sum(initial=0.0),
        np.abs(fs.table_value).max(initial=0.0),
    )
    k = stiffnesses.max(initial=0.0)
    return float(max(motion, force / k if k > 0 else 0.0, 1e-9))

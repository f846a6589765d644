"""Substructures: named linear models that an assembly joins with contacts (SI units).

A :class:`Substructure` holds ``M``, ``K`` (dense or scipy.sparse), a damping description
and named DOFs; named *points* say which DOFs carry a point's motion (x, y and optionally
the rotation rz of a 2D node) and where the point is [m]. Three ways to get one:

* :func:`frame_blade`: a 2D cantilever Euler-Bernoulli frame (axial + bending, 3 DOFs per
  node: x, y, rz), clamped at the root, with named ``platform`` and ``tip`` nodes. Element
  matrices in local axes (s along the beam, n across it; Przemieniecki 1968)

      K_axial = EA/l [[1, -1], [-1, 1]],  M_axial = rho A l / 6 [[2, 1], [1, 2]]
      K_bend  = EI/l^3 [[12, 6l, -12, 6l], [6l, 4l^2, -6l, 2l^2], [-12, -6l, 12, -6l], [6l, 2l^2, -6l, 4l^2]]
      M_bend  = rho A l / 420 [[156, 22l, 54, -13l], [22l, 4l^2, 13l, -3l^2], [54, 13l, 156, -22l], [-13l, -3l^2, -22l, 4l^2]]

  rotated to global axes (consistent mass);
* :func:`load_npz` / :func:`load_mtx`: imported reduced (or full) models, dense or sparse;
* :func:`craig_bampton`: a fixed-interface reduction onto named boundary DOFs b plus the
  lowest ``n_modes`` fixed-interface modes of the interior i (Craig & Bampton 1968):

      x = T [x_b; eta],   T = [[I, 0], [Psi, Phi]],   Psi = -K_ii^-1 K_ib,
      K_ii Phi = M_ii Phi Omega^2,   M_r = T^T M T,   K_r = T^T K T

  each mode scaled so that its largest translational interior entry is 1 (eta in m).

Damping: a matrix ``C``, or Rayleigh ``C = alpha M + beta K``, or a modal damping ratio
zeta of every mode of the substructure alone, ``C = M Phi diag(2 zeta omega_k) Phi^T M``
with mass-normalised ``Phi`` (Phi^T M Phi = I).
"""

from __future__ import annotations

import math
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from slipstep.errors import InputError
from slipstep.output.io import atomic_path
from slipstep.model.structure import Structure
from slipstep.model.validate import positive

COMPONENTS = ("x", "y", "rz")


@dataclass(frozen=True)
class Point:
    """A named point of a substructure: ``dofs`` maps a motion component (x, y, rz) to the
    DOF carrying it (a missing component does not move); ``position`` (X, Y) [m]."""

    dofs: dict
    position: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class Substructure:
    """Mass [kg] and stiffness [N/m] (dense or sparse), damping, DOF names and units, points.

    Damping: at most one of ``damping`` (a matrix [N s/m]), ``rayleigh`` (alpha [1/s], beta
    [s]) and ``modal_damping_ratio`` (zeta of every mode); none: undamped."""

    name: str
    mass: object
    stiffness: object
    dof_names: tuple[str, ...] = ()
    dof_units: tuple[str, ...] = ()
    damping: object = None
    rayleigh: tuple[float, float] | None = None
    modal_damping_ratio: float | None = None
    points: dict = field(default_factory=dict)

    def __post_init__(self):
        where = f"substructures[{self.name}]"
        if not isinstance(self.name, str) or not self.name or "." in self.name:
            raise InputError(f"{where}.name", f"is {self.name!r}", "give a non-empty name without dots")
        M = _matrix(f"{where}.mass", self.mass)
        n = M.shape[0]
        K = _matrix(f"{where}.stiffness", self.stiffness, n)
        C = None if self.damping is None else _matrix(f"{where}.damping", self.damping, n)
        given = [
            k
            for k, v in (("damping", C), ("rayleigh", self.rayleigh), ("modal_damping_ratio", self.modal_damping_ratio))
            if v is not None
        ]
        if len(given) > 1:
            raise InputError(
                f"{where}.{given[1]}", f"is given together with {given[0]}", "give one damping description"
            )
        if self.rayleigh is not None:
            ab = np.asarray(self.rayleigh, float)
            if ab.shape != (2,) or not np.all(np.isfinite(ab)) or np.any(ab < 0):
                raise InputError(f"{where}.rayleigh", f"is {self.rayleigh!r}", "give [alpha, beta] >= 0")
            object.__setattr__(self, "rayleigh", (float(ab[0]), float(ab[1])))
        if self.modal_damping_ratio is not None:
            z = positive(f"{where}.modal_damping_ratio", self.modal_damping_ratio, allow_zero=True)
            if z >= 1:
                raise InputError(f"{where}.modal_damping_ratio", f"is {z}", "give a ratio below 1 (e.g. 0.002)")
            object.__setattr__(self, "modal_damping_ratio", z)
        names = tuple(str(s) for s in self.dof_names) or tuple(f"x{i}" for i in range(n))
        if len(names) != n:
            raise InputError(f"{where}.dof_names", f"has {len(names)} names for {n} DOFs", f"give {n} names")
        if len(set(names)) != n:
            dup = sorted({s for s in names if names.count(s) > 1})
            raise InputError(f"{where}.dof_names", f"contains duplicates {dup}", "give unique names")
        units = tuple(str(u) for u in self.dof_units) or ("m",) * n
        if len(units) != n:
            raise InputError(f"{where}.dof_units", f"has {len(units)} units for {n} DOFs", f"give {n} units")
        points = {}
        for pname, pt in dict(self.points).items():
            pt = pt if isinstance(pt, Point) else Point(**pt)
            bad = set(pt.dofs) - set(COMPONENTS)
            if bad:
                raise InputError(
                    f"{where}.points[{pname}]", f"has unknown component(s) {sorted(bad)}", f"use {list(COMPONENTS)}"
                )
            for comp, dof in pt.dofs.items():
                if dof not in names:
                    raise InputError(
                        f"{where}.points[{pname}].{comp}",
                        f"names unknown DOF {dof!r}",
                        f"use one of the substructure's DOFs ({', '.join(names[:6])}, ...)",
                    )
            points[pname] = Point(dict(pt.dofs), tuple(float(c) for c in pt.position))
        object.__setattr__(self, "mass", M)
        object.__setattr__(self, "stiffness", K)
        object.__setattr__(self, "damping", C)
        object.__setattr__(self, "dof_names", names)
        object.__setattr__(self, "dof_units", units)
        object.__setattr__(self, "points", points)

    @property
    def n_dofs(self) -> int:
        return self.mass.shape[0]

    @property
    def sparse(self) -> bool:
        return sp.issparse(self.mass) or sp.issparse(self.stiffness)

    def index(self, dof: str, field_name: str = "dof") -> int:
        if dof not in self.dof_names:
            raise InputError(
                field_name,
                f"names unknown DOF {dof!r} of {self.name}",
                f"use one of {', '.join(self.dof_names[:8])}{', ...' if self.n_dofs > 8 else ''}",
            )
        return self.dof_names.index(dof)

    def damping_matrix(self) -> np.ndarray:
        """Dense C [N s/m] from the damping description (module docstring)."""
        M, K = _dense(self.mass), _dense(self.stiffness)
        if self.damping is not None:
            return _dense(self.damping)
        if self.rayleigh is not None:
            return self.rayleigh[0] * M + self.rayleigh[1] * K
        if self.modal_damping_ratio:
            w2, phi = scipy.linalg.eigh(K, M)
            w = np.sqrt(np.clip(w2, 0.0, None))
            MP = M @ phi
            return MP @ np.diag(2.0 * self.modal_damping_ratio * w) @ MP.T
        return np.zeros_like(M)

    def to_structure(self) -> Structure:
        """The dense :class:`Structure` (validated: M SPD, C and K symmetric PSD)."""
        return Structure(
            _dense(self.mass), self.damping_matrix(), _dense(self.stiffness), self.dof_names, self.dof_units
        )

    def frequencies(self, k: int | None = None) -> np.ndarray:
        """Undamped natural frequencies [Hz] of the substructure alone, ascending (the lowest k)."""
        w2 = _eig(self.stiffness, self.mass, k)[0]
        return np.sqrt(np.clip(w2, 0.0, None)) / (2 * math.pi)


# ---- helpers -----------------------------------------------------------------------------
def _matrix(field_name: str, value, n: int | None = None):
    """A square finite float matrix, sparse (CSR) kept sparse; symmetric within 1e-9."""
    if sp.issparse(value):
        A = sp.csr_matrix(value, dtype=np.float64)
        data = A.data
    else:
        try:
            A = np.array(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise InputError(field_name, f"is not numeric ({exc})", "give numbers only") from None
        data = A
        if A.ndim != 2:
            raise InputError(field_name, f"has {A.ndim} dimension(s)", "give a square matrix")
    if A.shape[0] != A.shape[1] or A.shape[0] == 0:
        raise InputError(field_name, f"is {A.shape[0]}x{A.shape[1]}", "give a non-empty square matrix")
    if n is not None and A.shape[0] != n:
        raise InputError(
            field_name, f"is {A.shape[0]}x{A.shape[1]} but the mass matrix is {n}x{n}", f"give a {n}x{n} matrix"
        )
    if not np.all(np.isfinite(data)):
        raise InputError(field_name, "contains NaN or infinite values", "give finite numbers")
    scale = max(float(np.abs(data).max(initial=0.0)), 1e-300)
    asym = abs(A - A.T).max()
    if asym > 1e-9 * scale:
        raise InputError(field_name, f"is not symmetric (max |A - A^T| = {asym:.3g})", "give a symmetric matrix")
    return A


def _dense(A) -> np.ndarray:
    return A.toarray() if sp.issparse(A) else np.asarray(A, dtype=np.float64)


def _eig(K, M, k: int | None = None):
    """Lowest k eigenpairs of K phi = w^2 M phi (all when k is None): dense eigh, or sparse
    shift-invert Lanczos (eigsh, sigma = 0) when the matrices are sparse and k < n - 1."""
    n = M.shape[0]
    if k is not None and (sp.issparse(K) or sp.issparse(M)) and k < n - 1:
        from scipy.sparse.linalg import eigsh

        w2, phi = eigsh(sp.csc_matrix(K), k=k, M=sp.csc_matrix(M), sigma=0.0, which="LM")
        order = np.argsort(w2)
        return w2[order], phi[:, order]
    sub = None if k is None else (0, min(k, n) - 1)
    return scipy.linalg.eigh(_dense(K), _dense(M), subset_by_index=sub)


# ---- builder: a 2D cantilever frame blade ---------------------------------------------------
def frame_element(E: float, rho: float, area: float, inertia: float, length: float, angle: float):
    """(k, m): 6x6 global stiffness [N/m, N, N m] and consistent mass of a 2D Euler-Bernoulli
    frame element on DOFs (x1, y1, rz1, x2, y2, rz2), axis at ``angle`` [rad] from X."""
    l = length
    ea, ei, ml = E * area / l, E * inertia / l**3, rho * area * l
    kl = np.zeros((6, 6))
    ml_ = np.zeros((6, 6))
    ax, bd = [0, 3], [1, 2, 4, 5]
    kl[np.ix_(ax, ax)] = ea * np.array([[1, -1], [-1, 1]])
    kl[np.ix_(bd, bd)] = ei * np.array(
        [
            [12, 6 * l, -12, 6 * l],
            [6 * l, 4 * l * l, -6 * l, 2 * l * l],
            [-12, -6 * l, 12, -6 * l],
            [6 * l, 2 * l * l, -6 * l, 4 * l * l],
        ]
    )
    ml_[np.ix_(ax, ax)] = ml / 6 * np.array([[2, 1], [1, 2]])
    ml_[np.ix_(bd, bd)] = (
        ml
        / 420
        * np.array(
            [
                [156, 22 * l, 54, -13 * l],
                [22 * l, 4 * l * l, 13 * l, -3 * l * l],
                [54, 13 * l, 156, -22 * l],
                [-13 * l, -3 * l * l, -22 * l, 4 * l * l],
            ]
        )
    )
    c, s = math.cos(angle), math.sin(angle)
    R3 = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # global -> local
    T = np.kron(np.eye(2), R3)
    return T.T @ kl @ T, T.T @ ml_ @ T


def frame_blade(
    name: str,
    length: float,
    n_elements: int,
    youngs_modulus: float,
    density: float,
    area: float,
    second_moment: float,
    platform_node: int | None = None,
    root: tuple[float, float] = (0.0, 0.0),
    angle: float = math.pi / 2,
    tip_mass: float = 0.0,
    platform_mass: float = 0.0,
    sparse: bool | None = None,
    **damping,
) -> Substructure:
    """A cantilever frame blade clamped at ``root`` [m], axis at ``angle`` [rad] (default +Y,
    radial), ``n_elements`` equal elements; nodes 1..n_elements with DOFs '<i>.x', '<i>.y'
    [m] and '<i>.rz' [rad] (i = node number); points 'platform' (node ``platform_node``,
    default the tip) and 'tip'; optional lumped ``tip_mass`` and ``platform_mass`` [kg] (on x
    and y of their node: a shroud, a platform). ``sparse``: CSR matrices (default: above 600
    DOFs), else dense. ``damping``: damping /
    rayleigh / modal_damping_ratio of :class:`Substructure`."""
    where = f"substructures[{name}]"
    L = positive(f"{where}.length", length)
    if isinstance(n_elements, bool) or not isinstance(n_elements, (int, np.integer)) or n_elements < 1:
        raise InputError(f"{where}.elements", f"is {n_elements!r}", "give a whole number of elements >= 1")
    E = positive(f"{where}.youngs_modulus", youngs_modulus)
    rho = positive(f"{where}.density", density)
    A_ = positive(f"{where}.area", area)
    I_ = positive(f"{where}.second_moment", second_moment)
    pnode = n_elements if platform_node is None else platform_node
    if isinstance(pnode, bool) or not isinstance(pnode, (int, np.integer)) or not 1 <= pnode <= n_elements:
        raise InputError(f"{where}.platform_node", f"is {platform_node!r}", f"give a node number 1..{n_elements}")
    ne, le = int(n_elements), L / n_elements
    k_e, m_e = frame_element(E, rho, A_, I_, le, angle)
    n_all = 3 * (ne + 1)
    rows = (3 * np.arange(ne)[:, None, None] + np.arange(6)[None, :, None]).repeat(6, axis=2).ravel()
    cols = (3 * np.arange(ne)[:, None, None] + np.arange(6)[None, None, :]).repeat(6, axis=1).ravel()
    lumped = np.zeros(n_all)
    for key, node, value in (("tip_mass", ne, tip_mass), ("platform_mass", pnode, platform_mass)):
        if value:
            lumped[3 * node : 3 * node + 2] += positive(f"{where}.{key}", value)
    K = sp.coo_matrix((np.tile(k_e.ravel(), ne), (rows, cols)), shape=(n_all, n_all)).tocsr()
    M = (sp.coo_matrix((np.tile(m_e.ravel(), ne), (rows, cols)), shape=(n_all, n_all)) + sp.diags(lumped)).tocsr()
    K, M = K[3:, 3:], M[3:, 3:]  # clamp the root node
    if not (sparse if sparse is not None else n_all > 600):
        K, M = K.toarray(), M.toarray()
    names = tuple(f"{i}.{c}" for i in range(1, ne + 1) for c in COMPONENTS)
    units = ("m", "m", "rad") * ne
    c, s = math.cos(angle), math.sin(angle)
    pos = lambda i: (root[0] + i * le * c, root[1] + i * le * s)
    points = {
        p: Point({comp: f"{i}.{comp}" for comp in COMPONENTS}, pos(i)) for p, i in (("platform", pnode), ("tip", ne))
    }
    return Substructure(name, M, K, names, units, points=points, **damping)


def cantilever_frequencies(
    length: float, youngs_modulus: float, density: float, area: float, second_moment: float, n: int = 3
) -> tuple[np.ndarray, np.ndarray]:
    """Analytic Euler-Bernoulli cantilever frequencies [Hz]: bending (beta_k L)^2 sqrt(EI /
    (rho A L^4)) / 2 pi with cos(bL) cosh(bL) = -1, and axial (2k - 1) c / 4L, c = sqrt(E/rho)."""
    from scipy.optimize import brentq

    roots = [
        brentq(
            lambda b: math.cos(b) * math.cosh(b) + 1,
            (k - 0.5) * math.pi - 0.5 + (k == 1) * 0.3,
            (k - 0.5) * math.pi + 0.5,
        )
        for k in range(1, n + 1)
    ]
    bend = np.array(
        [b * b * math.sqrt(youngs_modulus * second_moment / (density * area * length**4)) for b in roots]
    ) / (2 * math.pi)
    axial = np.array([(2 * k - 1) / (4 * length) * math.sqrt(youngs_modulus / density) for k in range(1, n + 1)])
    return bend, axial


# ---- Craig-Bampton ------------------------------------------------------------------------
def craig_bampton(
    sub: Substructure, boundary: list[str], n_modes: int, name: str | None = None, **damping
) -> Substructure:
    """Fixed-interface reduction of ``sub`` onto the DOFs named in ``boundary`` plus its
    ``n_modes`` lowest fixed-interface modes (module docstring). Sparse input is factorised
    and eigen-solved sparse (splu, eigsh); the reduced model is dense. Reduced DOFs: the
    boundary names, then 'mode<k>' [m]. A point keeps its components on the boundary (the
    others no longer move it) and is dropped when none is.
    Damping of the reduced model: ``damping`` if given, else the original's Rayleigh or modal
    ratio (a damping matrix is projected: C_r = T^T C T)."""
    where = f"substructures[{name or sub.name}]"
    if not boundary:
        raise InputError(f"{where}.boundary_dofs", "is empty", "name the DOFs that contacts and forces use")
    b = [sub.index(d, f"{where}.boundary_dofs") for d in boundary]
    if len(set(b)) != len(b):
        raise InputError(f"{where}.boundary_dofs", "names a DOF twice", "give each boundary DOF once")
    n = sub.n_dofs
    inner = np.setdiff1d(np.arange(n), b)
    if isinstance(n_modes, bool) or not isinstance(n_modes, (int, np.integer)) or not 0 <= n_modes <= inner.size:
        raise InputError(f"{where}.modes", f"is {n_modes!r}", f"give a whole number 0..{inner.size}")
    sparse = sub.sparse
    M = sp.csr_matrix(sub.mass) if sparse else np.asarray(sub.mass)
    K = sp.csr_matrix(sub.stiffness) if sparse else np.asarray(sub.stiffness)
    Kii, Kib, Mii = _block(K, inner, inner), _block(K, inner, b), _block(M, inner, inner)
    try:
        if sparse:
            from scipy.sparse.linalg import splu

            lu = splu(sp.csc_matrix(Kii))
            if not np.all(np.isfinite(lu.U.diagonal())) or np.any(lu.U.diagonal() == 0):
                raise np.linalg.LinAlgError("singular")
            Psi = -lu.solve(np.asarray(Kib.toarray()))
        else:
            Psi = -scipy.linalg.solve(Kii, Kib, assume_a="sym")
    except (np.linalg.LinAlgError, RuntimeError, ValueError):
        raise InputError(
            f"{where}.boundary_dofs",
            "leave the interior free to move (K_ii singular)",
            "add boundary DOFs so that fixing them holds the substructure",
        ) from None
    T = np.zeros((n, len(b) + n_modes))
    T[b, np.arange(len(b))] = 1.0
    T[inner, : len(b)] = Psi
    if n_modes:
        _, phi = _eig(Kii, Mii, n_modes)
        trans = np.array([sub.dof_units[i] != "rad" for i in inner])
        for k in range(n_modes):
            ref = phi[trans, k] if trans.any() else phi[:, k]
            j = int(np.argmax(np.abs(ref)))
            phi[:, k] /= ref[j]
        T[inner, len(b) :] = phi
    proj = lambda A: (T.T @ (A @ T)) if sparse else T.T @ A @ T
    sym = lambda A: 0.5 * (A + A.T)
    Mr, Kr = sym(np.asarray(proj(M))), sym(np.asarray(proj(K)))
    if not damping:
        if sub.damping is not None:
            damping = {"damping": sym(np.asarray(proj(sp.csr_matrix(sub.damping) if sparse else sub.damping)))}
        elif sub.rayleigh is not None:
            damping = {"rayleigh": sub.rayleigh}
        elif sub.modal_damping_ratio is not None:
            damping = {"modal_damping_ratio": sub.modal_damping_ratio}
    names = tuple(boundary) + tuple(f"mode{k + 1}" for k in range(n_modes))
    units = tuple(sub.dof_units[i] for i in b) + ("m",) * n_modes
    points = {}
    for p, pt in sub.points.items():
        kept = {c: d for c, d in pt.dofs.items() if d in boundary}
        if kept:
            points[p] = Point(kept, pt.position)
    return Substructure(name or sub.name, Mr, Kr, names, units, points=points, **damping)


def _block(A, rows, cols):
    return A[rows][:, cols] if sp.issparse(A) else A[np.ix_(rows, cols)]


# ---- import / export ----------------------------------------------------------------------
_KEYS = {"mass": ("M", "mass"), "stiffness": ("K", "stiffness"), "damping": ("C", "damping")}


def save_npz(sub: Substructure, path: str | Path) -> None:
    """Write M, K (and C when given) with DOF names and units to one .npz; a sparse matrix is
    stored as its CSR parts '<key>.data', '<key>.indices', '<key>.indptr', '<key>.shape'."""
    arrays = {"dof_names": np.array(sub.dof_names), "dof_units": np.array(sub.dof_units)}
    for attr, (key, _) in _KEYS.items():
        A = getattr(sub, attr)
        if A is None:
            continue
        if sp.issparse(A):
            A = sp.csr_matrix(A)
            arrays.update(
                {
                    f"{key}.data": A.data,
                    f"{key}.indices": A.indices,
                    f"{key}.indptr": A.indptr,
                    f"{key}.shape": np.array(A.shape),
                }
            )
        else:
            arrays[key] = np.asarray(A)
    path = Path(path)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)


_KINDS = {"c": "complex", "U": "text", "S": "text", "O": "object"}


def load_npz(path: str | Path, name: str, field_name: str = "file", **kwargs) -> Substructure:
    """A substructure from an .npz holding 'M' (or 'mass'), 'K' ('stiffness'), optional 'C'
    ('damping'), 'dof_names', 'dof_units'; dense arrays or the CSR parts of :func:`save_npz`.
    ``kwargs`` (damping, points, dof_names, ...) override or complete the file."""
    try:
        with np.load(path, allow_pickle=False) as data:
            content = {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise InputError(field_name, f"file {str(path)!r} not found", "give the path of an .npz file") from None
    except (OSError, ValueError, TypeError, AttributeError, zipfile.BadZipFile) as exc:  # not a zip: an array, text
        raise InputError(
            field_name, f"{str(path)!r} is not a readable .npz file ({exc})", "write it with numpy.savez"
        ) from None
    for key, value in content.items():
        if key not in ("dof_names", "dof_units") and value.dtype.kind not in "fiub":
            raise InputError(
                field_name,
                f"{str(path)!r} holds {key!r} as {_KINDS.get(value.dtype.kind, str(value.dtype))} values",
                "store real numbers (float64)",
            )
    mats = {}
    for attr, keys in _KEYS.items():
        for key in keys:
            if key in content:
                mats[attr] = content[key]
            elif f"{key}.data" in content:
                try:
                    mats[attr] = sp.csr_matrix(
                        (content[f"{key}.data"], content[f"{key}.indices"], content[f"{key}.indptr"]),
                        shape=tuple(content[f"{key}.shape"]),
                    )
                except KeyError as exc:
                    raise InputError(
                        field_name,
                        f"{path} has {key}.data but no {exc.args[0]}",
                        "store all CSR parts: data, indices, indptr, shape",
                    ) from None
    for attr in ("mass", "stiffness"):
        if attr not in mats:
            raise InputError(
                field_name,
                f"{path} holds no {' or '.join(repr(k) for k in _KEYS[attr])} array",
                f"store the {attr} matrix under the key {_KEYS[attr][0]!r}",
            )
    for key in ("dof_names", "dof_units"):
        if key in content and key not in kwargs:
            kwargs[key] = tuple(str(s) for s in content[key])
    if "damping" in mats and not any(k in kwargs for k in ("damping", "rayleigh", "modal_damping_ratio")):
        kwargs["damping"] = mats["damping"]
    return Substructure(name, mats["mass"], mats["stiffness"], **kwargs)


def save_mtx(sub: Substructure, directory: str | Path) -> dict:
    """Write '<name>_M.mtx', '<name>_K.mtx' (and '_C') in Matrix Market format (coordinate for
    sparse, array for dense) and '<name>_dofs.txt' (name and unit per line); returns the paths."""
    import scipy.io

    directory = Path(directory)
    paths = {}
    for attr, (key, _) in _KEYS.items():
        A = getattr(sub, attr)
        if A is None:
            continue
        p = directory / f"{sub.name}_{key}.mtx"
        with atomic_path(p) as tmp, open(tmp, "wb") as fh:
            scipy.io.mmwrite(fh, sp.coo_matrix(A) if sp.issparse(A) else np.asarray(A), precision=17)
        paths[attr] = p
    p = directory / f"{sub.name}_dofs.txt"
    with atomic_path(p) as tmp:
        tmp.write_text("".join(f"{n} {u}\n" for n, u in zip(sub.dof_names, sub.dof_units)))
    paths["dofs"] = p
    return paths


def read_mtx(path: str | Path, field_name: str = "file"):
    """One Matrix Market matrix: CSR when stored as coordinates, else a dense array. A
    "pattern" file (positions without values) and a complex one are refused."""
    import scipy.io

    try:
        field = scipy.io.mminfo(str(path))[4]
        if field in ("pattern", "complex"):
            raise InputError(
                field_name,
                f"{str(path)!r} is a Matrix Market {field!r} file"
                + (" (positions without values)" if field == "pattern" else " (complex values)"),
                "write the real matrix with its values (scipy.io.mmwrite of a real array or sparse matrix)",
            )
        A = scipy.io.mmread(str(path))
    except InputError:
        raise
    except FileNotFoundError:
        raise InputError(field_name, f"file {str(path)!r} not found", "give the path of a .mtx file") from None
    except (OSError, ValueError) as exc:
        raise InputError(
            field_name, f"{str(path)!r} is not a Matrix Market file ({exc})", "write it with scipy.io.mmwrite"
        ) from None
    return sp.csr_matrix(A) if sp.issparse(A) else np.asarray(A, dtype=np.float64)


def read_dof_file(path: str | Path, field_name: str = "dofs_file") -> tuple[tuple[str, ...], tuple[str, ...]]:
    """DOF names (and optional units, default m) from a text file, one DOF per line."""
    try:
        lines = [ln.split() for ln in Path(path).read_text().splitlines() if ln.strip()]
    except OSError as exc:
        raise InputError(
            field_name, f"{str(path)!r} cannot be read ({exc.strerror})", "give a text file, one DOF a line"
        ) from None
    return tuple(ln[0] for ln in lines), tuple(ln[1] if len(ln) > 1 else "m" for ln in lines)


def load_mtx(
    mass: str | Path,
    stiffness: str | Path,
    name: str,
    damping: str | Path | None = None,
    dofs_file: str | Path | None = None,
    **kwargs,
) -> Substructure:
    """A substructure from Matrix Market files (M, K, optional C) and an optional DOF file."""
    if dofs_file is not None and "dof_names" not in kwargs:
        kwargs["dof_names"], kwargs["dof_units"] = read_dof_file(dofs_file)
    if damping is not None:
        kwargs["damping"] = read_mtx(damping, "damping_file")
    return Substructure(name, read_mtx(mass, "mass_file"), read_mtx(stiffness, "stiffness_file"), **kwargs)

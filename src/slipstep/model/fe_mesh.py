"""A 3D solid FE model with a friction joint, meshed and assembled by scikit-fem (issue 26).

The bolted beam: a solid beam of hexahedra (trilinear, linear elasticity) along x, clamped
at x = 0; over its last ``joint_length`` its lower face (z = 0) is a lap joint pressed onto a
rigid support by a bolt pressure on the upper face above it. Every node of the joint face is
one contact point (quasi-3D: two tangential directions and the normal), with its own normal
and tributary area from the mesh:

    a_i = int_joint phi_i dS,    n_i = int_joint phi_i n dS / |int_joint phi_i n dS|

(phi_i the node's shape function, n the outward unit normal of the face), contact
stiffnesses k_n,i = k_n'' a_i, k_t,i = k_t'' a_i (stiffness per unit area [N/m^3]), gather
rows (t1, t2, n) on the node's three displacement components, v = n . u the approach into
the support. A harmonic lateral force (along y, in the joint plane) acts on the free end
face x = L, spread as a uniform traction. Damping: Rayleigh, C = alpha M + beta K.

scikit-fem is an optional dependency (``pip install scikit-fem``; the ``fe`` extra):
:func:`bolted_beam` raises ImportError naming it when it is missing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


#: matrix entries below this fraction of the largest are round-off (:func:`_pruned`)
PRUNE_RTOL = 1e-14


@dataclass(frozen=True)
class BeamSpec:
    """The bolted beam's geometry [m], mesh (elements along x, y, z), material (E [Pa], nu,
    rho [kg/m^3]), joint (length [m], contact stiffness per unit area [N/m^3], mu, bolt
    pressure [Pa]), Rayleigh damping (alpha [1/s], beta [s]) and load (amplitude [N],
    frequency [Hz])."""

    length: float = 0.5
    width: float = 0.024
    height: float = 0.012
    elements: tuple[int, int, int] = (360, 6, 3)
    young: float = 2.1e11
    poisson: float = 0.3
    density: float = 7850.0
    joint_length: float = 0.04
    kn_per_area: float = 2e13
    kt_per_area: float = 1e13
    mu: float = 0.3
    pressure: float = 2e6
    alpha: float = 20.0
    beta: float = 2e-6
    force: float = 200.0
    frequency: float = 300.0


@dataclass(frozen=True)
class BeamModel:
    """The assembled model: the System, the contact nodes' coordinates (nc, 3) [m], areas
    (nc,) [m^2] and unit normals (nc, 3), the tip DOF index (the y displacement of the
    end face's centre node) and the mesh's node count."""

    system: object
    contact_xyz: np.ndarray
    contact_area: np.ndarray
    contact_normal: np.ndarray
    tip_dof: int
    n_nodes: int


def coarse_spec(**changes) -> BeamSpec:
    """A small version of the default beam (a few hundred DOFs) for tests: the same geometry
    and physics, coarser mesh."""
    base = {"elements": (12, 2, 2), "joint_length": 0.5 * 4 / 12}
    base.update(changes)
    return BeamSpec(**base)


def _skfem():
    try:
        import skfem
    except ImportError as exc:  # an optional dependency
        raise ImportError("the FE mesh model needs scikit-fem: pip install scikit-fem (or slipstep[fe])") from exc
    return skfem


def _tangents(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (t1, t2) with (t1, t2, n) right-handed: t1 the projection of the
    coordinate axis least aligned with n."""
    axis = np.eye(3)[np.argmin(np.abs(normal))]
    t1 = axis - normal * (axis @ normal)
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(normal, t1)


def bolted_beam(spec: BeamSpec | None = None) -> BeamModel:
    """The bolted beam of ``spec`` (module docstring) as a slipstep System with sparse
    matrices (DOF names ``n<node>.x|y|z``, contacts ``J<node>``)."""
    import slipstep as ss

    spec = spec or BeamSpec()
    skfem = _skfem()
    from skfem.helpers import ddot, div, dot, sym_grad
    from skfem.models.elasticity import lame_parameters

    nx, ny, nz = spec.elements
    L, W, H = spec.length, spec.width, spec.height
    mesh = skfem.MeshHex.init_tensor(np.linspace(0, L, nx + 1), np.linspace(0, W, ny + 1), np.linspace(0, H, nz + 1))
    element = skfem.ElementVector(skfem.ElementHex1())
    basis = skfem.Basis(mesh, element, intorder=2)
    lam, mu = lame_parameters(spec.young, spec.poisson)

    @skfem.BilinearForm
    def elasticity(u, v, w):  # lambda div u div v + 2 mu eps(u) : eps(v) (skfem's linear_elasticity, 3x faster)
        return lam * div(u) * div(v) + 2.0 * mu * ddot(sym_grad(u), sym_grad(v))

    K = skfem.asm(elasticity, basis)

    @skfem.BilinearForm
    def mass(u, v, w):
        return spec.density * dot(u, v)

    M = skfem.asm(mass, basis)
    tol = 1e-9 * L
    x_joint = L - spec.joint_length - tol
    joint = mesh.facets_satisfying(lambda x: (x[2] < tol) & (x[0] > x_joint))
    top = mesh.facets_satisfying(lambda x: (x[2] > H - tol) & (x[0] > x_joint))
    end = mesh.facets_satisfying(lambda x: x[0] > L - tol)

    @skfem.LinearForm
    def normal_moment(v, w):
        return dot(w.n, v)

    @skfem.LinearForm
    def lateral(v, w):
        return v[1]

    @skfem.LinearForm
    def downward(v, w):
        return -v[2]

    fb = lambda facets: skfem.FacetBasis(mesh, element, facets=facets, intorder=2)  # noqa: E731
    nvec = skfem.asm(normal_moment, fb(joint))  # int phi_i n_c dS per DOF (i, c)
    tip_load = skfem.asm(lateral, fb(end))  # int phi_i dS on the y DOFs of the end face
    bolt = spec.pressure * skfem.asm(downward, fb(top))
    area_end = W * H
    nodal = basis.nodal_dofs  # (3, nodes)
    clamped = np.flatnonzero(mesh.p[0] < tol)
    fixed = np.sort(nodal[:, clamped].ravel())
    free = np.setdiff1d(np.arange(K.shape[0]), fixed)
    index = np.full(K.shape[0], -1)
    index[free] = np.arange(free.size)
    n = free.size
    M, K = (_pruned(X.tocsr()[free][:, free]) for X in (M, K))
    C = (spec.alpha * M + spec.beta * K).tocsr()
    names = _dof_names(nodal, free)
    joint_nodes = np.unique(mesh.facets[:, joint])
    contacts, xyz, areas, normals = [], [], [], []
    for node in joint_nodes:
        dofs = nodal[:, node]
        moment = nvec[dofs]
        area = float(np.linalg.norm(moment))  # a flat face: |int phi n dS| = int phi dS
        normal = moment / area
        t1, t2 = _tangents(normal)
        rows = np.repeat(np.arange(3), 3)
        gather = sp.csr_matrix((np.concatenate([t1, t2, normal]), (rows, np.tile(index[dofs], 3))), shape=(3, n))
        contacts.append(
            ss.ContactElement(
                f"J{node}", gather, spec.kt_per_area * area, spec.kn_per_area * area, spec.mu, law="quasi-3d-uncoupled"
            )
        )
        xyz.append(mesh.p[:, node])
        areas.append(area)
        normals.append(normal)
    constant = bolt[free]
    amplitude = spec.force / area_end * tip_load[free]
    end_nodes = np.flatnonzero(mesh.p[0] > L - tol)
    centre = end_nodes[np.argmin(np.hypot(mesh.p[1, end_nodes] - W / 2, mesh.p[2, end_nodes] - H / 2))]
    tip_dof = int(index[nodal[1, centre]])
    force = ss.Signal(names, (ss.Harmonic(spec.frequency, amplitude),))
    structure = ss.Structure(M, C, K, dof_names=names)
    system = ss.System(
        structure,
        tuple(contacts),
        ss.Excitation(constant_force=constant, force=force),
        name=f"bolted-beam-{n}",
    )
    return BeamModel(system, np.array(xyz), np.array(areas), np.array(normals), tip_dof, mesh.p.shape[1])


def _pruned(X) -> sp.csr_matrix:
    """X without the entries that are zero but for round-off (below PRUNE_RTOL of the largest):
    the couplings that cancel on a regular grid come out as 0 or 1e-19 by the order of the
    sums, and the pattern, hence the sparse LU's fill, must not depend on that."""
    X = sp.csr_matrix(X, copy=True)
    X.data[np.abs(X.data) < PRUNE_RTOL * np.abs(X.data).max(initial=0.0)] = 0.0
    X.eliminate_zeros()
    X.sort_indices()
    return X


def _dof_names(nodal: np.ndarray, free: np.ndarray) -> tuple[str, ...]:
    """``n<node>.x|y|z`` of each free DOF (nodal: the basis's (3, nodes) DOF table)."""
    owner = np.empty(nodal.size, np.int64)
    comp = np.empty(nodal.size, np.int64)
    for c in range(3):
        owner[nodal[c]] = np.arange(nodal.shape[1])
        comp[nodal[c]] = c
    return tuple(f"n{owner[d]}.{'xyz'[comp[d]]}" for d in free)

"""The buffers of a march: the kernel workspace (kernels.march.Workspace: state, scratch,
factorisation caches) and the output rows (kernels.march.Outputs), their sizes (the memory
estimate of methods/plan.py counts them before anything is allocated) and their resets.
"""

from __future__ import annotations

import math

import numpy as np

from slipstep.kernels import banded as BD
from slipstep.kernels import march as K
from slipstep.kernels.contact import STICK
from slipstep.kernels.state_solve import LowRank
from slipstep.methods import memory
from slipstep.methods import save as SV
from slipstep.methods.eigen import band_mass_lu, mass_factor
from slipstep.model.system import CompiledSystem


def reset_cache(ws: K.Workspace) -> None:
    """Forget the factorisations (every march pays for its own). T_min per state is a property
    of the matrices and is kept for the life of the marcher (cleared at allocation and when a
    marcher is retargeted to other matrices)."""
    ws.cache_used[:] = False
    ws.lr.base_used[:] = False
    ws.lin_dt[0] = np.nan


def cache_capacities(n: int, nq: int, low_rank: bool, band_width: int = 0) -> tuple[int, int, int]:
    """(matrix size factorised per state, state cache slots, low-rank base slots): at most
    about 200 MB of factorisations each. ``band_width`` > 0 (the banded backend: 2 kl + ku + 1
    columns per row of a banded LU): the slots of n x band_width LUs."""
    if band_width > 0:
        cap = int(min(512, max(8, 2e8 // (8 * n * (band_width + 1) + 1))))
        return n, cap, 1
    size = nq if low_rank else n  # the matrix factorised per state: C(S) (nq) or J(S) (n)
    cap = int(min(512, max(8, 2e8 // (8 * size * size + 1))))
    capb = int(min(64, max(2, 2e8 // (8 * (n * n + 2 * n * nq) + 1)))) if low_rank else 1
    return size, cap, capb


def lu_width(cs: CompiledSystem) -> int:
    """Columns of a banded LU (2 kl + ku + 1), 0 for the dense backend."""
    return 2 * cs.kl + cs.ku + 1 if cs.banded else 0


def workspace_bytes(cs: CompiledSystem, max_state_iter: int, low_rank: bool) -> int:
    """Bytes of :func:`allocate_workspace` (its largest arrays)."""
    n, nq, nd = cs.M.shape[0], cs.A.shape[0], cs.kt.shape[0]
    width = lu_width(cs)
    size, cap, capb = cache_capacities(n, nq, low_rank, width)
    if width:  # banded: LUs (cap + 2) x n x (width + 1 pivots), Lin, J, M's LU, T_min Lanczos basis
        lanczos = 2 * min(n, BD.LANCZOS_FULL if n <= BD.LANCZOS_FULL else BD.LANCZOS_STEPS) * n
        return int(8 * ((cap + 2) * n * (width + 1) + 4 * n * width + lanczos + 20 * (n + nq + nd)) + 2 * cap * nd)
    nb, nqb = (n, nq) if low_rank else (1, 1)
    return int(
        8
        * (
            (cap + 2) * size * (size + 1)
            + (capb + 1) * (nb * nb + nb + nb * nqb + nqb * nqb)
            + 4 * n * n
            + 20 * (n + nq + nd)
        )
        + 2 * cap * nd
        + nd * (max_state_iter + 1)
    )


def allocate_workspace(cs: CompiledSystem, max_state_iter: int, low_rank: bool) -> K.Workspace:
    n, nq, nd, m = cs.M.shape[0], cs.A.shape[0], cs.kt.shape[0], cs.B.shape[1]
    width = lu_width(cs)
    size, cap, capb = cache_capacities(n, nq, low_rank, width)
    nb, nqb = (n, nq) if low_rank else (1, 1)
    z = lambda *shape: np.zeros(shape)
    i8 = lambda *shape: np.zeros(shape, np.int8)
    if width:  # banded backend: band storage for Lin (kl + ku + 1) and the LUs (2 kl + ku + 1); M's LU
        lin, jac, lus = z(n, cs.kl + cs.ku + 1), z(n, width), z(cap + 2, n, width)
        mfac, mpiv = band_mass_lu(cs)  # the banded LU of M (kernels/banded.py band_lambda_max)
    else:
        lin, jac, lus = z(n, n), z(n, n), z(cap + 2, size, size)
        mfac, mpiv = mass_factor(cs.M), np.zeros(0, np.int64)
    lr = LowRank(
        base_keys=i8(capb, nd),
        base_used=np.zeros(capb, np.bool_),
        base_ok=np.zeros(capb + 1, np.bool_),
        base_lu=z(capb + 1, nb, nb),
        base_piv=np.zeros((capb + 1, nb), np.int64),
        Z=z(capb + 1, nb, nqb),
        AZ=z(capb + 1, nqb, nqb),
        slot_base=np.zeros(cap + 2, np.int64),
        slot_identity=np.zeros(cap + 2, np.bool_),
        Ay=z(nq),
        t=z(nq),
        s=z(nq),
        col=z(n),
        zc=z(n),
    )
    return K.Workspace(
        x=z(n),
        v=z(n),
        a=z(n),
        fe=z(n),
        gf=z(n),
        w=z(nd),
        state=i8(nd),
        fe1=z(n),
        gf1=z(n),
        f1=z(nq),
        q1=z(nq),
        w1=z(nd),
        state1=i8(nd),
        dx=z(n),
        delta=z(n),
        r0=z(n),
        r=z(n),
        p=z(m),
        qbase=z(nq),
        Lin=lin,
        J=jac,
        mass_factor=mfac,
        key=i8(2 * nd),
        dt_state=i8(nd),
        stick=np.full(nd, STICK, np.int8),
        cache_keys=i8(cap, 2 * nd),
        cache_used=np.zeros(cap, np.bool_),
        cache_ok=np.zeros(cap + 2, np.bool_),
        cache_lu=lus,
        cache_piv=np.zeros((cap + 2, size), np.int64),
        tmin_keys=i8(cap, nd),
        tmin_used=np.zeros(cap, np.bool_),
        tmin_value=z(cap),
        lin_dt=np.full(1, np.nan),
        visited=i8(max_state_iter + 1, nd),
        basis=z(4, cs.force_frequency.shape[0] + cs.motion_frequency.shape[0]),
        clock=z(4),
        mpiv=mpiv,
        lr=lr,
    )


def allocate_outputs(
    cs: CompiledSystem, capacity: int, max_memory: float | None = None, plan: SV.Plan | None = None, t_end: float = 0.0
) -> K.Outputs:
    """The output buffers of a march of at most ``capacity`` steps saving ``plan`` (None: every
    DOF and contact at every step); a buffer beyond the memory limit (default: half of the
    available memory) is refused first (runners check it earlier with a better message)."""
    n, nq, nd = cs.M.shape[0], cs.A.shape[0], cs.kt.shape[0]
    if plan is None:
        dofs, rows, dirs = np.arange(n, dtype=np.int64), np.arange(nq, dtype=np.int64), np.arange(nd, dtype=np.int64)
        ip, times = np.array([capacity, 1, 0, -1, 0, 0], np.int64), np.array([-math.inf, math.nan, math.inf])
        k = capacity + 3
    else:
        dofs, rows, dirs, ip, times = SV.kernel_arrays(plan, cs, capacity)
        k = SV.rows_needed(plan, capacity, 0.0, t_end)
    ns, nqs, nds = dofs.size, rows.size, dirs.size
    if k > 100_000:
        limit = None if max_memory is None else memory.parse_size("max_memory", max_memory)
        memory.check(k, ns, nqs, nds, cs.B.shape[1], 0, limit, "duration", "simulate a shorter time or save less")
    return K.Outputs(
        t=np.zeros(k),
        dt=np.zeros(k),
        x=np.zeros((k, ns)),
        v=np.zeros((k, ns)),
        a=np.zeros((k, ns)),
        q=np.zeros((k, nqs)),
        f=np.zeros((k, nqs)),
        w=np.zeros((k, nds)),
        state=np.zeros((k, nds), np.int8),
        solves=np.zeros(k, np.int64),
        counters=np.zeros(K.N_COUNTERS, np.int64),
        step=np.full(k, -1, np.int64),
        dofs=dofs,
        rows=rows,
        dirs=dirs,
        plan=ip,
        times=times,
    )


def reset_outputs(out: K.Outputs) -> None:
    """Set the save plan's running entries before a march (the kernel's _store keeps them):
    no row kept, no step kept, the first given time, the first multiple of every; no failure."""
    out.plan[[K.S_ROWS, K.S_LAST, K.S_GRID, K.S_NEXT]] = 0, -1, 0, 0
    out.times[K.S_FAIL] = math.nan


def saved_rows(out: K.Outputs, n_steps: int) -> int:
    """Rows of ``out`` holding the march of ``n_steps`` steps: those the kernel kept, and the
    pending row when it holds the last step (a march always ends with its last step)."""
    rows = int(out.plan[K.S_ROWS])
    if rows < out.step.shape[0] and out.step[rows] == n_steps and (rows == 0 or out.step[rows - 1] != n_steps):
        rows += 1
    return max(rows, 1)

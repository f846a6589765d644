"""Pseudo-arclength continuation of the harmonic balance over frequency or excitation level.

The branch y(s) = (Z(s), p(s)) of R(Z, p) = 0 (p = Omega or the excitation level lambda) is
followed in scaled variables y_s = (Z / z_scale, p / p_scale). From a solved point y_i with
unit tangent t_i (solution of [dR/dy_s; t_{i-1}^T] t = [0; 1], oriented along t_{i-1}), the
predictor is y_i + ds t_i and the corrector Newton's method on

    R(Z, p) = 0,    t_i . (y_s - y_i - ds t_i) = 0          (the pseudo-arclength condition)

with the exact Jacobian [[dR/dZ, dR/dp]; t_i^T]. It follows turning points (p reverses while
s keeps growing) and so both branches around a jump. Step control: ds grows by up to 2x
when the corrector needs few iterations (ds *= clip(target / iterations, 0.5, 2)), halves
after a failed corrector, and is capped so that a step moves p by at most ``max_dp`` and
the response by at most ``max_dz`` (relative); below ``min_ds`` the continuation stops with
status NOT_CONVERGED. The last point lands on the end value of p exactly (a natural-parameter
Newton solve from the interpolated crossing).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from slipstep.hbm.residual import HarmonicBalance, Point, blas_threads


@dataclass
class Branch:
    """The points of a continuation, in the order computed, and how it ended."""

    points: list[Point] = field(default_factory=list)
    status: str = "OK"
    message: str = "completed"
    steps: int = 0
    failed_correctors: int = 0
    turning_points: int = 0


class _Problem:
    """R(Z, p) and its Jacobian for p = 'omega' or 'level' at the other one fixed."""

    def __init__(self, hb: HarmonicBalance, parameter: str, fixed: float):
        self.hb, self.parameter, self.fixed = hb, parameter, fixed

    def args(self, p):
        return (p, self.fixed) if self.parameter == "omega" else (self.fixed, p)

    def evaluate(self, Z, p, jacobian=True):
        w, lv = self.args(p)
        if not jacobian:
            return self.hb.evaluate(Z, w, lv, jacobian=False)
        R, J, dw, dl = self.hb.evaluate(Z, w, lv)
        return R, J, (dw if self.parameter == "omega" else dl)

    def solve(self, p, Z0):
        w, lv = self.args(p)
        if self.parameter == "omega":
            return solve_point(self.hb, w, lv, Z0)
        return self.hb.solve(w, lv, Z0)


def _tangent(J, Jp, t_prev, zs, ps):
    """Unit tangent in scaled variables, oriented along t_prev."""
    n = J.shape[0]
    A = np.zeros((n + 1, n + 1))
    A[:n, :n] = J * zs
    A[:n, n] = Jp * ps
    A[n] = t_prev
    rhs = np.zeros(n + 1)
    rhs[n] = 1.0
    t = np.linalg.solve(A, rhs)
    t /= np.linalg.norm(t)
    if t @ t_prev < 0:
        t = -t
    return t


def solve_point(hb: HarmonicBalance, omega: float, level: float, Z0: np.ndarray | None = None) -> Point:
    """Newton at (omega, level); if it fails, a homotopy in the excitation level at fixed omega,
    from 1 % of the level (where the contacts are near their static state and Newton from the
    preload converges) up to the level itself."""
    pt = hb.solve(omega, level, Z0, max_iterations=15 if Z0 is None else 25)
    if pt.converged or level == 0:
        return pt
    branch = trace(hb, "level", 0.01 * level, level, omega, max_dp=0.1 * level, max_steps=500)
    last = branch.points[-1] if branch.points else pt
    if branch.status == "OK" and last.converged:
        last.tangent = None
        return last
    return pt


def trace(hb: HarmonicBalance, parameter: str, start: float, end: float, fixed: float, **options) -> Branch:
    """Continue the balance from p = start to p = end (p = 'omega' [rad/s] or 'level'), the
    other parameter held at ``fixed`` (options: see :func:`_trace`); BLAS on one thread."""
    with blas_threads(hb.size):
        return _trace(hb, parameter, start, end, fixed, **options)


def _trace(
    hb: HarmonicBalance,
    parameter: str,
    start: float,
    end: float,
    fixed: float,
    *,
    ds: float | None = None,
    max_dp: float | None = None,
    max_dz: float = 0.1,
    min_ds: float = 1e-7,
    max_steps: int = 2000,
    target_iterations: int = 4,
    max_corrector: int = 12,
    tol: float = 1e-10,
    Z0: np.ndarray | None = None,
    progress: Callable[[Point], None] | None = None,
) -> Branch:
    """Continue the balance from p = start to p = end (p = 'omega' [rad/s] or 'level'), the
    other parameter held at ``fixed``. ``progress(point)`` is called after every point."""
    prob = _Problem(hb, parameter, fixed)
    branch = Branch()
    clock = [time.perf_counter()]

    def done(pt):
        now = time.perf_counter()
        pt.wall_time, clock[0] = now - clock[0], now
        branch.points.append(pt)
        if progress:
            progress(pt)

    span = end - start
    sign = 1.0 if span > 0 else -1.0
    ps = abs(span) if span != 0 else max(abs(start), 1.0)
    first = prob.solve(start, Z0)
    done(first)
    if not first.converged:
        branch.status, branch.message = "NOT_CONVERGED", f"the first point ({parameter} = {start:.6g}) did not converge"
        return branch
    if span == 0:
        return branch
    zs = max(hb.scale(first.Y, first.level), float(np.abs(first.Y[1:]).max(initial=0.0)))
    shape = first.Y.shape
    max_dp = abs(span) / 20 if max_dp is None else abs(max_dp)
    ds = max_dp / ps if ds is None else ds
    ds_max = max_dp / ps * 4
    y = np.concatenate([first.Y.ravel() / zs, [start / ps]])
    t_prev = np.zeros_like(y)
    t_prev[-1] = sign
    R, J, Jp = prob.evaluate(first.Y, start)
    t = _tangent(J, Jp, t_prev, zs, ps)
    first.tangent = (t[:-1].reshape(shape).copy(), float(t[-1]), zs, ps, parameter)
    n = y.size - 1
    while branch.steps < max_steps:
        branch.steps += 1
        # cap: parameter change and response change per step
        dp_frac = abs(t[-1]) * ds * ps
        if dp_frac > max_dp:
            ds *= max_dp / dp_frac
        dz = np.abs(t[:n]).max(initial=0.0) * ds
        if dz > max_dz:
            ds *= max_dz / dz
        y_pred = y + ds * t
        yc = y_pred.copy()
        ok, its = False, 0
        for its in range(1, max_corrector + 1):
            Z = (yc[:n] * zs).reshape(shape)
            p = yc[n] * ps
            R, J, Jp = prob.evaluate(Z, p)
            g = t @ (yc - y_pred)
            if hb.converged(R, Z, prob.args(p)[1], tol) and abs(g) <= 1e-12:
                ok = True
                break
            A = np.zeros((n + 1, n + 1))
            A[:n, :n] = J * zs
            A[:n, n] = Jp * ps
            A[n] = t
            try:
                delta = np.linalg.solve(A, -np.concatenate([R, [g]]))
            except np.linalg.LinAlgError:
                break
            yc = yc + delta
            if not np.all(np.isfinite(yc)):
                break
        if not ok:
            branch.failed_correctors += 1
            ds *= 0.5
            if ds < min_ds:
                branch.status = "NOT_CONVERGED"
                branch.message = (
                    f"the arclength step fell below {min_ds:g} at {parameter} = {y[n] * ps:.6g} "
                    f"(the corrector did not converge)"
                )
                return branch
            continue
        p = yc[n] * ps
        crossed = (p - end) * sign >= 0
        if crossed:  # land exactly on the end value
            frac = (end - y[n] * ps) / (p - y[n] * ps) if p != y[n] * ps else 1.0
            Zg = ((y[:n] + frac * (yc[:n] - y[:n])) * zs).reshape(shape)
            last = prob.solve(end, Zg)
            done(last)
            if not last.converged:
                branch.status, branch.message = (
                    "NOT_CONVERGED",
                    f"the end point ({parameter} = {end:.6g}) did not converge",
                )
            return branch
        Z = (yc[:n] * zs).reshape(shape)
        w, lv = prob.args(p)
        pt = hb.point(Z, w, lv, its - 1, True, hb.residual_norm(R))
        t_new = _tangent(J, Jp, t, zs, ps)
        pt.tangent = (t_new[:n].reshape(shape).copy(), float(t_new[n]), zs, ps, parameter)
        done(pt)
        if t_new[-1] * t[-1] < 0:
            branch.turning_points += 1
        y, t = yc, t_new
        zs_new = max(zs, float(np.abs(Z[1:]).max(initial=0.0)))  # the response scale grows along the branch
        if zs_new > zs:
            y[:n] *= zs / zs_new
            t[:n] *= zs / zs_new
            t /= np.linalg.norm(t)
            zs = zs_new
        ds = min(ds * min(2.0, max(0.5, target_iterations / max(its - 1, 1))), ds_max)
    branch.status, branch.message = (
        "NOT_CONVERGED",
        f"stopped after {max_steps} continuation steps before {parameter} = {end:.6g}",
    )
    return branch

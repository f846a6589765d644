"""Continuation of the harmonic balance over frequency or excitation level, through asked values.

The branch y(s) = (Y(s), p(s)) of R(Y, p) = 0 (Y the unknowns of slipstep.hbm.residual,
p = Omega or the excitation level lambda) is followed in scaled variables
y_s = (Y / z_scale, p / p_scale) from the first asked value to the last, landing on every
asked value in between (points marked "asked"; the others "continuation", or "turning" where
p reverses). From an asked point the next one is first tried by Newton at its value from the
tangent predictor (:func:`_natural_step`, refused where Newton jumps to another branch or a
fold lies between). Otherwise pseudo-arclength: from a solved point y_i with unit tangent t_i
(solution of [dR/dy_s; t_{i-1}^T] t = [0; 1], oriented along t_{i-1}), the predictor is
y_i + ds t_i and the corrector Newton's method (with backtracking) on

    R(Y, p) = 0,    t_i . (y_s - y_i - ds t_i) = 0          (the pseudo-arclength condition)

with the exact Jacobian [[dR/dY, dR/dp]; t_i^T]. It follows turning points (p reverses while
s keeps growing) and so both branches around a jump. Step control: ds grows by up to 2x
when the corrector needs few iterations (ds *= clip(target / iterations, 0.5, 2)), halves
after a failed corrector, and is capped so that a step moves p by at most ``max_dp`` and
the response by at most ``max_dz`` (relative). When a step crosses the next asked value the
continuation lands on it (Newton at that value from the interpolated crossing) and restarts
there; below ``min_ds``, or after ``max_between`` continuation points without reaching it,
the next asked value is solved by Newton from the last point instead.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from slipstep.hbm.residual import HarmonicBalance, Point
from slipstep.methods.blas import one_blas_thread


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
    pt = hb.solve(omega, level, Z0, max_iterations=30 if Z0 is None else 25)
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
    with one_blas_thread(hb.size):
        return _mark_turning(_trace(hb, parameter, start, end, fixed, **options), parameter)


def _mark_turning(branch: Branch, parameter: str) -> Branch:
    """Mark the continuation points where the parameter reverses (p_i - p_{i-1} and
    p_{i+1} - p_i of opposite signs) as "turning" and count them (judged on the points, not on
    the tangent, which the piecewise-smooth residual can flip spuriously)."""
    p = np.array([pt.omega if parameter == "omega" else pt.level for pt in branch.points])
    d = np.diff(p)
    count = 0
    for i in range(1, p.size - 1):
        if d[i - 1] * d[i] < 0 and branch.points[i].kind != "asked":
            branch.points[i].kind = "turning"
            count += 1
    branch.turning_points = count
    return branch


def _trace(
    hb: HarmonicBalance,
    parameter: str,
    start: float,
    end: float,
    fixed: float,
    *,
    asked=(),
    ds: float | None = None,
    max_dp: float | None = None,
    max_dz: float = 0.1,
    min_ds: float = 1e-7,
    max_steps: int = 2000,
    target_iterations: int = 4,
    max_corrector: int = 8,
    max_between: int = 15,
    tol: float = 1e-10,
    Z0: np.ndarray | None = None,
    progress: Callable[[Point], None] | None = None,
) -> Branch:
    """Continue the balance from p = start to p = end (p = 'omega' [rad/s] or 'level'), the
    other parameter held at ``fixed``, landing on each of ``asked`` (values strictly between
    start and end, in order) and on ``end`` when the branch first crosses it. ``progress(point)``
    is called after every point. Points are marked ``kind``: "asked" (start, the asked values,
    end), "continuation" or "turning". When the corrector fails below ``min_ds``, the next
    asked value is solved by Newton from the last point and the continuation restarts there;
    so it is after ``max_between`` continuation points without reaching it (the arclength
    crawling over a non-smooth stretch of the branch), when Newton converges there."""
    prob = _Problem(hb, parameter, fixed)
    branch = Branch()
    clock = [time.perf_counter()]

    def done(pt, kind):
        now = time.perf_counter()
        pt.wall_time, clock[0] = now - clock[0], now
        pt.kind = kind
        branch.points.append(pt)
        if progress:
            progress(pt)

    span = end - start
    sign = 1.0 if span > 0 else -1.0
    ps = abs(span) if span != 0 else max(abs(start), 1.0)
    targets = [float(v) for v in asked] + [float(end)]
    first = prob.solve(start, Z0)
    done(first, "asked")
    if not first.converged:
        branch.status, branch.message = "NOT_CONVERGED", f"the first point ({parameter} = {start:.6g}) did not converge"
        return _remaining(prob, branch, targets, None, done, parameter)
    if span == 0:
        return branch
    zs = max(hb.scale(first.Y, first.level), float(np.abs(first.Y[1:]).max(initial=0.0)))
    shape = first.Y.shape
    max_dp = abs(span) / 20 if max_dp is None else abs(max_dp)
    ds0 = max_dp / ps if ds is None else ds
    ds_max = max_dp / ps * 4
    n = first.Y.size

    def restart(pt, p, t_dir):
        """(y, t) at a solved point, the tangent oriented along t_dir."""
        _, J, Jp = prob.evaluate(pt.Y, p)
        t = _tangent(J, Jp, t_dir, zs, ps)
        pt.tangent = (t[:-1].reshape(shape).copy(), float(t[-1]), zs, ps, parameter)
        return np.concatenate([pt.Y.ravel() / zs, [p / ps]]), t

    along = np.zeros(n + 1)
    along[-1] = sign
    y, t = restart(first, start, along)
    ds = ds0
    last_good = first
    natural = True  # try a natural-parameter step to the next asked value (after each landing)
    between = 0  # continuation points since the last asked one
    while branch.steps < max_steps and targets:
        branch.steps += 1
        if natural or between >= max_between:
            crawl, natural = between >= max_between, False
            between = 0 if crawl else between
            pt = _natural_step(hb, prob, y, t, targets[0], zs, ps, shape, tol, fold_check=not crawl)
            if pt is not None:
                target = targets.pop(0)
                done(pt, "asked")
                y = np.concatenate([pt.Y.ravel() / zs, [target / ps]])
                t = np.concatenate([pt.tangent[0].ravel(), [pt.tangent[1]]])
                last_good, natural, between = pt, True, 0
                if crawl:
                    branch.message = (
                        f"the arclength crawled ({max_between} points) before {parameter} = {target:.6g}; "
                        "solved there by Newton from the last point"
                    )
                continue
        dp_frac = abs(t[-1]) * ds * ps  # cap: parameter change and response change per step
        if dp_frac > max_dp:
            ds *= max_dp / dp_frac
        dz = np.abs(t[:n]).max(initial=0.0) * ds
        if dz > max_dz:
            ds *= max_dz / dz
        ok, its, yc, R, J, Jp = _corrector(prob, hb, y, t, ds, zs, ps, shape, tol, max_corrector)
        if not ok:
            branch.failed_correctors += 1
            ds *= 0.5
            if ds >= min_ds:
                continue
            # the arclength failed: Newton at the next asked value from the last point, then go on from there
            target = targets.pop(0)
            pt = prob.solve(target, last_good.Y)
            done(pt, "asked")
            branch.message = (
                f"the arclength corrector failed near {parameter} = {y[n] * ps:.6g}; "
                f"{parameter} = {target:.6g} solved from the last point"
            )
            if not pt.converged:
                return _remaining(prob, branch, targets, last_good.Y, done, parameter)
            y, t = restart(pt, target, along)
            ds, last_good, natural, between = ds0, pt, True, 0
            continue
        p = yc[n] * ps
        target = targets[0]
        if (p - target) * sign >= 0 and (y[n] * ps - target) * sign < 0:  # crossed: land on it exactly
            frac = (target - y[n] * ps) / (p - y[n] * ps)
            Yg = ((y[:n] + frac * (yc[:n] - y[:n])) * zs).reshape(shape)
            pt = prob.solve(target, Yg)
            if pt.converged:
                targets.pop(0)
                done(pt, "asked")
                if not targets:
                    return branch
                y, t = restart(pt, target, t)
                last_good, natural, between = pt, True, 0
                ds = min(ds * min(2.0, max(0.5, target_iterations / max(its - 1, 1))), ds_max)
                continue
            ds *= 0.5  # the landing failed: a shorter step lands closer
            if ds >= min_ds:
                continue
            targets.pop(0)
            done(pt, "asked")
            return _remaining(prob, branch, targets, last_good.Y, done, parameter)
        Y = (yc[:n] * zs).reshape(shape)
        w, lv = prob.args(p)
        pt = hb.point(Y, w, lv, its - 1, True, hb.residual_norm(R))
        t_new = _tangent(J, Jp, t, zs, ps)
        pt.tangent = (t_new[:n].reshape(shape).copy(), float(t_new[n]), zs, ps, parameter)
        done(pt, "continuation")
        last_good, between = pt, between + 1
        y, t = yc, t_new
        zs_new = max(zs, float(np.abs(Y[1:]).max(initial=0.0)))  # the response scale grows along the branch
        if zs_new > zs:
            y[:n] *= zs / zs_new
            t[:n] *= zs / zs_new
            t /= np.linalg.norm(t)
            zs = zs_new
        ds = min(ds * min(2.0, max(0.5, target_iterations / max(its - 1, 1))), ds_max)
    if targets:
        branch.status, branch.message = (
            "NOT_CONVERGED",
            f"stopped after {max_steps} continuation steps before {parameter} = {end:.6g}",
        )
        return _remaining(prob, branch, targets, last_good.Y, done, parameter)
    return branch


def _natural_step(hb, prob, y, t, target, zs, ps, shape, tol, jump=0.5, max_iterations=25, fold_check=True):
    """Newton at p = target from the tangent predictor Y + (target - p) dY/dp (else from Y
    itself: near a peak the tangent is steep and its predictor poor); the solved point
    (its tangent oriented along t), or None where that is not the branch continued: Newton
    failed, the solution is farther than ``jump`` x the response scale from the predictor
    (it jumped to another branch), or the tangent's parameter component reversed (a fold lies
    between; not checked with ``fold_check`` False). The arclength then takes over."""
    n = y.size - 1
    step = (target / ps - y[n]) / t[n] if t[n] != 0 else -1.0
    if step <= 0 and fold_check:
        return None
    w, lv = prob.args(target)
    guesses = [(y[:n] * zs).reshape(shape)]
    if step > 0:
        guesses.insert(0, ((y[:n] + step * t[:n]) * zs).reshape(shape))
    for Y_pred in guesses:
        pt = hb.solve(w, lv, Y_pred, tol=tol, max_iterations=max_iterations)  # tangent, then last point
        if pt.converged:
            break
    if not pt.converged or np.abs(pt.Y - Y_pred).max(initial=0.0) > jump * zs:
        return None
    _, J, Jp = prob.evaluate(pt.Y, target)
    t_new = _tangent(J, Jp, t, zs, ps)
    if fold_check and t_new[n] * t[n] <= 0:
        return None
    pt.tangent = (t_new[:n].reshape(shape).copy(), float(t_new[n]), zs, ps, prob.parameter)
    return pt


def _corrector(prob, hb, y, t, ds, zs, ps, shape, tol, max_corrector):
    """Newton on [R(Z, p); t . (y - y_pred)] = 0 from the predictor y + ds t, with backtracking
    on |R| + |g| (the residual is piecewise smooth: the AFT states change between samples).
    Returns (converged, iterations, y, R, dR/dZ, dR/dp) at the last iterate."""
    n = y.size - 1
    y_pred = y + ds * t
    yc = y_pred.copy()
    merit = None
    for its in range(1, max_corrector + 1):
        Z = (yc[:n] * zs).reshape(shape)
        p = yc[n] * ps
        R, J, Jp = prob.evaluate(Z, p)
        g = t @ (yc - y_pred)
        if hb.converged(R, Z, prob.args(p)[1], tol) and abs(g) <= 1e-12:
            return True, its, yc, R, J, Jp
        A = np.zeros((n + 1, n + 1))
        A[:n, :n] = J * zs
        A[:n, n] = Jp * ps
        A[n] = t
        try:
            delta = np.linalg.solve(A, -np.concatenate([R, [g]]))
        except np.linalg.LinAlgError:
            break
        merit = np.linalg.norm(R) + abs(g) * zs if merit is None else merit
        alpha, trial, mt = 1.0, yc, np.inf
        for _ in range(6):
            trial = yc + alpha * delta
            if not np.all(np.isfinite(trial)):
                alpha *= 0.5
                continue
            Rt = prob.evaluate((trial[:n] * zs).reshape(shape), trial[n] * ps, jacobian=False)
            mt = np.linalg.norm(Rt) + abs(t @ (trial - y_pred)) * zs
            if mt < merit:
                break
            alpha *= 0.5
        yc, merit = trial, mt
        if not np.all(np.isfinite(yc)):
            break
    return False, max_corrector, yc, None, None, None


def _remaining(prob, branch, targets, Y, done, parameter):
    """Newton at each remaining asked value, each from the last converged solution (after the
    continuation failed); the branch is NOT_CONVERGED where one of them does not converge."""
    for target in targets:
        pt = prob.solve(target, Y)
        done(pt, "asked")
        if pt.converged:
            Y = pt.Y
        else:
            branch.status = "NOT_CONVERGED"
            branch.message = f"{parameter} = {target:.6g} did not converge"
    targets.clear()
    return branch

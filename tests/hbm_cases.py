"""Oscillators shared by the harmonic-balance tests and benchmarks/bench_hbm.py.

Jenkins element: a spring k_t in series with a Coulomb slider of constant slip force F_s,
modelled as a ContactElement whose normal row gathers nothing and whose normal offset g
gives the constant normal load N = k_n g = F_s (mu = 1).
"""

import numpy as np

import slipstep as ss

KN = 1.0e6


def jenkins(row, kt, fs, name, mu=1.0):
    A = np.vstack([np.asarray(row, float), np.zeros(len(row))])
    return ss.ContactElement(
        name, A, tangential_stiffness=kt, normal_stiffness=KN, friction_coefficient=mu, normal_offset=fs / KN
    )


def jenkins_1dof(frequency=350.0, force=100.0, mu=1.0, alpha=40.0):
    """m 2.5 kg, k 1e7 N/m, C = alpha M, k_t 1e7 N/m, slip force 50 N, force 100 N at 350 Hz."""
    m, k = 2.5, 1.0e7
    st = ss.Structure(np.array([[m]]), np.array([[alpha * m]]), np.array([[k]]), dof_names=("x",))
    exc = ss.Excitation(force=ss.Signal(("x",), (ss.Harmonic(frequency, [force]),)))
    return ss.System(st, (jenkins([1.0], 1.0e7, 50.0, "J", mu),), exc, name="jenkins-1dof")


def jenkins_2dof(frequency=300.0, force=80.0, mu=1.0):
    """Two masses in a chain (k1 to ground, k2 between), a Jenkins element to ground on x1 and
    one between x1 and x2; C = 40 M; the force on x2."""
    M = np.diag([2.5, 1.5])
    k1, k2 = 1.0e7, 6.0e6
    K = np.array([[k1 + k2, -k2], [-k2, k2]])
    st = ss.Structure(M, 40.0 * M, K, dof_names=("x1", "x2"))
    exc = ss.Excitation(force=ss.Signal(("x1", "x2"), (ss.Harmonic(frequency, [0.0, force]),)))
    contacts = (jenkins([1.0, 0.0], 1.0e7, 40.0, "J1", mu), jenkins([-1.0, 1.0], 5.0e6, 20.0, "J2", mu))
    return ss.System(st, contacts, exc, name="jenkins-2dof")


def gap_oscillator(frequency=10.0, force=2.0):
    """1 DOF (15.9 Hz) hitting a unilateral spring 2x as stiff after a 1 mm gap: a stiffening
    response whose FRF folds over (two turning points)."""
    A = np.array([[0.0], [1.0]])
    c = ss.ContactElement(
        "gap", A, tangential_stiffness=1e4, normal_stiffness=2e4, friction_coefficient=0.0, normal_offset=-1e-3
    )
    st = ss.Structure(np.array([[1.0]]), np.array([[4.0]]), np.array([[1e4]]), dof_names=("x",))
    return ss.System(st, (c,), ss.Excitation(force=ss.Signal(("x",), (ss.Harmonic(frequency, [force]),))), name="gap")


def wedge(frequency=200.0):
    """2 DOFs (x tangential, y normal) pressed by a constant load onto a 2D friction contact with
    variable normal load and lift-off, driven by a harmonic tangential and normal force, plus a
    quasi-3D contact on a third DOF; C = 20 M."""
    M = np.diag([0.2, 0.2, 0.1])
    K = np.diag([2e6, 1e6, 1.5e6])
    A1 = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # u = x, v = -y (pressed down by -y load)
    A2 = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # quasi-3D: u1 = z, u2 = x, v = -y
    c1 = ss.ContactElement("C1", A1, tangential_stiffness=3e6, normal_stiffness=4e6, friction_coefficient=0.3)
    c2 = ss.ContactElement("C2", A2, tangential_stiffness=(2e6, 1e6), normal_stiffness=2e6, friction_coefficient=0.5)
    st = ss.Structure(M, 20.0 * M, K, dof_names=("x", "y", "z"))
    exc = ss.Excitation(
        constant_force=np.array([0.0, -60.0, 0.0]),
        force=ss.Signal(("x", "y", "z"), (ss.Harmonic(frequency, [40.0, 90.0, 30.0], [0.0, 0.7, 1.3]),)),
    )
    return ss.System(st, (c1, c2), exc, name="wedge")


def base_driven(frequency=300.0, base=2.0e-5):
    """jenkins_1dof driven through its Jenkins element by a prescribed base motion p (the
    contact's tangential coordinate u = x - p) besides a force on x."""
    m, k = 2.5, 1.0e7
    st = ss.Structure(np.array([[m]]), np.array([[40.0 * m]]), np.array([[k]]), dof_names=("x",))
    c = ss.ContactElement(
        "J",
        np.array([[1.0], [0.0]]),
        tangential_stiffness=1.0e7,
        normal_stiffness=KN,
        friction_coefficient=1.0,
        normal_offset=50.0 / KN,
        motion_gather=np.array([[1.0], [0.0]]),
    )
    exc = ss.Excitation(
        force=ss.Signal(("x",), (ss.Harmonic(frequency, [40.0]),)),
        motion=ss.Signal(("base",), (ss.Harmonic(frequency, [base]),)),
    )
    return ss.System(st, (c,), exc, name="base-driven")

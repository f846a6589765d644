"""The real Fourier basis of a harmonic balance: a chosen set of harmonics and its time samples.

A periodic coordinate is represented by its real coefficients over the retained harmonics
h_0 = 0 < h_1 < ... < h_m (the mean is always retained):

    y(theta) = c_0 + sum_i ( a_i cos(h_i theta) + b_i sin(h_i theta) ),   theta = Omega t,

stored in the order z = [c_0, a_1, b_1, a_2, b_2, ...] (n_coef = 1 + 2 m entries). The
time samples are theta_k = 2 pi k / N, k = 0..N-1 (N > 2 h_m, no aliasing of retained
harmonics onto each other). ``inverse`` E (N x n_coef) gives the samples y_k = E z;
``forward`` P (n_coef x N) the discrete Fourier coefficients z = P y (P E = I). The complex
phasor of harmonic h_i is Y_i = a_i - i b_i, so that y = Re(sum Y_i exp(i h_i theta)).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from slipstep.errors import InputError


def harmonic_set(harmonics) -> np.ndarray:
    """The retained harmonic numbers, sorted, with 0 (the mean) always included.

    ``harmonics``: an int H (all of 0..H) or a sequence of non-negative ints (a chosen set,
    e.g. (1, 3, 5) for odd harmonics)."""
    if isinstance(harmonics, (bool, np.bool_)):
        raise InputError("harmonics", f"is {harmonics!r}", "give an int H (harmonics 0..H) or a list like [1, 3, 5]")
    if isinstance(harmonics, (int, np.integer)):
        if harmonics < 1:
            raise InputError("harmonics", f"is {harmonics}", "give H >= 1 (harmonics 0..H)")
        return np.arange(int(harmonics) + 1)
    try:
        hs = [int(h) for h in harmonics]
        ok = all(float(h) == int(h) for h in harmonics)
    except (TypeError, ValueError):
        ok = False
    if not ok or not hs or min(hs) < 0:
        raise InputError("harmonics", f"is {harmonics!r}", "give non-negative whole numbers, e.g. [1, 3, 5]")
    out = np.unique(np.array([0] + hs, dtype=np.int64))
    if out.size < 2:
        raise InputError("harmonics", f"is {harmonics!r}: only the mean", "retain at least harmonic 1")
    return out


@dataclass(frozen=True)
class Basis:
    """Harmonic set ``h`` (with 0) and ``samples`` N per period; the DFT matrices."""

    h: np.ndarray
    samples: int
    inverse: np.ndarray = field(init=False, repr=False)
    forward: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        h = np.asarray(self.h, dtype=np.int64)
        n = int(self.samples)
        if n <= 2 * h.max():
            raise InputError(
                "samples",
                f"is {n}, not above 2 x the highest harmonic {h.max()}",
                f"give at least {2 * h.max() + 1} samples (4-8 x the highest harmonic is usual)",
            )
        theta = 2.0 * np.pi * np.arange(n) / n
        E = np.empty((n, 2 * h.size - 1))
        E[:, 0] = 1.0
        ht = np.outer(theta, h[1:])
        E[:, 1::2] = np.cos(ht)
        E[:, 2::2] = np.sin(ht)
        P = E.T * (2.0 / n)
        P[0] *= 0.5
        object.__setattr__(self, "h", h)
        object.__setattr__(self, "samples", n)
        object.__setattr__(self, "inverse", np.ascontiguousarray(E))
        object.__setattr__(self, "forward", np.ascontiguousarray(P))

    @property
    def n_coef(self) -> int:
        return 2 * self.h.size - 1

    @property
    def theta(self) -> np.ndarray:
        return 2.0 * np.pi * np.arange(self.samples) / self.samples

    def phasors(self, z: np.ndarray) -> np.ndarray:
        """Complex phasors Y_i = a_i - i b_i (Y_0 = c_0) of coefficients z (n_coef, ...)."""
        out = np.empty((self.h.size,) + z.shape[1:], dtype=complex)
        out[0] = z[0]
        out[1:] = z[1::2] - 1j * z[2::2]
        return out

    def coefficients(self, Y: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`phasors`: z = [Re Y_0, Re Y_1, -Im Y_1, ...]."""
        out = np.empty((self.n_coef,) + Y.shape[1:])
        out[0] = Y[0].real
        out[1::2] = Y[1:].real
        out[2::2] = -Y[1:].imag
        return out


def spectrum(samples: np.ndarray) -> np.ndarray:
    """|c_h| of every harmonic 0..N/2 of real samples (N, ...) along axis 0 (single-sided amplitudes)."""
    n = samples.shape[0]
    c = np.abs(np.fft.rfft(samples, axis=0)) * (2.0 / n)
    c[0] *= 0.5
    return c

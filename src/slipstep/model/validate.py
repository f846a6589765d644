"""Small validators that raise :class:`~slipstep.errors.InputError` naming the field."""

from __future__ import annotations

import numpy as np

from slipstep.errors import InputError


def float_array(field: str, value, ndim: int | None = None, shape: tuple | None = None) -> np.ndarray:
    """Convert to a finite float64 array of the given rank/shape or raise naming ``field``."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(field, f"is not numeric ({exc})", "give numbers only") from None
    if ndim is not None and arr.ndim != ndim:
        raise InputError(field, f"has {arr.ndim} dimension(s), expected {ndim}",
                         f"give a {'vector' if ndim == 1 else 'matrix' if ndim == 2 else f'{ndim}-d array'}")
    if shape is not None:
        for axis, (got, want) in enumerate(zip(arr.shape, shape)):
            if want is not None and got != want:
                raise InputError(field, f"has shape {arr.shape}, expected {tuple('*' if s is None else s for s in shape)}",
                                 f"make axis {axis} of length {want}")
    if not np.all(np.isfinite(arr)):
        raise InputError(field, "contains NaN or infinite values", "give finite numbers")
    return arr


def positive(field: str, value, allow_zero: bool = False) -> float:
    """A finite scalar > 0 (or >= 0)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(field, f"is not a number ({value!r})", "give a number") from None
    if not np.isfinite(x):
        raise InputError(field, "is not finite", "give a finite number")
    if x < 0 or (x == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise InputError(field, f"is {x}, must be {bound}", f"give a value {bound}")
    return x


def finite(field: str, value) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(field, f"is not a number ({value!r})", "give a number") from None
    if not np.isfinite(x):
        raise InputError(field, "is not finite", "give a finite number")
    return x


def square_matrix(field: str, value, n: int | None = None) -> np.ndarray:
    arr = float_array(field, value, ndim=2)
    if arr.shape[0] != arr.shape[1]:
        raise InputError(field, f"is {arr.shape[0]}x{arr.shape[1]}, not square", "give an n x n matrix")
    if n is not None and arr.shape[0] != n:
        raise InputError(field, f"is {arr.shape[0]}x{arr.shape[1]} but the structure has {n} DOFs",
                         f"give a {n}x{n} matrix")
    return arr

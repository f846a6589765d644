"""Small validators that raise :class:`~slipstep.errors.InputError` naming the field."""

from __future__ import annotations

import math
import re

import numpy as np

from slipstep.errors import InputError
from slipstep.model.text import MAX_NAME_LENGTH, check_name, escape_text  # noqa: F401 (re-exported)

#: no physical input of slipstep reaches this magnitude in SI or in the units of a case file;
#: beyond it products overflow (1e300 * 1e10 = inf) and the run would give inf/NaN, not an error
MAX_MAGNITUDE = 1e100


def float_array(field: str, value, ndim: int | None = None, shape: tuple | None = None) -> np.ndarray:
    """Convert to a finite float64 array of the given rank/shape or raise naming ``field``
    (complex numbers and numbers written as text are refused, not converted: a cast would drop
    the imaginary part or read a string silently)."""
    _real_numbers(field, value)
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        if "inhomogeneous" in str(exc):
            raise InputError(field, "is ragged (rows of different lengths)", "give rows of equal length") from None
        raise InputError(field, f"is not numeric ({' '.join(str(exc).split())[:120]})", "give numbers only") from None
    if ndim is not None and arr.ndim != ndim:
        raise InputError(
            field,
            f"has {arr.ndim} dimension(s), expected {ndim}",
            f"give a {'vector' if ndim == 1 else 'matrix' if ndim == 2 else f'{ndim}-d array'}",
        )
    if shape is not None:
        for axis, (got, want) in enumerate(zip(arr.shape, shape)):
            if want is not None and got != want:
                raise InputError(
                    field,
                    f"has shape {arr.shape}, expected {tuple('*' if s is None else s for s in shape)}",
                    f"make axis {axis} of length {want}",
                )
    if not np.all(np.isfinite(arr)):
        raise InputError(field, "contains NaN or infinite values", "give finite numbers")
    if arr.size and np.abs(arr).max() > MAX_MAGNITUDE:
        raise InputError(
            field,
            f"holds {np.abs(arr).max():.3g}, beyond any physical value (|x| > {MAX_MAGNITUDE:g})",
            "check the values and their units",
        )
    return arr


def _real_numbers(field: str, value) -> None:
    """Refuse complex values and text inside an array-like (np.array(..., float) would cast them)."""
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError):  # ragged: float_array's conversion names it
        return
    kind = raw.dtype.kind
    if kind == "c":
        raise InputError(
            field, "holds complex numbers", "give real numbers (a cast to real would drop the imaginary part)"
        )
    if kind in "US" or (kind == "O" and any(isinstance(v, (str, bytes)) for v in raw.ravel())):
        raise InputError(field, "holds text (numbers written as strings)", "give numbers, not strings: 1.0, not '1.0'")
    if kind == "O" and any(isinstance(v, complex) for v in raw.ravel()):
        raise InputError(
            field, "holds complex numbers", "give real numbers (a cast to real would drop the imaginary part)"
        )


def positive(field: str, value, allow_zero: bool = False) -> float:
    """A finite scalar > 0 (or >= 0); a boolean is not a number."""
    x = finite(field, value)
    if x < 0 or (x == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise InputError(field, f"is {x}, must be {bound}", f"give a value {bound}")
    return x


def finite(field: str, value) -> float:
    """A finite scalar; a boolean is not a number."""
    _not_bool(field, value)
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(field, f"is not a number ({value!r})", "give a number") from None
    if not np.isfinite(x):
        raise InputError(field, f"is {x}, not a finite number", "give a finite number")
    return _not_absurd(field, x)


def _not_bool(field: str, value) -> None:
    """Booleans and text are not numbers (float(True) = 1.0 and float('3') = 3.0 would pass)."""
    if isinstance(value, (bool, np.bool_)):
        raise InputError(field, f"is {value!r}, a boolean", "give a number")
    if isinstance(value, (str, bytes)):
        raise InputError(field, f"is {value!r}, text", "give a number, not a string")


def _not_absurd(field: str, x: float) -> float:
    if abs(x) > MAX_MAGNITUDE:
        raise InputError(
            field, f"is {x:.3g}, beyond any physical value (|x| > {MAX_MAGNITUDE:g})", "check the value and its unit"
        )
    return x


_NUMBER = re.compile(r"^[+-]?(\d{1,40}(\.\d{0,40})?|\.\d{1,40})([eE][+-]?\d{1,4})?$")


def number_text(field: str, text: str) -> float:
    """A number typed as text ('0.1', '1e-3', '1/6'): finite, at most 40 digits and a 4-digit
    exponent (so '1e100000000' is refused at once instead of built as an integer)."""
    text = str(text).strip()
    parts = text.split("/")
    if len(parts) > 2 or not all(_NUMBER.match(p.strip()) for p in parts):
        raise InputError(field, f"{text!r} is not a number", "give a number or a fraction such as 1/6")
    values = [float(p) for p in parts]
    value = values[0] / values[1] if len(values) == 2 and values[1] != 0 else values[0]
    if len(values) == 2 and values[1] == 0:
        raise InputError(field, f"{text!r} divides by zero", "give a number or a fraction such as 1/6")
    if not math.isfinite(value):
        raise InputError(field, f"{text!r} is not a finite number", "give a finite number")
    return _not_absurd(field, value)


def square_matrix(field: str, value, n: int | None = None) -> np.ndarray:
    arr = float_array(field, value, ndim=2)
    if arr.shape[0] != arr.shape[1]:
        raise InputError(field, f"is {arr.shape[0]}x{arr.shape[1]}, not square", "give an n x n matrix")
    if n is not None and arr.shape[0] != n:
        raise InputError(
            field, f"is {arr.shape[0]}x{arr.shape[1]} but the structure has {n} DOFs", f"give a {n}x{n} matrix"
        )
    return arr


def square_matrix_or_sparse(field: str, value, n: int | None = None):
    """A square finite matrix: a scipy.sparse one is kept sparse (:func:`_sparse_matrix`),
    anything else as :func:`square_matrix`."""
    import scipy.sparse as sp

    if not sp.issparse(value):
        return square_matrix(field, value, n)
    A = _sparse_matrix(field, value)
    if A.shape[0] != A.shape[1]:
        raise InputError(field, f"is {A.shape[0]}x{A.shape[1]}, not square", "give an n x n matrix")
    if n is not None and A.shape[0] != n:
        raise InputError(
            field, f"is {A.shape[0]}x{A.shape[1]} but the structure has {n} DOFs", f"give a {n}x{n} matrix"
        )
    return A


def gather_matrix(field: str, value):
    """A contact's gather map (rows x DOFs): a scipy.sparse one is kept sparse
    (:func:`_sparse_matrix`), anything else as a finite dense matrix."""
    import scipy.sparse as sp

    if not sp.issparse(value):
        return float_array(field, value, ndim=2)
    return _sparse_matrix(field, value)


def _sparse_matrix(field: str, value):
    """A scipy.sparse matrix as canonical CSR (duplicates summed, explicit zeros dropped,
    indices sorted) with finite values of physical magnitude."""
    import scipy.sparse as sp

    if np.dtype(value.dtype).kind == "c":
        raise InputError(
            field, "holds complex numbers", "give real numbers (a cast to real would drop the imaginary part)"
        )
    try:
        A = sp.csr_matrix(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(field, f"is not numeric ({' '.join(str(exc).split())[:120]})", "give numbers only") from None
    A.sum_duplicates()
    A.eliminate_zeros()
    A.sort_indices()
    if not np.all(np.isfinite(A.data)):
        raise InputError(field, "contains NaN or infinite values", "give finite numbers")
    if A.nnz and np.abs(A.data).max() > MAX_MAGNITUDE:
        raise InputError(
            field,
            f"holds {np.abs(A.data).max():.3g}, beyond any physical value (|x| > {MAX_MAGNITUDE:g})",
            "check the values and their units",
        )
    return A


def names(field: str, values, what: str, unique: bool = True) -> tuple[str, ...]:
    """A sequence of names (each :func:`check_name`), unique unless ``unique`` is False; a bare
    string is not a sequence of names."""
    if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
        raise InputError(field, f"is {values!r}, not a sequence of {what} names", 'give a tuple of names: ("a", "b")')
    out = tuple(values)
    for value in out:
        check_name(field, value)
    if unique and len(set(out)) != len(out):
        twice = sorted({v for v in out if out.count(v) > 1})
        raise InputError(field, f"names {twice} more than once", f"give every {what} its own name")
    return out

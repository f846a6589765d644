"""The frequency grid of an FRF: reading it from the command line's text and checking it."""

from __future__ import annotations

import numpy as np

from slipstep.errors import InputError


def parse_frequencies(text: str, field: str = "--frequencies") -> list[float]:
    """'150:450:61' (start:stop:count, both ends included) or '300,350,400' [Hz]."""
    text = text.strip()
    try:
        if ":" in text:
            parts = text.split(":")
            if len(parts) != 3:
                raise ValueError
            start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
            if count < 1:
                raise ValueError
            if count == 1:
                return [start]
            return [start + (stop - start) * i / (count - 1) for i in range(count)]
        return [float(p) for p in text.split(",") if p.strip()]
    except ValueError:
        raise InputError(
            field, f"cannot read {text!r}", "give start:stop:count (e.g. 150:450:61) or a comma list (e.g. 300,350,400)"
        ) from None


def check_frequencies(frequencies) -> np.ndarray:
    try:
        f = np.atleast_1d(np.asarray(frequencies, dtype=float))
    except (TypeError, ValueError):
        raise InputError("frequencies", f"is {frequencies!r}", "give a list of frequencies in Hz") from None
    if f.ndim != 1 or f.size == 0 or not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise InputError(
            "frequencies",
            f"must be positive finite numbers (got {f.tolist()[:5]}...)",
            "give frequencies in Hz, e.g. 150:450:61",
        )
    if np.unique(f).size != f.size:
        raise InputError("frequencies", "contains repeated values", "give each frequency once")
    return f

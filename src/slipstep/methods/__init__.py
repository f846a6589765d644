"""The march: options, plans, marchers, starting states and the method registry."""

from slipstep.methods import sparse_marcher  # noqa: F401  (registers the sparse backend's marcher)

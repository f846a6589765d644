"""Multi-harmonic balance with alternating frequency-time contact forces, on the same System
as the time marching (issue 13): the designers' usual tool, cross-checked by the exact one.

- :mod:`fourier`: the harmonic set, its time samples and DFT matrices;
- :mod:`aft`: the AFT contact forces with the kernels' law and their exact Jacobian;
- :mod:`linear`: excitation phasors and the dynamic compliance per harmonic;
- :mod:`residual`: the balance condensed onto the contact coordinates, Newton per point;
- :mod:`continuation`: pseudo-arclength over frequency or excitation level;
- :mod:`adequacy`: the harmonic-adequacy estimate and warning;
- :mod:`crosscheck`: the time-marching cross-check of chosen points;
- :mod:`frf`: the FRF driver returning the Dataset of ``slipstep.output.frf_schema``.
"""

from slipstep.hbm.frf import frf, level_response
from slipstep.hbm.residual import HarmonicBalance, Point

__all__ = ["HarmonicBalance", "Point", "frf", "level_response"]

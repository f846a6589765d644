"""Frequency response: the FRF driver, steady states per frequency, linear limits, harmonics.

The layout of every FRF Dataset (marched, shot, harmonic balance) is declared once, in
:mod:`slipstep.frequency.schema`.
"""

"""The numba kernels: plain functions over arrays and explicit state; no classes, no I/O.

``play`` (play operators, their compensator, controller and bank steps), ``packed`` (the
Preisach, Duhem and Bouc-Wen cores' steps and inverse), ``signal`` (running integral, lags,
input and mode filters, turns). Loaded when a model first runs (see :mod:`piezohyst._lazy`).
May import: the foundation (errors, _validation) only.
"""

"""Symbols shared by every stage of the pipeline."""
import sympy as sp

#: The time step. It is a run-time argument of every generated function.
h = sp.Symbol("h", positive=True)

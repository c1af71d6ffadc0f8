"""Stage 3, derivation: discrete Euler–Lagrange equations and their Jacobians as kernels
(paper §4–§5, DESIGN.md §4–§6), in :mod:`.derive`.
"""

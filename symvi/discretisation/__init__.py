"""Stage 2, discretisation: the discrete Lagrangian on the groupoid (paper §4, DESIGN.md §4).

:mod:`.rules` holds the quadrature rules, each owning its quadrature and consistency
order; :mod:`.discretise` turns a :class:`~symvi.declaration.model.Model` into a frozen
:class:`~symvi.discretisation.discretise.DiscreteModel`.
"""

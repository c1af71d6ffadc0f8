"""Stage 1, declaration: what the user writes down (paper §2–§3, DESIGN.md §1–§3).

The symbols shared by every stage (:mod:`.symbols`), checks of user input
(:mod:`.validation`), the continuous model on a Lie groupoid (:mod:`.model`), its
symmetries (:mod:`.symmetry`), optimal control as a second-order model on the algebroid
(:mod:`.control`), and the generic rank used to refuse degenerate Lagrangians
(:mod:`.rank`). The groupoids themselves live in :mod:`symvi.groupoids`.
"""

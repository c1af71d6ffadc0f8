"""The sign assumptions a parameter may be declared with, and what each requires of its
value: read by the declaration (which of a symbol's assumptions counts,
``symvi.declaration.symbols.sign``), by the command line and by the run time
(:func:`.arguments.parameters`).

A leaf both sides share: it imports nothing, so the declaration reads it without reaching
into the run time's machinery, and the copy in every generated package (which cannot
import symvi) holds the same table. Read only: nothing assigns to it.
"""

#: What a parameter declared with a sign assumption must satisfy, strongest first (the
#: declaration reads its symbols' assumptions in this order).
SIGNS = {"positive": (lambda v: v > 0, "> 0"), "nonnegative": (lambda v: v >= 0, "≥ 0"),
         "negative": (lambda v: v < 0, "< 0"), "nonpositive": (lambda v: v <= 0, "≤ 0")}

"""Exceptions raised by the compiler stages (model, derivation, build).

Run-time errors of generated modules live in :mod:`symvi._runtime.core.errors`, which the
generated packages carry with them (they must not import symvi itself).
"""


class SymviError(Exception):
    """Base class of every error symvi raises on purpose."""


class ModelError(SymviError, ValueError):
    """A model declaration is invalid: undeclared symbol, wrong shape, not regular, ..."""


class BuildError(SymviError, RuntimeError):
    """The C build failed; the message carries the compiler's own output."""


class CompilerNotFoundError(BuildError):
    """No working C compiler is available to cffi."""


class OutputConflictError(BuildError, ValueError):
    """The output folder holds something named like the model's package that symvi did
    not make: the build refuses it (never moves or deletes it). A ``ValueError`` too: bad
    input, fixed by another output folder or a rename."""


class DamagedPackageError(SymviError, ImportError):
    """A generated package's files do not match its manifest: recompile it."""


class CacheWarning(UserWarning):
    """A cached build was found damaged and is being rebuilt."""

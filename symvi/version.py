"""symvi's version (its own module, so that the stages can read it without importing the
package ``symvi``, whose ``__init__`` imports them)."""
__version__ = "0.1.0"

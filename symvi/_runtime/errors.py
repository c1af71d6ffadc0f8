"""Errors raised by generated modules."""


class NewtonError(RuntimeError):
    """Newton's method failed; ``result`` holds the partial result and its message."""

    def __init__(self, result):
        super().__init__(result.message)
        self.result = result

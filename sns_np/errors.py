"""Exception types raised by sns_np.

Every error is a subclass of :class:`ValueError`, so ``except ValueError`` catches all bad
input; the subclasses let callers tell the kinds apart.
"""


class SNSError(ValueError):
    """Base class of every sns_np input or data error."""


class ShapeError(SNSError):
    """An array has the wrong shape, dtype or contains non-finite values."""


class ModelFileError(SNSError):
    """A model or checkpoint file is missing, corrupt, foreign or of an incompatible version."""


class MeshError(SNSError):
    """A mesh cannot be read or fails a topological or geometric check."""


class DegenerateMapError(SNSError):
    """A surface map has a (near-)singular Jacobian where a regular one is needed."""


class DivergenceError(SNSError, ArithmeticError):
    """An optimisation or time integration produced non-finite values or exploded."""

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


class FitInterrupted(KeyboardInterrupt):
    """A fit stopped by Ctrl-C (SIGINT) or SIGTERM, between two optimiser steps.

    It is a :class:`KeyboardInterrupt`, so code that handles Ctrl-C handles it too.
    ``step`` is the last completed step, ``checkpoint`` the file that holds it (None when the
    fit had no checkpoint) and ``signal_name`` the signal's name ("SIGINT", "SIGTERM").
    """

    def __init__(self, step, checkpoint=None, signal_name="SIGINT"):
        self.step, self.checkpoint, self.signal_name = step, checkpoint, signal_name
        saved = (f"the checkpoint {str(checkpoint)!r} holds it (resume=True continues the fit)"
                 if checkpoint is not None else "no checkpoint was asked for")
        super().__init__(f"fit interrupted by {signal_name} after step {step}; {saved}")

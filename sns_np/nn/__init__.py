"""The hand-differentiated residual network and its optimisers.

ResidualMLP     the network: forward jets (value, J, D2, directional), reverse-mode gradients,
                the least-squares fit of its read-out layer

Adam, RMSProp, SGD, SOAP, Schedule    optimisers and learning-rate schedules on flat vectors
scipy_objective                 ``fun(theta) -> (loss, grad)`` for scipy.optimize.minimize
release_workspace               free the scratch memory the engine keeps between calls
"""

from ._engine import release_workspace
from .activations import sigmoid, softplus
from .mlp import ResidualMLP, n_streams
from .optim import (
                    SGD,
                    SOAP,
                    Adam,
                    Optimizer,
                    RMSProp,
                    Schedule,
                    constant,
                    cosine,
                    make_optimizer,
                    optimizer_class,
                    scipy_objective,
                    step,
)

__all__ = ["ResidualMLP", "n_streams", "softplus", "sigmoid", "Optimizer", "Adam", "RMSProp",
           "SOAP", "SGD", "Schedule", "constant", "cosine", "step", "make_optimizer",
           "optimizer_class", "scipy_objective", "release_workspace"]

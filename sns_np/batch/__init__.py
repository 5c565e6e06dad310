"""Collections of shapes on a Dask cluster: fit many meshes, then their spectra.

:func:`fit_many` fits one mesh per task and writes ``NAME.npz`` per mesh with a summary table
(``summary.csv``, ``summary.json``); :func:`spectra_many` computes the first ``k``
Laplace-Beltrami eigenvalues of many models (a meshing-independent shape descriptor,
"ShapeDNA"). Both run on ``dask.distributed``: a local cluster of processes sized to the
machine by default, or any running scheduler (``scheduler="tcp://host:port"`` or
``client=``). Both return a :class:`Table` and never need pandas.

Dask is an optional extra (``pip install "sns-np[distributed]"``): it is imported inside the
functions that use it, and a missing extra is an ``ImportError`` that names it. Nothing else
in sns_np imports this package (docs/batch.md).

Examples
--------
>>> from sns_np.batch import Table, local_layout
>>> local_layout(cores=2)                  # two processes of one thread on two cores
(2, 1)
>>> Table([{"name": "spot", "lambda_1": 2.5}]).column("lambda_1")
[2.5]
"""

from __future__ import annotations

from .cluster import connect, dashboard_address, limit_threads, local_layout
from .fit import FIT_COLUMNS, fit_many
from .spectra import spectra_many
from .table import Table

__all__ = ["fit_many", "spectra_many", "Table", "connect", "local_layout", "limit_threads",
           "dashboard_address", "FIT_COLUMNS"]

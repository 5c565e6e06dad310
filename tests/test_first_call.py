"""First call (issue 13): what a fresh process compiles before its first jet or training step.

Timings do not belong in tests (benchmarks/bench_first_call.py measures them, figures in
docs/performance.md). What decides them does: every kernel is cached on disk, and a first
``jet(order=2)`` or float32 training step compiles one specialisation of one row kernel (two
for the step), with no jitted wrappers around them (each wrapper was a second LLVM
optimisation of the same body, 0.3-0.5 s cold).
"""

import json
import subprocess
import sys

import pytest

from .conftest import NOJIT

pytestmark = pytest.mark.skipif(NOJIT, reason="about Numba compilation")

COUNT = r"""
import json
import numpy as np
from numba.core.registry import CPUDispatcher
from sns_np.geometry import tangent_frame
from sns_np.nn import ResidualMLP
from sns_np.nn import _kernels as K


def compiled():
    return {name: len(d.signatures) for name, d in vars(K).items()
            if isinstance(d, CPUDispatcher) and d.signatures}


p = np.random.default_rng(0).standard_normal((64, 3))
p /= np.linalg.norm(p, axis=1, keepdims=True)
ResidualMLP(width=64, depth=2, seed=0).jet(p, order=2)
after_jet = compiled()
net = ResidualMLP(width=64, depth=2, seed=0, dtype=np.float32)
R = tangent_frame(p).astype(np.float32)
net.value_and_grad(p.astype(np.float32), lambda y, JR, sl: (float((y ** 2).sum()), 2 * y,
                                                            0 * JR), order=1, directions=R)
print(json.dumps({"jet": after_jet, "both": compiled()}))
"""


def test_a_first_jet_and_training_step_compile_one_row_kernel_each():
    out = subprocess.run([sys.executable, "-c", COUNT], capture_output=True, text=True,
                         check=True).stdout
    counts = json.loads(out.strip().splitlines()[-1])
    assert counts["jet"] == {"_softplus_jet_rows": 1}
    # the float32 step: the forward rows kernel in float32 and its reverse
    assert counts["both"] == {"_softplus_jet_rows": 2, "_softplus_jet_back_rows": 1}


def test_every_kernel_is_cached_on_disk():
    from numba.core.caching import NullCache
    from numba.core.registry import CPUDispatcher

    from sns_np.nn import _kernels as K
    kernels = {name: d for name, d in vars(K).items() if isinstance(d, CPUDispatcher)}
    assert len(kernels) >= 8
    assert [name for name, d in kernels.items() if isinstance(d._cache, NullCache)] == []


def test_serial_entry_points_are_not_jitted_wrappers():
    from numba.core.registry import CPUDispatcher

    from sns_np.nn import _kernels as K
    for name in ("softplus_jet_serial", "softplus_jet_back_serial"):
        assert not isinstance(getattr(K, name), CPUDispatcher), name
    for name in ("_exp_parts", "_softplus_sigmoid"):
        assert getattr(K, name).targetoptions.get("inline") == "always", name

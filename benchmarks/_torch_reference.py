"""PyTorch anchors for the engine benchmark (benchmark-only; torch is never a dependency).

The same residual softplus network, built from the *same* parameters as an sns_np
``ResidualMLP``, and the fastest autograd variants we know for the two workloads:

* full Hessian of S: R^3 -> R^3 at n points: torch.func jacfwd/jacrev/hessian under vmap,
  chunked;
* one training step of the reference loss (position MSE + 1e-4 normal error): tangents along
  e_u, e_v by forward-mode AD or by create_graph Jacobians, then one backward pass.

``bench_engine.py`` runs this file as a separate process (``python _torch_reference.py
inputs.npz``), never importing torch itself: torch loads its own OpenMP runtime with an active
wait policy, and in the same process that runtime's spinning threads slow the Numba passes of
sns_np threefold (measured: full jet 0.95 s alone, 3.0 s after ``import torch``). Each library
is timed in its own process, with its own defaults, in the same run.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

# imported by main() only: bench_engine.py imports this module for write_inputs() and must not
# load torch into its own process
torch = hessian = jacfwd = jacrev = vmap = None


def _import_torch():
    global torch, hessian, jacfwd, jacrev, vmap
    import torch
    from torch.func import hessian, jacfwd, jacrev, vmap


def torch_params(net, dtype):
    """Torch tensors of the parameters; ``net`` has attributes W0, W1 (list), W2 (list), W3."""
    tdt = {np.dtype(np.float32): torch.float32, np.dtype(np.float64): torch.float64}[dtype]

    def t(a):
        return torch.tensor(np.asarray(a), dtype=tdt)

    return {"W0": t(net.W0), "W1": [t(w) for w in net.W1], "W2": [t(w) for w in net.W2],
            "W3": t(net.W3)}, tdt


def make_forward(P):
    sp = torch.nn.functional.softplus

    def f(x):
        h = sp(x @ P["W0"].T)
        for W1, W2 in zip(P["W1"], P["W2"]):
            h = sp(h + sp(h @ W1.T) @ W2.T)
        return h @ P["W3"].T

    return f


def _best(fn, repeats):
    fn()
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def full_hessian_times(net, x_np, dtype, repeats=2, chunks=(128, 256, 512)):
    """Seconds for the full Hessian at all points, per variant and chunk: name -> seconds."""
    P, tdt = torch_params(net, dtype)
    f = make_forward(P)
    x = torch.tensor(x_np, dtype=tdt)
    variants = {
        "hessian(jacfwd o jacrev)": lambda: vmap(hessian(f)),
        "jacfwd o jacfwd": lambda: vmap(jacfwd(jacfwd(f))),
        "jacfwd o jacrev": lambda: vmap(jacfwd(jacrev(f))),
    }
    out = {}
    with torch.no_grad():
        for name, make in variants.items():
            F = make()
            for c in chunks:
                # the Hessian alone (value and J cost extra in torch): a conservative anchor
                def run(F=F, c=c):
                    for s in range(0, x.shape[0], c):
                        F(x[s:s + c])
                out[f"{name}, chunk {c}"] = _best(run, repeats)
    return out


def training_step_times(net, p_np, R_np, q_np, n_np, dtype, weight=1e-4, repeats=3):
    """Seconds for one loss + gradient w.r.t. all parameters; dict name -> seconds."""
    P, tdt = torch_params(net, dtype)
    leaves = [P["W0"], *P["W1"], *P["W2"], P["W3"]]
    for w in leaves:
        w.requires_grad_(True)
    f = make_forward(P)
    p = torch.tensor(p_np, dtype=tdt)
    eu = torch.tensor(R_np[:, :, 0], dtype=tdt)
    ev = torch.tensor(R_np[:, :, 1], dtype=tdt)
    q = torch.tensor(q_np, dtype=tdt)
    nt = torch.tensor(n_np, dtype=tdt)
    N = p.shape[0]

    def loss_from(y, Su, Sv):
        c = torch.linalg.cross(Su, Sv)
        n = c / c.norm(dim=1, keepdim=True)
        return ((y - q) ** 2).sum() / N + weight * ((n - nt) ** 2).sum() / N

    def forward_ad():
        import torch.autograd.forward_ad as fwAD
        for w in leaves:
            w.grad = None
        with fwAD.dual_level():
            yu = fwAD.unpack_dual(f(fwAD.make_dual(p, eu)))
            yv = fwAD.unpack_dual(f(fwAD.make_dual(p, ev)))
            loss = loss_from(yu.primal, yu.tangent, yv.tangent)
        loss.backward()

    def forward_ad_stacked():
        import torch.autograd.forward_ad as fwAD
        for w in leaves:
            w.grad = None
        with fwAD.dual_level():
            out = fwAD.unpack_dual(f(fwAD.make_dual(torch.cat([p, p]), torch.cat([eu, ev]))))
            loss = loss_from(out.primal[:N], out.tangent[:N], out.tangent[N:])
        loss.backward()

    def create_graph():
        for w in leaves:
            w.grad = None
        x = p.clone().requires_grad_(True)
        y = f(x)
        rows = [torch.autograd.grad(y[:, i].sum(), x, create_graph=True)[0] for i in range(3)]
        J = torch.stack(rows, dim=1)
        loss = loss_from(y, torch.einsum("kia,ka->ki", J, eu), torch.einsum("kia,ka->ki", J, ev))
        loss.backward()

    out = {}
    for name, fn in [("forward-mode tangents + backward", forward_ad),
                     ("forward-mode, stacked tangents + backward", forward_ad_stacked),
                     ("create_graph Jacobian + backward", create_graph)]:
        out[name] = _best(fn, repeats)
    return out


class _Params:
    def __init__(self, data):
        depth = int(data["depth"])
        self.W0, self.W3 = data["W0"], data["W3"]
        self.W1 = [data[f"W1_{i}"] for i in range(depth)]
        self.W2 = [data[f"W2_{i}"] for i in range(depth)]


def write_inputs(path, net, x, p, R, q, nt, repeats, chunks):
    """Everything the torch process needs, in one .npz (called by bench_engine.py)."""
    arrays = {"W0": net.W0, "W3": net.W3, "depth": net.depth, "x": x, "p": p, "R": R, "q": q,
              "nt": nt, "dtype": np.dtype(net.dtype).name, "repeats": repeats,
              "chunks": np.asarray(chunks)}
    for i in range(net.depth):
        arrays[f"W1_{i}"] = net.W1[i]
        arrays[f"W2_{i}"] = net.W2[i]
    np.savez(path, **arrays)


def main(path):
    _import_torch()
    with np.load(path) as data:
        net = _Params(data)
        dt = np.dtype(str(data["dtype"]))
        repeats = int(data["repeats"])
        hess = full_hessian_times(net, data["x"], dt, repeats=max(1, repeats - 1),
                                  chunks=tuple(int(c) for c in data["chunks"]))
        train = training_step_times(net, data["p"], data["R"], data["q"], data["nt"], dt,
                                    repeats=repeats)
    print(json.dumps({"hessian": hess, "training": train, "threads": torch.get_num_threads(),
                      "version": torch.__version__}))


if __name__ == "__main__":
    main(sys.argv[1])

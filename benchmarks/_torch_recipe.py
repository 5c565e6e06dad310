"""The paper's published fitting recipe in PyTorch, for ``race_paper_recipe.py`` (benchmark
only; torch is never a dependency of sns_np).

Run by the race in its own process (``python _torch_recipe.py inputs.npz out.npz``), so that
torch's OpenMP runtime never shares a process with sns_np's Numba passes (see
``_torch_reference.py``). The recipe, as published (Williamson & Mitra 2025, section 3.1 and
the implementation details):

* the reference network: 3 -> 256, eight residual softplus blocks, 256 -> 3, no biases;
  PyTorch's default initialisation (``nn.Linear``: Kaiming-uniform, bound 1/sqrt(fan_in)) with
  the last layer set to the constant 1e-4;
* loss: mean squared position error + 1e-4 x mean squared normal error, normals from the two
  tangent derivatives along e_u, e_v (forward-mode AD, the fastest variant measured in
  ``_torch_reference.py``);
* RMSProp, learning rate 1e-4, momentum 0.9, constant;
* every step: 2,048 points uniform by area on the mesh (flat triangles, barycentric
  correspondence with the sphere) plus the next block of 1,024 mesh vertices, cycling.

The inputs (mesh, embedding, normalisation, seconds, snapshot times) come from the race; the
output holds the network's parameters at each snapshot time (training time only, the
snapshot copies excluded) and the step counts.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np


def main(inputs, output):
    import torch

    from sns_np.geometry import tangent_frame
    from sns_np.mesh import Correspondence
    from sns_np.mesh.operators import vertex_normals

    with np.load(inputs) as d:
        V, F, Vs = d["V"], d["F"], d["Vs"]
        center, scale = d["center"], float(d["scale"])
        seconds, times = float(d["seconds"]), list(d["times"])
        seed = int(d["seed"])
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    corr = Correspondence(V, F, Vs)
    Vn = (V - center) / scale
    Nv = vertex_normals(V, F)
    width, depth, block = 256, 8, 1024

    first = torch.nn.Linear(3, width, bias=False)
    blocks = [(torch.nn.Linear(width, width, bias=False), torch.nn.Linear(width, width,
                                                                          bias=False))
              for _ in range(depth)]
    last = torch.nn.Linear(width, 3, bias=False)
    with torch.no_grad():
        last.weight.fill_(1e-4)
    params = [first.weight, *[w for a, b in blocks for w in (a.weight, b.weight)], last.weight]
    sp = torch.nn.functional.softplus

    def net(x):
        h = sp(first(x))
        for a, b in blocks:
            h = sp(h + b(sp(a(h))))
        return last(h)

    opt = torch.optim.RMSprop(params, lr=1e-4, momentum=0.9)
    import torch.autograd.forward_ad as fwAD

    def batch():
        face, beta = corr.sample_barycentric(2048, rng)
        p = corr.to_sphere(face, beta)
        q, n = corr.to_mesh(face, beta)
        start = batch.next_vertex
        idx = np.arange(start, start + block) % len(V)
        batch.next_vertex = (start + block) % len(V)
        p = np.vstack([p, Vs[idx]])
        q = np.vstack([(q - center) / scale, Vn[idx]])
        n = np.vstack([n, Nv[idx]])
        R = tangent_frame(p)
        t = [torch.tensor(a, dtype=torch.float32) for a in (p, q, n, R[:, :, 0], R[:, :, 1])]
        return t

    batch.next_vertex = 0
    snaps, steps_at, clock = {}, [], 0.0
    step = 0
    pending = sorted(t for t in times if t < seconds) + [seconds]
    while pending:
        t0 = time.perf_counter()
        p, q, nt, eu, ev = batch()
        N = p.shape[0]
        opt.zero_grad(set_to_none=True)
        with fwAD.dual_level():
            out = fwAD.unpack_dual(net(fwAD.make_dual(torch.cat([p, p]), torch.cat([eu, ev]))))
            y, Su, Sv = out.primal[:N], out.tangent[:N], out.tangent[N:]
            c = torch.linalg.cross(Su, Sv)
            n = c / c.norm(dim=1, keepdim=True)
            loss = ((y - q) ** 2).sum() / N + 1e-4 * ((n - nt) ** 2).sum() / N
        loss.backward()
        opt.step()
        step += 1
        clock += time.perf_counter() - t0
        while pending and clock >= pending[0]:
            t = pending.pop(0)
            snaps[t] = [w.detach().numpy().astype(np.float64).copy() for w in params]
            steps_at.append((t, step, clock))
    arrays = {"times": np.array(sorted(snaps)), "steps": np.array([s for _, s, _ in steps_at]),
              "clock": np.array([c for _, _, c in steps_at])}
    for i, t in enumerate(sorted(snaps)):
        for j, w in enumerate(snaps[t]):
            arrays[f"s{i}_{j}"] = w
    np.savez(output, **arrays)
    print(json.dumps({"steps": step, "threads": torch.get_num_threads(),
                      "version": torch.__version__}))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])

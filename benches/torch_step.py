#!/usr/bin/env python3
"""The PyTorch side of doma's speed claims: one DOMA training step in plain PyTorch.

The protocol of `doma bench`'s `fit_step` rows (synthetic protocol, DOMA-Affinity, SIREN
4 -> 128 -> 128 -> 128 -> 12, omega 30 applied to the bias too, 750 training points, one
Adam step on one frame), with the spatial Jacobian for L_H (750 jittered points, or the
first --h-points of them; squared entries summed per point, mean over points) computed in
one of four ways:

  none      no regulariser: trajectory L1 only
  jacrev    torch.func.vmap(jacrev(...)): the path the authors' release offers
  jvp       torch.func forward mode, three jvp directions batched with vmap
  dual      the network run by hand on stacked value+tangent rows [4N, d]
            (the same maths as doma's Analytic method), reverse mode for the weights

`doma bench --compare-torch PYTHON` runs this script with PYTHON, alternating with doma's
own rows, and prints both sides in one table. Alone:

  python3 benches/torch_step.py [--threads 2] [--steps 200] [--warmup 20] [--modes none,dual]

Prints one JSON object per mode on stdout (median, min and max ms per step after warm-up).
Needs torch >= 2.0, installed outside the repository, e.g.
  python3 -m venv ~/.venv-torch && ~/.venv-torch/bin/pip install torch
"""
import argparse, json, statistics, sys, time

import torch
from torch import nn
from torch.func import functional_call, jacrev, jvp, vmap

OMEGA = 30.0


class Siren(nn.Module):
    """sin(omega (x W + b)) layers and a linear output layer, the authors' initialiser."""

    def __init__(self, d_in=4, hidden=128, n_hidden=2, d_out=12):
        super().__init__()
        dims = [d_in] + [hidden] * (n_hidden + 1)
        self.sine = nn.ModuleList(nn.Linear(a, b) for a, b in zip(dims[:-1], dims[1:]))
        self.out = nn.Linear(hidden, d_out)
        with torch.no_grad():
            self.sine[0].weight.uniform_(-1 / d_in, 1 / d_in)
            bound = (6 / hidden) ** 0.5 / OMEGA
            for layer in list(self.sine[1:]) + [self.out]:
                layer.weight.uniform_(-bound, bound)

    def forward(self, xt):
        h = xt
        for layer in self.sine:
            h = torch.sin(OMEGA * layer(h))
        return self.out(h)

    def forward_dual(self, xt):
        """Values and d/dx, d/dy, d/dz stacked as rows [4N, .] (time has no tangent)."""
        n = xt.shape[0]
        seed = torch.zeros(3, n, 4, dtype=xt.dtype)
        for k in range(3):
            seed[k, :, k] = 1
        s = torch.cat([xt, seed.reshape(3 * n, 4)], 0)
        for layer in self.sine:
            z = s @ layer.weight.T
            v = OMEGA * (z[:n] + layer.bias)
            tangent = (OMEGA * z[n:]).view(3, n, -1).mul(torch.cos(v)).reshape(3 * n, -1)
            s = torch.cat([torch.sin(v), tangent], 0)
        z = s @ self.out.weight.T
        return z[:n] + self.out.bias, z[n:].view(3, n, -1)


def warp(raw, x):
    """y = A x + u, A the first 9 outputs row-major (with I, so that y starts near x)."""
    a = raw[:, :9].reshape(-1, 3, 3) + torch.eye(3)
    return torch.einsum("nij,nj->ni", a, x) + raw[:, 9:12]


def time_mode(mode, n, h, warmup, steps):
    net = Siren()
    opt = torch.optim.Adam(net.parameters(), lr=1e-4, eps=1e-8)
    params = dict(net.named_parameters())
    x0 = torch.rand(n, 3) * 2 - 1
    target = x0 @ torch.tensor([[1.0, 0.3, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    t = 0.5

    def raw_at(p_, x):
        xt = torch.cat([x, torch.full((x.shape[0], 1), t)], 1)
        return functional_call(net, p_, (xt,))

    def step():
        xt = torch.cat([x0, torch.full((n, 1), t)], 1)
        loss = (warp(net(xt), x0) - target).abs().mean()
        if mode != "none":
            xh = x0[:h] + 0.1 * torch.randn(h, 3)
            if mode == "jacrev":
                f = lambda xi: raw_at(params, xi.unsqueeze(0)).squeeze(0)
                lh = vmap(jacrev(f))(xh).pow(2).sum((1, 2)).mean()  # [n, 12, 3]
            elif mode == "jvp":
                f = lambda xx: raw_at(params, xx)
                tangents = torch.eye(3).unsqueeze(1).expand(3, h, 3)
                _, jt = vmap(lambda v: jvp(f, (xh,), (v,)))(tangents)  # [3, n, 12]
                lh = jt.pow(2).sum((0, 2)).mean()
            elif mode == "dual":
                _, jt = net.forward_dual(torch.cat([xh, torch.full((h, 1), t)], 1))
                lh = jt.pow(2).sum((0, 2)).mean()
            else:
                raise SystemExit(f"unknown mode {mode!r} (none, jacrev, jvp, dual)")
            loss = loss + 0.1 * lh
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    times = []
    for i in range(warmup + steps):
        s = time.perf_counter()
        step()
        if i >= warmup:
            times.append((time.perf_counter() - s) * 1e3)
    return times


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--steps", type=int, default=200)
    p.add_argument("--warmup", type=int, default=20)
    p.add_argument("--points", type=int, default=750)
    p.add_argument("--h-points", type=int, default=None,
                   help="L_H samples per step (default: --points; at most --points)")
    p.add_argument("--modes", default="none,jacrev,jvp,dual")
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    torch.manual_seed(0)
    for mode in a.modes.split(","):
        h = min(a.h_points or a.points, a.points)
        times = time_mode(mode, a.points, h, a.warmup, a.steps)
        row = {"impl": "pytorch", "torch": torch.__version__, "mode": mode,
               "threads": a.threads, "points": a.points, "h_points": h,
               "ms_median": statistics.median(times),
               "ms_min": min(times), "ms_max": max(times)}
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    sys.exit(main())

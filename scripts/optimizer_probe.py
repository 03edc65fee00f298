#!/usr/bin/env python3
"""Does a second-order optimiser reach `--recipe fast`'s error in fewer steps? A probe in
plain PyTorch, before any port to doma's fused step.

The synthetic benchmark's DOMA-Affinity-H fit (the data, model and loss of
scripts/torch_synthetic.py) on `--recipe fast`'s schedule: 256 of the 750 training points and
64 jittered `L_H` samples a step, one step per frame in a fresh frame order each iteration, a
5-iteration linear warm-up then a cosine decay to 0, the learning rate 1.5e-4. The optimiser
is Adam (PyTorch's, β = (0.9, 0.999), ε = 1e-8, as doma's) or SOAP (Vyas et al. 2024,
"SOAP: Improving and Stabilizing Shampoo using Adam", Algorithm 3, written here from the
paper: Adam run in the eigenbasis of Shampoo's two Kronecker factors of each weight matrix,
the basis refreshed every `--soap-every` steps by one power iteration and a QR
decomposition; biases are stepped by plain Adam; bias-corrected; no update on the first
step, which only starts the factors).

Prints one JSON line per run with the held-out EPE x1e4 every 50 iterations and at the end,
and the seconds of fitting. It measures steps to an error; the seconds are PyTorch's, not
doma's.

Usage: python3 scripts/optimizer_probe.py --motion rotation --optimizer soap [--iters 1000]
       [--lr 1.5e-4] [--betas 0.95,0.95] [--soap-every 10] [--seed 0] [--json out.jsonl]
Needs torch >= 2.0 and numpy, in a virtual environment outside the repository.
"""
import argparse, json, math, sys, time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from torch_synthetic import FRAMES, Siren, emit, held_out_epe, sequence, warp, with_time  # noqa: E402


class Soap(torch.optim.Optimizer):
    """SOAP for the 2-D parameters, Adam for the others."""

    def __init__(self, params, lr, betas=(0.95, 0.95), eps=1e-8, every=10):
        super().__init__(params, dict(lr=lr, betas=betas, eps=eps, every=every))

    @staticmethod
    def _rotate(x, qs, back=False):
        ql, qr = qs
        return ql @ x @ qr.T if back else ql.T @ x @ qr

    @torch.no_grad()
    def step(self):
        for group in self.param_groups:
            b1, b2 = group["betas"]
            for p in group["params"]:
                g = p.grad
                if g is None:
                    continue
                st = self.state[p]
                matrix = g.dim() == 2
                if not st:
                    st["step"] = 0
                    st["m"] = torch.zeros_like(g)
                    st["v"] = torch.zeros_like(g)
                    if matrix:
                        st["gg"] = [g @ g.T, g.T @ g]
                        st["q"] = [torch.linalg.eigh(f)[1].flip(1) for f in st["gg"]]
                        # The first step only starts the factors.
                        continue
                st["step"] += 1
                t = st["step"]
                gr = self._rotate(g, st["q"]) if matrix else g
                st["m"].mul_(b1).add_(g, alpha=1 - b1)
                st["v"].mul_(b2).add_(gr * gr, alpha=1 - b2)
                mr = self._rotate(st["m"], st["q"]) if matrix else st["m"]
                n = mr / (st["v"].sqrt() + group["eps"])
                if matrix:
                    n = self._rotate(n, st["q"], back=True)
                size = group["lr"] * math.sqrt(1 - b2**t) / (1 - b1**t)
                p.add_(n, alpha=-size)
                if matrix:
                    gg = st["gg"]
                    gg[0].mul_(b2).add_(g @ g.T, alpha=1 - b2)
                    gg[1].mul_(b2).add_(g.T @ g, alpha=1 - b2)
                    if t % group["every"] == 0:
                        self._refresh(st)

    @staticmethod
    def _refresh(st):
        """One power iteration and a QR per factor, the basis sorted by the estimated
        eigenvalues (descending) and the second moment permuted with it."""
        qs = []
        v = st["v"]
        for dim, (f, q) in enumerate(zip(st["gg"], st["q"])):
            est = torch.diag(q.T @ f @ q)
            order = torch.argsort(est, descending=True)
            q = q[:, order]
            v = v.index_select(dim, order)
            q, _ = torch.linalg.qr(f @ q)
            qs.append(q)
        st["q"], st["v"] = qs, v


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--motion", default="rotation")
    p.add_argument("--optimizer", choices=["adam", "soap"], default="adam")
    p.add_argument("--iters", type=int, default=1000)
    p.add_argument("--lr", type=float, default=1.5e-4)
    p.add_argument("--betas", default=None, help="b1,b2 (Adam: 0.9,0.999; SOAP: 0.95,0.95)")
    p.add_argument("--soap-every", type=int, default=10)
    p.add_argument("--points", type=int, default=256)
    p.add_argument("--samples", type=int, default=64)
    p.add_argument("--h-weight", type=float, default=0.1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--json")
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    torch.manual_seed(a.seed)
    seq = torch.from_numpy(sequence(a.motion))
    train, test = seq[:, :750], seq[:, 750:]
    canon = train[0]
    n = canon.shape[0]
    ts = torch.linspace(-1, 1, FRAMES)
    net = Siren()
    if a.optimizer == "adam":
        betas = tuple(map(float, (a.betas or "0.9,0.999").split(",")))
        opt = torch.optim.Adam(net.parameters(), lr=a.lr, betas=betas, eps=1e-8)
    else:
        betas = tuple(map(float, (a.betas or "0.95,0.95").split(",")))
        opt = Soap(net.parameters(), lr=a.lr, betas=betas, every=a.soap_every)
    warm = 5

    def factor(e):
        if e < warm:
            return (e + 1) / warm
        return 0.5 * (1 + math.cos(math.pi * (e - warm) / max(1, a.iters - warm)))

    def xt_of(x, k):
        return with_time(x, ts[k])

    def epe():
        return held_out_epe(net, test, ts)

    curve = []
    seconds = 0.0
    for it in range(a.iters):
        start = time.perf_counter()
        for group in opt.param_groups:
            group["lr"] = a.lr * factor(it)
        for k in torch.randperm(FRAMES).tolist():
            rows = torch.randperm(n)[: a.points]
            x = canon[rows]
            loss = (warp(net(xt_of(x, k)), x) - train[k][rows]).abs().mean()
            if a.h_weight > 0:
                pts = canon[torch.randperm(n)[: a.samples]]
                pts = pts + 0.1 * torch.randn_like(pts)
                loss = loss + a.h_weight * net.jacobian(xt_of(pts, k)).pow(2).sum((1, 2)).mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
        seconds += time.perf_counter() - start
        if (it + 1) % 50 == 0 or it + 1 == a.iters:
            curve.append([it + 1, round(epe(), 4), round(seconds, 2)])
            print(f"{a.optimizer} {a.motion} iteration {it + 1}: EPE x1e-4 {curve[-1][1]:.2f}",
                  file=sys.stderr, flush=True)
    row = {"motion": a.motion, "optimizer": a.optimizer, "iters": a.iters, "lr": a.lr,
           "betas": betas, "soap_every": a.soap_every, "points": a.points,
           "samples": a.samples, "seed": a.seed, "epe_x1e4": curve[-1][1],
           "seconds": round(seconds, 2), "curve": curve, "torch": torch.__version__}
    emit(row, a.json)


if __name__ == "__main__":
    sys.exit(main())

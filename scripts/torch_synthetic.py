#!/usr/bin/env python3
"""The synthetic benchmark's DOMA-Affinity fit in plain PyTorch, written from
docs/reference.md (not the authors' code), to cross-check doma's fits.

Data: numpy's legacy generator, seed(0), rand(3000, 3) * 2 - 1 (the points doma's
`synthetic` job draws), 20 frames of one motion, the first 750 points train, the rest test.
Model: SIREN 4 -> 128 -> 128 -> 128 -> 12, omega 30 on weights and bias, the authors'
initialisation (first layer U(+-1/4), later layers U(+-sqrt(6/128)/30), biases PyTorch's
default), A = the first 9 outputs row-major with no identity added, u = the last 3.
Fit: Adam lr 1e-4; one iteration = every frame once in a fresh random order, one step per
frame on all training points; loss = mean |y - x_k| + w_H * L_H, L_H = mean over the
training points (in a fresh order) jittered by 0.1 N(0, 1) of the summed squares of the
[12, 3] Jacobian of the raw outputs, with exact (create-graph) gradients; the learning rate
factor 1 - max(0, e - 10) / (iters - 9) in iteration e. EPE x1e4 on the test points over
every frame, frame 0 included.

Usage: python3 scripts/torch_synthetic.py --motion shearing [--seed 0] [--iters 1000]
       [--h-weight 0.1] [--threads 2] [--json out.jsonl]
       [--dump STEPS.npz [--dump-steps 50] [--dump-every 500]]

With --dump, it takes the first --dump-steps steps (at most the whole fit) and writes what a
step-by-step comparison needs to an .npz: the data, the initial weights, each step's frame,
learning rate and L_H points, its losses, the first step's gradient, and the weights and
held-out EPE after each of the first 50 steps and every --dump-every-th step after them
(`cargo run --release --example torch_cross_check -- STEPS.npz` replays them in doma).
Needs torch >= 2.0 and numpy, in a virtual environment outside the repository.
"""
import argparse, json, math, sys, time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benches"))
from torch_step import OMEGA, Siren as StepSiren  # noqa: E402

FRAMES = 20


def sequence(motion):
    np.random.seed(0)
    pts = np.random.rand(3000, 3) * 2 - 1
    frames = []
    for t in range(FRAMES):
        if motion == "rotation":
            a = t * math.pi / FRAMES
            r = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
            frames.append(pts @ r.T)
        elif motion == "translation":
            frames.append(pts + np.linspace(-1, 1, FRAMES)[t])
        elif motion == "scaling":
            frames.append(pts * np.linspace(0.5, 1.5, FRAMES)[t])
        elif motion == "shearing":
            m = np.eye(3)
            m[0, 2] = np.linspace(0, 1.5, FRAMES)[t]
            frames.append(pts @ m.T)
        else:
            raise SystemExit(f"unknown motion {motion}")
    return np.stack(frames).astype(np.float32)  # [T, N, 3]


class Siren(StepSiren):
    """The SIREN of benches/torch_step.py (the same layers, initialisation and draws), with
    the Jacobian that L_H needs."""

    def jacobian(self, xt):
        """d raw / d x, [N, 12, 3], by forward mode (exact, differentiable)."""
        n = xt.shape[0]
        h, tan = xt, torch.eye(4)[:3].expand(n, 3, 4)  # tangents [N, 3, d]
        for layer in self.sine:
            z = OMEGA * layer(h)
            tan = OMEGA * (tan @ layer.weight.T) * torch.cos(z).unsqueeze(1)
            h = torch.sin(z)
        return (tan @ self.out.weight.T).transpose(1, 2)


def warp(raw, x):
    a = raw[:, :9].reshape(-1, 3, 3)
    return torch.einsum("nij,nj->ni", a, x) + raw[:, 9:12]


def with_time(x, t):
    """[x, y, z, t] rows from [x, y, z] rows at time t."""
    return torch.cat([x, t.expand(x.shape[0], 1)], 1)


def held_out_epe(net, test, ts):
    """EPE x1e4 on the test points over every frame, frame 0 included."""
    with torch.no_grad():
        err = [(warp(net(with_time(test[0], ts[k])), test[0]) - test[k]).abs().sum(1).mean()
               for k in range(FRAMES)]
        return float(torch.stack(err).mean()) * 1e4


def emit(row, path=None):
    """Prints `row` as one JSON line, and appends it to `path` when given."""
    print(json.dumps(row), flush=True)
    if path:
        with open(path, "a") as fh:
            fh.write(json.dumps(row) + "\n")


def write_dump(path, d):
    """The step-by-step record, float32 arrays (frames too) that doma's reader takes."""
    f32 = lambda v: np.asarray(v, dtype=np.float32)
    np.savez(path, canon=f32(d["canon"]), train=f32(d["train"]), test=f32(d["test"]),
             init=f32(d["init"]), grad=f32(d["grad"]), frames=f32(d["frames"]), lrs=f32(d["lrs"]),
             points=f32(torch.stack(d["points"])), l1=f32(d["l1"]), total=f32(d["total"]),
             after=f32(torch.stack(d["after"])), after_steps=f32(d["after_steps"]),
             epe=np.asarray(d["epe"], dtype=np.float64))
    print(f"wrote {len(d['frames'])} steps to {path}")


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--motion", default="shearing")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--iters", type=int, default=1000)
    p.add_argument("--h-weight", type=float, default=0.1)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--json")
    p.add_argument("--dump")
    p.add_argument("--dump-steps", type=int, default=50)
    p.add_argument("--dump-every", type=int, default=500)
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    torch.manual_seed(a.seed)
    seq = torch.from_numpy(sequence(a.motion))
    train, test = seq[:, :750], seq[:, 750:]
    canon = train[0]
    ts = torch.linspace(-1, 1, FRAMES)
    net = Siren()
    opt = torch.optim.Adam(net.parameters(), lr=1e-4)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda e: 1 - max(0, e - 10) / float(a.iters - 9))
    n = canon.shape[0]

    def xt_of(x, k):
        return with_time(x, ts[k])

    def epe():
        return held_out_epe(net, test, ts)

    def flat():
        return torch.cat([p.detach().reshape(-1) for p in params]).clone()

    params = [t for layer in list(net.sine) + [net.out] for t in (layer.weight, layer.bias)]
    dump = {"canon": canon, "train": train, "test": test, "init": flat(), "frames": [], "lrs": [],
            "points": [], "l1": [], "total": [], "after": [], "after_steps": [], "epe": []}
    start = time.perf_counter()
    for it in range(a.iters):
        for k in torch.randperm(FRAMES).tolist():
            lr = opt.param_groups[0]["lr"]
            l1 = (warp(net(xt_of(canon, k)), canon) - train[k]).abs().mean()
            loss = l1
            if a.h_weight > 0:
                pts = canon[torch.randperm(n)[:min(1024, n)]]
                pts = pts + 0.1 * torch.randn_like(pts)
                loss = loss + a.h_weight * net.jacobian(xt_of(pts, k)).pow(2).sum((1, 2)).mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            if a.dump:
                if not dump["frames"]:
                    dump["grad"] = torch.cat([p.grad.reshape(-1) for p in params]).clone()
                dump["frames"].append(k)
                dump["lrs"].append(lr)
                dump["points"].append(pts.detach().clone() if a.h_weight > 0 else canon)
                dump["l1"].append(float(l1.detach()))
                dump["total"].append(float(loss.detach()))
            opt.step()
            if a.dump:
                done = len(dump["frames"])
                if done <= 50 or done % a.dump_every == 0 or done == a.dump_steps:
                    dump["after"].append(flat())
                    dump["after_steps"].append(done)
                    dump["epe"].append(epe())
                if done == a.dump_steps:
                    write_dump(a.dump, dump)
                    return 0
        sched.step()
        if (it + 1) % 100 == 0:
            print(f"iteration {it + 1}: EPE x1e-4 {epe():.2f}", flush=True)
    row = {"motion": a.motion, "seed": a.seed, "iters": a.iters, "h_weight": a.h_weight,
           "epe_x1e4": epe(), "seconds": time.perf_counter() - start, "torch": torch.__version__}
    emit(row, a.json)


if __name__ == "__main__":
    sys.exit(main())

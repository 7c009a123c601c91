#!/usr/bin/env python3
"""Peer benchmark for `cargo bench -p equiarm_sac --bench update`: one SAC update (critic step,
actor step, alpha step, Polyak target) in PyTorch on the authors' networks (e2cnn's R2Conv for
Equivariant SAC, group D4; plain convolutions for CNN SAC), the same shapes and the same work as
equiarm's `Agent::update`:

- critic target without gradients: the actor on the next observations, the target critic;
- critic step: both Q heads on (obs, action), MSE to the target, backward, Adam;
- actor step: the actor on obs, the updated critic with its weights frozen (gradients reach the
  action only), expert L2 on the sampled action of expert rows, backward, Adam;
- alpha: one scalar Adam step; target: Polyak averaging with tau 0.01.

Also the batch-1 greedy action (the actor in eval mode, where e2cnn caches its expanded filters).

Run with any python3: it re-executes itself in the venv of e2cnn_peer.py (torch + e2cnn from PyPI,
created on first use). Prints one JSON object: {"model", "config", "threads", "update_s",
"act_b1_s", "updates", "acts", "peak_rss_mb"}.

Usage: sac_update_peer.py --model equi|cnn --config reduced16|paper [--threads 1] [--reps 5] [--device cpu|cuda]

On `--device cuda` the networks, batch and Adam state live on the GPU and each timing waits for it
(torch.cuda.synchronize); bench/gpu_check.sh runs it so beside equiarm's GPU build.
"""
import argparse
import json
import math
import os
import resource
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import e2cnn_peer  # noqa: E402  (its venv and the actors' layer lists)

# (hidden, input px, batch), as equiarm's TrainConfig presets.
CONFIGS = {"reduced16": (16, 32, 64), "paper": (64, 128, 128)}


def equi_encoder(hidden, size, g, enn, in_ch=5):
    t_in = enn.FieldType(g, in_ch * [g.trivial_repr])
    first, layers = t_in, []
    n = hidden
    for f, pad, pool in e2cnn_peer.kept_layers([n // 8, n // 4, n // 2, n, 2 * n, n, n], size):
        t_out = enn.FieldType(g, f * [g.regular_repr])
        layers += [enn.R2Conv(t_in, t_out, kernel_size=3, padding=pad), enn.ReLU(t_out, inplace=True)]
        if pool:
            layers.append(enn.PointwiseMaxPool(t_out, 2))
        t_in = t_out
    return first, t_in, layers


def build_equi(hidden, size):
    import torch
    from e2cnn import gspaces, nn as enn
    g = gspaces.FlipRot2dOnR2(N=4)

    class Actor(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.t_in, t_enc, layers = equi_encoder(hidden, size, g, enn)
            out = enn.FieldType(g, [g.irrep(1, 1), g.quotient_repr((None, 4))] + 7 * [g.trivial_repr])
            self.net = enn.SequentialModule(*layers, enn.R2Conv(t_enc, out, kernel_size=1, padding=0))

        def forward(self, obs):
            raw = self.net(enn.GeometricTensor(obs, self.t_in)).tensor.reshape(obs.shape[0], -1)
            dxy, inv = raw[:, 0:2], raw[:, 4:6]
            dtheta = raw[:, 2:3] - raw[:, 3:4]
            mean = torch.cat([inv[:, 0:1], dxy, inv[:, 1:2], dtheta], 1)
            return mean, raw[:, 6:11].clamp(-20, 2)

    class Critic(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.t_in, t_enc, layers = equi_encoder(hidden, size, g, enn)
            self.enc = enn.SequentialModule(*layers)
            self.t_act = enn.FieldType(g, 2 * [g.trivial_repr] + [g.irrep(1, 1), g.quotient_repr((None, 4))])
            self.t_cat = t_enc + self.t_act
            reg = enn.FieldType(g, hidden * [g.regular_repr])
            triv = enn.FieldType(g, hidden * [g.trivial_repr])

            def head():
                return enn.SequentialModule(
                    enn.R2Conv(self.t_cat, reg, kernel_size=1), enn.ReLU(reg, inplace=True),
                    enn.GroupPooling(reg), enn.R2Conv(triv, enn.FieldType(g, [g.trivial_repr]), kernel_size=1))
            self.q1, self.q2 = head(), head()

        def forward(self, obs, act):
            h = self.enc(enn.GeometricTensor(obs, self.t_in)).tensor
            b = obs.shape[0]
            p, dx, dy, dz, dth = (act[:, i:i + 1] for i in range(5))
            lifted = torch.cat([p, dz, dx, dy, dth, -dth], 1).reshape(b, 6, 1, 1)
            x = enn.GeometricTensor(torch.cat([h, lifted], 1), self.t_cat)
            return self.q1(x).tensor.reshape(b, 1), self.q2(x).tensor.reshape(b, 1)

    return Actor(), Critic(), Critic()


def build_cnn(hidden, size):
    import torch
    import torch.nn as nn
    n = hidden
    widths = [n // 4, n // 2, n, 2 * n, 2 * n, 4 * n, 4 * n]

    def encoder():
        layers, c = [], 5
        for w, pad, pool in e2cnn_peer.kept_layers(widths, size):
            layers += [nn.Conv2d(c, w, 3, padding=pad), nn.ReLU(inplace=True)]
            if pool:
                layers.append(nn.MaxPool2d(2))
            c = w
        return nn.Sequential(*layers), c

    class Actor(nn.Module):
        def __init__(self):
            super().__init__()
            self.enc, c = encoder()
            self.head = nn.Conv2d(c, 10, 1)

        def forward(self, obs):
            y = self.head(self.enc(obs)).reshape(obs.shape[0], 10)
            return y[:, :5], y[:, 5:].clamp(-20, 2)

    class Critic(nn.Module):
        def __init__(self):
            super().__init__()
            self.enc, c = encoder()
            self.q1 = nn.Sequential(nn.Conv2d(c + 5, c, 1), nn.ReLU(inplace=True), nn.Conv2d(c, 1, 1))
            self.q2 = nn.Sequential(nn.Conv2d(c + 5, c, 1), nn.ReLU(inplace=True), nn.Conv2d(c, 1, 1))

        def forward(self, obs, act):
            b = obs.shape[0]
            x = torch.cat([self.enc(obs), act.reshape(b, 5, 1, 1)], 1)
            return self.q1(x).reshape(b, 1), self.q2(x).reshape(b, 1)

    return Actor(), Critic(), Critic()


def sample(mean, log_std, eps):
    import torch
    std = log_std.exp()
    x = mean + std * eps
    a = torch.tanh(x)
    log_n = -0.5 * eps.pow(2) - log_std - 0.5 * math.log(2 * math.pi)
    logp = (log_n - torch.log(1 - a.pow(2) + 1e-6)).sum(1, keepdim=True)
    return a, logp


def main():
    e2cnn_peer.ensure_venv()
    import torch
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", choices=["equi", "cnn"], required=True)
    ap.add_argument("--config", choices=list(CONFIGS), required=True)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--device", default="cpu")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    torch.manual_seed(0)
    hidden, size, batch = CONFIGS[a.config]
    dev = torch.device(a.device)
    sync = torch.cuda.synchronize if dev.type == "cuda" else (lambda: None)
    actor, critic, target = (m.to(dev) for m in (build_equi if a.model == "equi" else build_cnn)(hidden, size))
    target.load_state_dict(critic.state_dict())
    for p in target.parameters():
        p.requires_grad_(False)
    actor_opt = torch.optim.Adam(actor.parameters(), lr=1e-3)
    critic_opt = torch.optim.Adam(critic.parameters(), lr=1e-3)
    log_alpha = torch.tensor(math.log(1e-2), device=dev, requires_grad=True)
    alpha_opt = torch.optim.Adam([log_alpha], lr=1e-3)
    obs = torch.randn(batch, 5, size, size, device=dev)
    next_obs = torch.randn(batch, 5, size, size, device=dev)
    action = torch.tanh(torch.randn(batch, 5, device=dev))
    reward = (torch.arange(batch, device=dev) % 7 == 0).float().reshape(batch, 1)
    mask = 1 - reward
    expert = (torch.arange(batch, device=dev) % 3 == 0).float().reshape(batch, 1)
    gamma, tau, target_entropy = 0.99, 0.01, -5.0

    def update():
        alpha = log_alpha.exp().item()
        with torch.no_grad():
            mn, ls = actor(next_obs)
            a_next, logp_next = sample(mn, ls, torch.randn(batch, 5, device=dev))
            q1t, q2t = target(next_obs, a_next)
            y = reward + mask * gamma * (torch.min(q1t, q2t) - alpha * logp_next)
        q1, q2 = critic(obs, action)
        critic_loss = (q1 - y).pow(2).mean() + (q2 - y).pow(2).mean()
        critic_opt.zero_grad()
        critic_loss.backward()
        critic_opt.step()
        for p in critic.parameters():
            p.requires_grad_(False)
        mean, log_std = actor(obs)
        a_pi, logp = sample(mean, log_std, torch.randn(batch, 5, device=dev))
        q1a, q2a = critic(obs, a_pi)
        actor_loss = (alpha * logp - torch.min(q1a, q2a)).mean()
        actor_loss = actor_loss + ((a_pi - action).pow(2) * expert).sum() / (expert.sum() * 5)
        actor_opt.zero_grad()
        actor_loss.backward()
        actor_opt.step()
        for p in critic.parameters():
            p.requires_grad_(True)
        alpha_loss = -(log_alpha * (logp.detach() + target_entropy)).mean()
        alpha_opt.zero_grad()
        alpha_loss.backward()
        alpha_opt.step()
        with torch.no_grad():
            for pt, p in zip(target.parameters(), critic.parameters()):
                pt.mul_(1 - tau).add_(p, alpha=tau)
        return critic_loss.item()

    update()  # warm-up
    if dev.type == "cuda":
        update()  # the first CUDA steps also pick their kernels (cuDNN)
    sync()
    times = []
    for _ in range(a.reps):
        t0 = time.perf_counter()
        update()
        sync()
        times.append(time.perf_counter() - t0)
    actor.eval()
    one = obs[:1]
    acts = []
    with torch.no_grad():
        actor(one)  # warm-up (e2cnn expands and caches its filters in eval mode)
        for _ in range(max(5, 5 * a.reps)):
            t0 = time.perf_counter()
            torch.tanh(actor(one)[0])
            sync()
            acts.append(time.perf_counter() - t0)
    times.sort()
    acts.sort()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(json.dumps({"model": a.model, "config": a.config, "threads": a.threads, "device": a.device,
                      "update_s": times[len(times) // 2], "act_b1_s": acts[len(acts) // 2],
                      "updates": len(times), "acts": len(acts), "peak_rss_mb": rss}), flush=True)


if __name__ == "__main__":
    main()

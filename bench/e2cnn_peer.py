#!/usr/bin/env python3
"""Peer benchmark for crates/nn: the Equi SAC actor (PyTorch + e2cnn, the authors' stack) and the
CNN SAC actor (plain PyTorch), same shapes as equiarm_nn's nets (docs/paper.md §1.4, §1.8).

Run with any python3: on first use it creates a venv under ~/.cache/equiarm/venvs, installs torch and e2cnn
from PyPI into it, and re-executes itself there. Prints one JSON object per line:
{"net", "config", "mode", "median_s", "runs"}. Called by `cargo bench -p equiarm_nn --bench actors`,
which interleaves these figures with its own and prints ratios.

Usage: e2cnn_peer.py --net equi|cnn --config paper|reduced --mode fwd_b1|fwd_b128|train_b128
                     [--threads 2] [--reps 3]
"""
import argparse
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
# Outside the clone (torch from PyPI is several GB); EQUIARM_VENV_DIR moves it.
VENV = os.path.join(os.environ.get("EQUIARM_VENV_DIR", os.path.expanduser("~/.cache/equiarm/venvs")), "e2cnn-peer")
VPY = os.path.join(VENV, "bin", "python")


def ensure_venv():
    patch_e2cnn()  # before the first import of e2cnn
    try:
        import torch  # noqa: F401
        import e2cnn  # noqa: F401
        return
    except ImportError:
        pass
    if os.path.abspath(sys.executable) == os.path.abspath(VPY):
        sys.exit(f"{VENV} exists but lacks torch or e2cnn; delete it and retry")
    if not os.path.exists(VPY):
        subprocess.check_call([sys.executable, "-m", "venv", VENV])
        pip = [VPY, "-m", "pip", "install", "--quiet"]
        subprocess.check_call(pip + ["torch"])
        # e2cnn 0.2.3 calls ndarray.tostring(), removed in numpy 2.
        subprocess.check_call(pip + ["e2cnn", "scipy", "numpy<2"])
    os.execv(VPY, [VPY] + sys.argv)


def patch_e2cnn():
    """e2cnn 0.2.3 indexes with uint8 masks, which torch >= 2 rejects ("masked_fill_ only
    supports boolean masks"). Patch the venv's copy to use bool masks (same semantics)."""
    import importlib.util
    spec = importlib.util.find_spec("e2cnn")
    if spec is None:
        return
    f = os.path.join(os.path.dirname(spec.origin), "nn", "modules", "r2_conv", "basisexpansion_singleblock.py")
    src = open(f).read()
    fixed = src.replace("mask = mask.astype(np.uint8)", "mask = mask.astype(bool)").replace(
        "full_mask[mask] = norms.to(torch.uint8)", "full_mask[mask] = norms")
    if fixed != src:
        open(f, "w").write(fixed)
    # It also calls ndarray.tostring(), which numpy 2 removed (tobytes() is the same); the GPU
    # machine's numpy is 2.x.
    for root, _, files in os.walk(os.path.dirname(spec.origin)):
        for name in files:
            if name.endswith(".py"):
                path = os.path.join(root, name)
                src = open(path).read()
                if ".tostring()" in src:
                    open(path, "w").write(src.replace(".tostring()", ".tobytes()"))


CONFIGS = {"paper": (64, 128), "reduced": (16, 64)}  # (hidden, input size), as NetConfig


def kept_layers(widths, size):
    """The paper's 128 px layers as (width, pad, pool after), minus the first 4 - p of them at
    8 * 2^p px (the authors' EquivariantEncoder64 rule, as equiarm's NetConfig)."""
    p = {8: 0, 16: 1, 32: 2, 64: 3, 128: 4}[size]
    layers = list(zip(widths, [1, 1, 1, 1, 1, 0, 0], [True, True, True, True, False, True, False]))
    return layers[4 - p:]


def equi_actor(hidden, size, in_ch=5):
    from e2cnn import gspaces, nn as enn
    g = gspaces.FlipRot2dOnR2(N=4)
    n = hidden
    t_in = enn.FieldType(g, in_ch * [g.trivial_repr])
    input_type = t_in
    layers = []
    for f, pad, pool in kept_layers([n // 8, n // 4, n // 2, n, 2 * n, n, n], size):
        t_out = enn.FieldType(g, f * [g.regular_repr])
        layers += [enn.R2Conv(t_in, t_out, kernel_size=3, padding=pad), enn.ReLU(t_out, inplace=True)]
        if pool:
            layers.append(enn.PointwiseMaxPool(t_out, 2))
        t_in = t_out
    out = enn.FieldType(g, [g.irrep(1, 1), g.quotient_repr((None, 4))] + 7 * [g.trivial_repr])
    layers.append(enn.R2Conv(t_in, out, kernel_size=1, padding=0))
    net = enn.SequentialModule(*layers)

    def fwd(x):
        return net(enn.GeometricTensor(x, input_type)).tensor.reshape(x.shape[0], -1)

    return net, fwd


def cnn_actor(hidden, size, in_ch=5):
    import torch.nn as nn
    n = hidden
    widths = [n // 4, n // 2, n, 2 * n, 2 * n, 4 * n, 4 * n]
    layers, c = [], in_ch
    for w, pad, pool in kept_layers(widths, size):
        layers += [nn.Conv2d(c, w, 3, padding=pad), nn.ReLU(inplace=True)]
        if pool:
            layers.append(nn.MaxPool2d(2))
        c = w
    layers.append(nn.Conv2d(c, 10, 1))
    net = nn.Sequential(*layers)
    return net, lambda x: net(x).reshape(x.shape[0], -1)


def main():
    ensure_venv()
    import torch
    ap = argparse.ArgumentParser()
    ap.add_argument("--net", choices=["equi", "cnn"], required=True)
    ap.add_argument("--config", choices=list(CONFIGS), required=True)
    ap.add_argument("--mode", choices=["fwd_b1", "fwd_b128", "train_b128"], required=True)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--reps", type=int, default=3)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    torch.manual_seed(0)
    hidden, size = CONFIGS[a.config]
    net, fwd = (equi_actor if a.net == "equi" else cnn_actor)(hidden, size)
    batch = 1 if a.mode == "fwd_b1" else 128
    x = torch.randn(batch, 5, size, size)
    if a.mode == "train_b128":
        net.train()
        opt = torch.optim.Adam(net.parameters(), lr=1e-4)
        target = torch.randn(batch, 10 if a.net == "cnn" else 11)

        def step():
            opt.zero_grad()
            loss = ((fwd(x) - target) ** 2).mean()
            loss.backward()
            opt.step()
    else:
        net.eval()  # e2cnn caches the expanded filters in eval mode

        def step():
            with torch.no_grad():
                fwd(x)
    step()  # warm-up
    times = []
    for _ in range(a.reps):
        t0 = time.perf_counter()
        step()
        times.append(time.perf_counter() - t0)
    times.sort()
    print(json.dumps({"net": a.net, "config": a.config, "mode": a.mode,
                      "median_s": times[len(times) // 2], "runs": len(times)}), flush=True)


if __name__ == "__main__":
    main()

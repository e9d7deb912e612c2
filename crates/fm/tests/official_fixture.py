"""Writes fixtures/official-tiny: a tiny checkpoint in the layout of the
official Matérn-FM code (a PyTorch Lightning checkpoint of its Matern_FM
module: base_model.* parameters plus Lightning's own entries), its YAML
configuration, the template mesh, and the network's output on two inputs
computed here in float64 by a forward pass written from reading the
official PoissonNet (models/poissonnet/PoissonNet.py, common.py): the
oracle the import test compares mfm's network against.

The mesh, parameter and forward-pass functions are importable (the
arbitrary-source fixture, crates/arbitrary/tests/official_arbitrary_fixture.py,
builds on them); running the file writes the single-source fixture.

Usage: python official_fixture.py OUT_DIR
"""

import collections
import math
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

WIDTH, BLOCKS, NLAYERS = 8, 2, 2


def octahedron_subdivided():
    """An octahedron, each face split in four, projected to the unit sphere
    then squashed (an ellipsoid): 18 vertices, 32 faces."""
    v = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
    f = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    v = [np.array(p, dtype=float) for p in v]
    mid = {}

    def midpoint(a, b):
        key = (min(a, b), max(a, b))
        if key not in mid:
            p = v[a] + v[b]
            v.append(p / np.linalg.norm(p))
            mid[key] = len(v) - 1
        return mid[key]

    out = []
    for a, b, c in f:
        ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
        out += [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
    verts = np.array(v) * np.array([0.5, 0.4, 0.3]) + np.array([0.05, -0.02, 0.01])
    return verts, np.array(out, dtype=np.int64)


class Mesh:
    """The operators of a triangle mesh as the official network uses them:
    interleaved intrinsic gradient G [2F, V] (any orthonormal frame per
    face: the network's vertex output does not depend on it), interleaved
    areas M [2F], lumped vertex masses [V], Laplacian L = G^T M G + 1e-6 I,
    and the faces."""

    def __init__(self, V, Fc):
        G = np.zeros((2 * len(Fc), len(V)))
        areas = np.zeros(len(Fc))
        mass = np.zeros(len(V))
        for f, (i, j, k) in enumerate(Fc):
            p = V[[i, j, k]]
            n = np.cross(p[1] - p[0], p[2] - p[0])
            area = np.linalg.norm(n) / 2
            n /= np.linalg.norm(n)
            e1 = (p[1] - p[0]) / np.linalg.norm(p[1] - p[0])
            e2 = np.cross(n, e1)
            for a, vi in enumerate((i, j, k)):
                opp = p[(a + 2) % 3] - p[(a + 1) % 3]
                grad = np.cross(n, opp) / (2 * area)
                G[2 * f, vi] += grad @ e1
                G[2 * f + 1, vi] += grad @ e2
            areas[f] = area
            mass[[i, j, k]] += area / 3
        M = np.repeat(areas, 2)
        L = G.T @ (M[:, None] * G) + 1e-6 * np.eye(len(V))
        self.G, self.M, self.mass, self.L = (torch.tensor(x) for x in (G, M, mass, L))
        self.faces = torch.tensor(Fc)
        self.nV = len(V)

    def face_mean(self, x):  # vertices_to_faces: (B, V, C) -> (B, F, C)
        return x[:, self.faces, :].mean(dim=2)

    def poisson(self, grads):
        rhs = self.G.T @ (self.M[:, None] * grads)  # (B, V, C) by broadcasting the matmul
        u = torch.linalg.solve(self.L, rhs)
        return u - (u * self.mass[None, :, None]).sum(1, keepdim=True) / self.mass.sum()


# ---- parameters in the official layout ---------------------------------------
def randn(g, *shape, scale=1.0):
    return (torch.randn(*shape, generator=g) * scale).float()


def linear(g, name, sd, cin, cout):
    sd[name + ".weight"] = randn(g, cout, cin, scale=1 / math.sqrt(cin))
    sd[name + ".bias"] = randn(g, cout, scale=0.1)


def complex_mlp(g, prefix, sd, cin, cout, modulate, width, nlayers):
    for i in range(nlayers):
        a = cin if i == 0 else width
        b = cout if i == nlayers - 1 else width
        sd[f"{prefix}.layers.{i}.lin_real.weight"] = randn(g, b, a, scale=1 / math.sqrt(a))
        sd[f"{prefix}.layers.{i}.lin_imag.weight"] = randn(g, b, a, scale=1 / math.sqrt(a))
        if i < nlayers - 1:
            sd[f"{prefix}.layers.{i}.mag_bias"] = randn(g, b, scale=0.1)
    if modulate:
        linear(g, f"{prefix}.modulator.modulator.0", sd, cin, cin)
        linear(g, f"{prefix}.modulator.modulator.2", sd, cin, 2 * cin)


def poissonnet_params(g, *, c_in, width, blocks, nlayers, extra, head, c_out=None):
    """The official PoissonNet's parameter set, in its registration order:
    extra_feat_mlp (when `extra` > 0), proj_in, the blocks (modulated vector
    MLPs; the first vertex MLP reads [x, u] plus the conditioning's width
    when there is one), the head (`njf`: a modulated vector MLP to 3
    channels; `linear`: head.{weight,bias} to `c_out`)."""
    net = collections.OrderedDict()
    if extra > 0:
        linear(g, "extra_feat_mlp.0", net, extra, width)
        linear(g, "extra_feat_mlp.2", net, width, width)
    linear(g, "proj_in", net, c_in, width)
    mlp_in = (3 if extra > 0 else 2) * width
    for k in range(blocks):
        complex_mlp(g, f"blocks.{k}.grad_mlp", net, width, width, True, width, nlayers)
        linear(g, f"blocks.{k}.vert_mlp.mlp1.layers.0", net, mlp_in, width)
        linear(g, f"blocks.{k}.vert_mlp.mlp1.layers.3", net, width, width)
        net[f"blocks.{k}.vert_mlp.ls1"] = 1.0 + randn(g, width, scale=0.1)
        linear(g, f"blocks.{k}.vert_mlp.mlp2.layers.0", net, width, width)
        linear(g, f"blocks.{k}.vert_mlp.mlp2.layers.3", net, width, width)
        net[f"blocks.{k}.vert_mlp.ls2"] = 1.0 + randn(g, width, scale=0.1)
    if head == "njf":
        complex_mlp(g, "head.grad_mlp", net, width, 3, True, width, nlayers)
    elif head == "linear":
        linear(g, "head", net, width, c_out)
    else:
        raise ValueError(head)
    return net


# ---- the official forward pass, float64 -------------------------------------
def lin(P, x, name):
    return x @ P[name + ".weight"].T + P[name + ".bias"]


def cmlp(P, nlayers, prefix, grads, x_face, modulate):
    re, im = grads[:, 0::2, :], grads[:, 1::2, :]
    if modulate:
        ps = lin(P, F.gelu(lin(P, x_face, prefix + ".modulator.modulator.0")), prefix + ".modulator.modulator.2")
        phase, scale = ps.chunk(2, dim=-1)
        scale = F.softplus(scale) + 1e-8
        re, im = (re * torch.cos(phase) - im * torch.sin(phase)) * scale, (re * torch.sin(phase) + im * torch.cos(phase)) * scale
    for i in range(nlayers):
        wr = P[f"{prefix}.layers.{i}.lin_real.weight"]
        wi = P[f"{prefix}.layers.{i}.lin_imag.weight"]
        yr = re @ wr.T - im @ wi.T
        yi = im @ wr.T + re @ wi.T
        if i < nlayers - 1:
            r = torch.sqrt(yr**2 + yi**2 + 1e-8)
            s = F.gelu(r + P[f"{prefix}.layers.{i}.mag_bias"]) / (r + 1e-8)
            yr, yi = yr * s, yi * s
        re, im = yr, yi
    out = torch.empty(re.shape[0], 2 * re.shape[1], re.shape[2], dtype=re.dtype)
    out[:, 0::2], out[:, 1::2] = re, im
    return out


def poissonnet_forward(net, mesh, x_in, extra, *, blocks, nlayers, head):
    """The official PoissonNet.forward in float64: `extra` is the raw
    conditioning (B, V, C) or None; `head` `njf` (vertex output of the NJF
    head, with the input-gradient residual) or `linear`."""
    P = {k: v.double() for k, v in net.items()}
    if extra is not None:
        extra = lin(P, F.gelu(lin(P, extra, "extra_feat_mlp.0")), "extra_feat_mlp.2")
    grad_in = mesh.G @ x_in
    x = lin(P, x_in, "proj_in")
    for k in range(blocks):
        b = f"blocks.{k}"
        grads = cmlp(P, nlayers, b + ".grad_mlp", mesh.G @ x, mesh.face_mean(x), True)
        u = mesh.poisson(grads)
        h = torch.cat([x, u] + ([extra] if extra is not None else []), dim=-1)
        out = x + P[b + ".vert_mlp.ls1"] * lin(P, F.gelu(lin(P, h, b + ".vert_mlp.mlp1.layers.0")), b + ".vert_mlp.mlp1.layers.3")
        x = out + P[b + ".vert_mlp.ls2"] * lin(P, F.gelu(lin(P, out, b + ".vert_mlp.mlp2.layers.0")), b + ".vert_mlp.mlp2.layers.3")
    if head == "linear":
        return lin(P, x, "head")
    grads = cmlp(P, nlayers, "head.grad_mlp", mesh.G @ x, mesh.face_mean(x), True) + grad_in
    return mesh.poisson(grads)


# ---- files -------------------------------------------------------------------
def write_obj(path, V, Fc):
    with open(path, "w") as f:
        for p in V:
            f.write("v %.17g %.17g %.17g\n" % tuple(p))
        for a, b, c in Fc:
            f.write(f"f {a + 1} {b + 1} {c + 1}\n")


def lightning_checkpoint(sd, params):
    """`sd` wrapped as a PyTorch Lightning checkpoint, with Lightning's own
    entries (optimizer state over `params`, scheduler, loops, callbacks)."""
    return {
        "epoch": 0,
        "global_step": 1234,
        "pytorch-lightning_version": "2.5.1",
        "state_dict": sd,
        "loops": {"fit_loop": {"state_dict": {}, "epoch_loop.state_dict": {"_batches_that_stepped": 1234}}},
        "callbacks": {"ModelCheckpoint{'monitor': None, 'mode': 'min', 'every_n_train_steps': 10000}": {
            "monitor": None, "best_model_score": None, "best_model_path": "", "kth_best_model_path": "",
            "kth_value": torch.tensor(float("inf")), "dirpath": "results/tiny/checkpoints", "last_model_path": ""}},
        "optimizer_states": [{
            "state": {i: {"step": torch.tensor(1234.0), "exp_avg": torch.zeros_like(p), "exp_avg_sq": torch.zeros_like(p)} for i, p in enumerate(params[:2])},
            "param_groups": [{"lr": 1e-4, "betas": (0.9, 0.999), "eps": 1e-8, "weight_decay": 0, "amsgrad": False,
                              "maximize": False, "foreach": None, "capturable": False, "differentiable": False,
                              "fused": None, "initial_lr": 5e-4, "params": list(range(len(params)))}]}],
        "lr_schedulers": [{"milestones": collections.Counter({5000: 1, 140000: 1}), "gamma": 0.2, "base_lrs": [5e-4],
                           "last_epoch": 1234, "verbose": False, "_step_count": 1235,
                           "_get_lr_called_within_step": False, "_last_lr": [1e-4]}],
    }


def main(out):
    out.mkdir(parents=True, exist_ok=True)
    g = torch.Generator().manual_seed(20261203)
    V, Fc = octahedron_subdivided()
    mesh = Mesh(V, Fc)
    nV = mesh.nV

    # The official parameter set of Matern_FM's PoissonNet: in_dim 3, njf head,
    # extra features ['v_source', 't'] (4 channels through extra_feat_mlp).
    net = poissonnet_params(g, c_in=3, width=WIDTH, blocks=BLOCKS, nlayers=NLAYERS, extra=4, head="njf")
    sd = collections.OrderedDict(("base_model." + name, t) for name, t in net.items())

    v_source = torch.tensor(V)[None]
    x_t = torch.randn(2, nV, 3, generator=g, dtype=torch.float64) * 0.3 + v_source
    t = torch.tensor([0.25, 0.8], dtype=torch.float64)
    B = x_t.shape[0]
    extra = torch.cat([v_source.expand(B, -1, -1), t.reshape(B, 1, 1).expand(B, nV, 1)], dim=-1)
    with torch.no_grad():
        expected = poissonnet_forward(net, mesh, x_t, extra, blocks=BLOCKS, nlayers=NLAYERS, head="njf")

    write_obj(out / "template.obj", V, Fc)
    np.save(out / "x_t.npy", x_t.numpy())
    np.save(out / "t.npy", t.numpy())
    np.save(out / "expected.npy", expected.numpy())

    params = list(sd.values())
    torch.save(lightning_checkpoint(sd, params), out / "tiny.ckpt")

    (out / "config.yaml").write_text(f"""group: Tiny
exp_name: fixture

manual_seed: 42

model:
  type: Matern_FM
  model_type: PoissonNet
  outputs_at: vertices
  x0_dist:
    type: 'poisson_solve'
    sigma: 3.0
    screened_solver_for_x0: True
    screening_term: 100.0
  in_dim: 3
  out_dim: 6
  hidden_dim: {WIDTH}
  num_blocks: {BLOCKS}
  head_type: njf
  use_source_xyz_grad: True
  use_extra_features: True
  extra_features: ['v_source', 't']
  extra_configs:
    dropout_p: 0.0
    drop_path: 0.0
    mlp_norm: False
    inner_prod_features: False
    cmlp_modulate: True
    cmlp_nlayers: {NLAYERS}
    cmlp_dropout: 0.0

train:
  lr: 0.0005
  iterations: 160000
  batch_size: 40
  center_target_data: True

ode_solver:
  method: 'midpoint'
  step_size: 0.05
""")
    print(f"{len(sd)} tensors, {sum(p.numel() for p in params)} parameters -> {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]))

"""Writes fixtures/official-arbitrary: a tiny arbitrary-source model in the
layout of the official Matérn-FM code, for the import test.

- arbitrary.ckpt: a PyTorch Lightning checkpoint of the official
  Matern_FM_arbitrary_source module: the flow's PoissonNet under
  base_model.* (njf head, conditioning [source xyz, t, K predicted
  eigenvectors] through extra_feat_mlp) and the frozen eigenvector
  predictor under eigenvecs_predictor.* (linear head, no conditioning),
  plus Lightning's own entries;
- predictor.ckpt: the predictor alone, as the official Eigenvec_Predictor
  module saves it (base_model.*);
- config.yaml: the flow's configuration (moyo_arbitrary_source.yaml at a
  tiny size);
- template.obj, x_t.npy, t.npy: the mesh and the flow's inputs;
- expected_eigenvectors.npy: the predictor's output on the template's
  positions, [1, V, K];
- expected.npy: the flow's vertex output on x_t, t with the conditioning
  [template xyz, t, expected eigenvectors], [2, V, 3].

Both outputs are computed here in float64 by the forward pass written from
reading the official PoissonNet (crates/fm/tests/official_fixture.py's
functions, reused).

Usage: python official_arbitrary_fixture.py OUT_DIR
"""

import collections
import sys
from pathlib import Path

import numpy as np
import torch

sys.dont_write_bytecode = True  # no __pycache__ in the source tree
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "fm" / "tests"))
from official_fixture import (  # noqa: E402
    Mesh,
    lightning_checkpoint,
    octahedron_subdivided,
    poissonnet_forward,
    poissonnet_params,
    write_obj,
)

WIDTH, FLOW_BLOCKS, PREDICTOR_BLOCKS, NLAYERS, K = 8, 2, 1, 3, 4


def main(out):
    out.mkdir(parents=True, exist_ok=True)
    g = torch.Generator().manual_seed(20261204)
    V, Fc = octahedron_subdivided()
    mesh = Mesh(V, Fc)
    nV = mesh.nV

    flow = poissonnet_params(g, c_in=3, width=WIDTH, blocks=FLOW_BLOCKS, nlayers=NLAYERS, extra=4 + K, head="njf")
    predictor = poissonnet_params(g, c_in=3, width=WIDTH, blocks=PREDICTOR_BLOCKS, nlayers=NLAYERS, extra=0,
                                  head="linear", c_out=K)

    v_source = torch.tensor(V)[None]
    x_t = torch.randn(2, nV, 3, generator=g, dtype=torch.float64) * 0.3 + v_source
    t = torch.tensor([0.3, 0.7], dtype=torch.float64)
    B = x_t.shape[0]
    with torch.no_grad():
        eigen = poissonnet_forward(predictor, mesh, v_source, None, blocks=PREDICTOR_BLOCKS, nlayers=NLAYERS,
                                   head="linear")
        extra = torch.cat([v_source.expand(B, -1, -1), t.reshape(B, 1, 1).expand(B, nV, 1),
                           eigen.expand(B, -1, -1)], dim=-1)
        expected = poissonnet_forward(flow, mesh, x_t, extra, blocks=FLOW_BLOCKS, nlayers=NLAYERS, head="njf")

    write_obj(out / "template.obj", V, Fc)
    np.save(out / "x_t.npy", x_t.numpy())
    np.save(out / "t.npy", t.numpy())
    np.save(out / "expected_eigenvectors.npy", eigen.numpy())
    np.save(out / "expected.npy", expected.numpy())

    # the Lightning module registers base_model first, then the predictor
    sd = collections.OrderedDict(("base_model." + n, p) for n, p in flow.items())
    sd.update(("eigenvecs_predictor." + n, p) for n, p in predictor.items())
    torch.save(lightning_checkpoint(sd, list(flow.values())), out / "arbitrary.ckpt")
    alone = collections.OrderedDict(("base_model." + n, p) for n, p in predictor.items())
    torch.save(lightning_checkpoint(alone, list(predictor.values())), out / "predictor.ckpt")

    (out / "config.yaml").write_text(f"""group: Tiny_arbitrary_source
exp_name: fixture

manual_seed: 42

model:
  type: Matern_FM_arbitrary_source
  model_type: PoissonNet

  outputs_at: vertices

  x0_dist:
    type: 'poisson_solve'
    sigma: 5.0
    screened_solver_for_x0: True
    screening_term: 100.0

  in_dim: 3
  out_dim: 6
  hidden_dim: {WIDTH}
  num_blocks: {FLOW_BLOCKS}

  head_type: njf
  use_source_xyz_grad: True

  use_extra_features: True
  extra_features: ['v_source', 't']

  use_predicted_eigenvecs: True

  extra_configs:
    dropout_p: 0.0
    drop_path: 0.0
    mlp_norm: False
    inner_prod_features: False
    cmlp_modulate: True
    cmlp_nlayers: {NLAYERS}
    cmlp_dropout: 0.0

  eigenvecs_predictor:
    checkpoint_path: ckpts/tiny_eigenvecs_predictor.ckpt
    in_dim: 3
    out_dim: {K}
    hidden_dim: {WIDTH}
    num_blocks: {PREDICTOR_BLOCKS}
    head_type: 'linear'
    outputs_at: 'vertices'

    extra_configs:
      dropout_p: 0.0
      drop_path: 0.0
      mlp_norm: False
      inner_prod_features: False
      cmlp_modulate: True
      cmlp_nlayers: {NLAYERS}
      cmlp_dropout: 0.0

dataset:
  name: arbitrary_source
  data_file: data/tiny_arbitrary_source.pt
  screening_term: 100.0
  use_data_augmentation: True

train:
  lr: 0.0005
  iterations: 240000
  batch_size: 32
  lr_scheduler:
    type: MultiStepLR
    milestones: [40000, 160000]
    gamma: 0.2
  save_every_n_steps: 10000
  gradient_clipping:
    enabled: True
    max_norm: 1.0
  loss_type: NJF_loss
  center_target_data: True

ode_solver:
  method: 'midpoint'
  step_size: 0.05
""")
    n = sum(p.numel() for p in sd.values())
    print(f"{len(sd)} tensors, {n} parameters -> {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]))

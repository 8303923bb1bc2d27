"""A rank of a small data-parallel training job (torch.multiprocessing.spawn target)."""
import json
import os
import socket

import torch

from helpers.blobs import blob_recording
from monet_ros.learning import distributed
from monet_ros.learning.config import TrainConfig
from monet_ros.models import build_model

CONFIG = dict(mode='monet', steps=20, epipolar_warmup=0.25, architecture='small',
              input_size=48, width=16, batch_labelled=4, batch_pseudo=4, batch_unlabeled=1,
              views_per_instant=3, lr=3e-3, eval_fraction=0.25, device='cpu',
              checkpoint_every=10)


def free_port():
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def without_batchnorm(model):
    """The network with its BatchNorm layers replaced by identities (per-sample arithmetic,
    so a data-parallel step is the single-process step up to float summation order)."""
    for module in model.modules():
        for name, child in list(module.named_children()):
            if isinstance(child, torch.nn.BatchNorm2d):
                setattr(module, name, torch.nn.Identity())
    return model


def train_rank(rank, world_size, port, out, result, batchnorm=True, precision='float32'):
    """Train CONFIG (in `precision`) on the blob recording as rank `rank` of `world_size`
    (1 = no process group); writes {'losses': [...], 'params': [...]} to `result`_<rank>.json."""
    if world_size > 1:
        os.environ.update(RANK=str(rank), WORLD_SIZE=str(world_size), LOCAL_RANK=str(rank),
                          MASTER_ADDR='127.0.0.1', MASTER_PORT=str(port))
    torch.set_num_threads(1)
    distributed.init_from_env('cpu')
    recording = blob_recording(num_views=4, T=24, C=3, labelled=(2, 9), label_views=(0, 1))
    config = TrainConfig(**CONFIG, precision=precision)
    torch.manual_seed(config.seed)
    model = build_model('small', 3, **config.model_options())
    if not batchnorm:
        model = without_batchnorm(model)
    data = distributed.shared_training_data(recording, config, model.input_size,
                                            model.heatmap_size)
    trainer = distributed.DistributedTrainer(config, data, out, model=model, device='cpu')
    losses = [trainer.step()['loss'] for _ in range(config.steps)]
    params = torch.cat([p.detach().flatten() for p in trainer.model.parameters()])
    with open(f'{result}_{rank}.json', 'w') as f:
        json.dump({'losses': losses, 'params': params.tolist(),
                   'per_rank_batch': trainer.per_rank_batch}, f)
    distributed.shutdown()

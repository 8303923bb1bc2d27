"""Data-parallel training under torchrun (torch.distributed + DistributedDataParallel).

    torchrun --nproc-per-node N -m monet_ros.cli train ...

The launcher's environment (RANK, WORLD_SIZE, LOCAL_RANK, MASTER_ADDR, MASTER_PORT) is read by
`init_from_env`; without it nothing changes (world size 1, no process group). Backend: nccl
when the run trains on CUDA (one device per rank, cuda:LOCAL_RANK), gloo on CPU.

How a step is shared so that the global batch and schedule equal the single-process run:
every rank holds the same RNG state and draws the same global batch plan (Trainer's
_batch_plan: labelled, pseudo-labelled and L_E's unlabeled crops) and the same augmented
crops; each rank runs the network on its contiguous share of the crops (sizes differ by at
most one), the outputs are all-gathered (so every rank evaluates the single-process loss,
masks and all, on the whole batch) and the backward pass sends each rank the gradient of its
share; DDP averages the ranks' gradients, so the update is the single-process one. Parameters
stay equal on every rank (DDP), so resuming with another world size works: the saved state
is global. Bootstrapping rounds (detections -> pseudo-labels) are computed by rank 0 and
broadcast; only rank 0 writes checkpoints, the log and the summary.

Batch normalisation: on CUDA the BatchNorm layers become SyncBatchNorm (statistics over the
global batch: the single-process forward). SyncBatchNorm needs a GPU, so on CPU (gloo) each
rank normalises with its share's statistics: the loss curve then differs from the
single-process one by the batch-statistics noise of the smaller per-rank batch (measured in
test/learning/test_distributed.py).
"""
from dataclasses import dataclass
import datetime
import os

import numpy as np
import torch
import torch.distributed as dist

from monet_ros.learning.trainer import Trainer

# How long a collective waits for a missing rank before failing (s): torchrun stops the job
# at once when a rank dies; this bounds the wait of a survivor that is not supervised.
TIMEOUT_S = float(os.environ.get('MONET_DDP_TIMEOUT_S', '300'))


@dataclass(frozen=True)
class World:
    """This process's place in the job: rank, world_size, local_rank, backend ('' = none)."""
    rank: int = 0
    world_size: int = 1
    local_rank: int = 0
    backend: str = ''

    @property
    def distributed(self):
        return self.world_size > 1

    @property
    def writer(self):
        """Rank 0 writes checkpoints, logs and the summary."""
        return self.rank == 0


def launched():
    """True when a launcher (torchrun) set the environment of a job of several processes."""
    return int(os.environ.get('WORLD_SIZE', '1')) > 1 and 'RANK' in os.environ


_world = World()


def current_world():
    """The World set by init_from_env (World() outside a torchrun job)."""
    return _world


def init_from_env(device='auto'):
    """Join torchrun's job (process group from the environment) when there is one; returns
    (World, torch device or None). device: TrainConfig.device ('auto', 'cpu', 'cuda[:N]');
    under torchrun CUDA means cuda:LOCAL_RANK. Raises ValueError naming the variable when
    the environment is inconsistent."""
    if not launched():
        return World(), None
    try:
        rank, size = int(os.environ['RANK']), int(os.environ['WORLD_SIZE'])
        local = int(os.environ.get('LOCAL_RANK', '0'))
    except ValueError as error:
        raise ValueError(f'torchrun environment: RANK / WORLD_SIZE / LOCAL_RANK: {error}') \
            from None
    cuda = device != 'cpu' and torch.cuda.is_available()
    backend = 'nccl' if cuda else 'gloo'
    where = None
    if cuda:
        if local >= torch.cuda.device_count():
            raise ValueError(f'torchrun environment: LOCAL_RANK {local} but only '
                             f'{torch.cuda.device_count()} CUDA device(s)')
        where = torch.device('cuda', local)
        torch.cuda.set_device(where)
    if not dist.is_initialized():
        dist.init_process_group(backend, timeout=datetime.timedelta(seconds=TIMEOUT_S),
                                **({'device_id': where} if cuda else {}))
    global _world
    _world = World(rank, size, local, backend)
    return _world, where or torch.device('cpu')


def shutdown():
    if dist.is_initialized():
        dist.destroy_process_group()


def shares(n, world_size):
    """(world_size + 1,) boundaries of the ranks' contiguous shares of n crops."""
    sizes = np.full(world_size, n // world_size)
    sizes[:n % world_size] += 1
    return np.concatenate([[0], np.cumsum(sizes)])


class _GatherShares(torch.autograd.Function):
    """All-gather of the ranks' (n_r, ...) outputs into the (N, ...) batch; backward: this
    rank's rows of the gradient x world size (every rank computes the same loss on the
    gathered batch, and DDP averages the ranks' gradients, so the sum is the full one)."""

    @staticmethod
    def forward(ctx, local, bounds):
        size = dist.get_world_size()
        rank = dist.get_rank()
        longest = int(np.max(np.diff(bounds)))
        padded = local.new_zeros((longest, *local.shape[1:]))
        padded[:len(local)] = local
        gathered = [torch.empty_like(padded) for _ in range(size)]
        dist.all_gather(gathered, padded.contiguous())
        ctx.rows = (int(bounds[rank]), int(bounds[rank + 1]))
        ctx.size = size
        return torch.cat([g[:bounds[r + 1] - bounds[r]] for r, g in enumerate(gathered)])

    @staticmethod
    def backward(ctx, grad):
        start, stop = ctx.rows
        return grad[start:stop] * ctx.size, None


class DistributedTrainer(Trainer):
    """Trainer of one rank of a torchrun job (see the module docstring). Built like Trainer,
    with `world` (World); out_dir is given on every rank (resume reads it) but only rank 0
    writes into it."""

    def __init__(self, config, data, out_dir=None, model=None, device=None, warn=None,
                 world=None):
        self.world = world or current_world()
        super().__init__(config, data, out_dir, model=model, device=device,
                         warn=warn if self.world.writer else (lambda message: None))
        self._ddp = None

    @property
    def per_rank_batch(self):
        """Crops per step on each rank: the largest share of the global batch."""
        c = self.config
        k = self.views_per_instant() if hasattr(self, 'views_per_instant') else \
            min(c.views_per_instant, self.data.recording.num_views)
        total = c.batch_labelled + c.batch_pseudo + c.batch_unlabeled * k
        return int(np.max(np.diff(shares(total, self.world.world_size))))

    def _wrap(self):
        if self._ddp is None:
            if self.world.backend == 'nccl':      # global batch statistics (GPU only)
                self.model = torch.nn.SyncBatchNorm.convert_sync_batchnorm(self.model)
            ids = [self.device.index] if self.device.type == 'cuda' else None
            self._ddp = torch.nn.parallel.DistributedDataParallel(self.model, device_ids=ids)
        return self._ddp

    def forward_batch(self, images):
        """The network on this rank's share of a training step's images, gathered into the
        whole batch's outputs (a list of (N, C, h, w) stages). Evaluation (no grad / eval
        mode) runs locally on every image, as Trainer does."""
        if not (self.world.distributed and torch.is_grad_enabled() and self.model.training):
            return super().forward_batch(images)
        bounds = shares(len(images), self.world.world_size)
        if np.any(np.diff(bounds) == 0):
            raise ValueError(f'a training step has {len(images)} crops, fewer than the '
                             f'{self.world.world_size} ranks (raise --batch-labelled)')
        rank = self.world.rank
        stages = self._wrap()(images[bounds[rank]:bounds[rank + 1]])
        # gathered in float32 (bfloat16 autocast outputs too: the losses are float32 anyway)
        return [_GatherShares.apply(s.float(), bounds) for s in stages]

    def bootstrap(self):
        """A bootstrapping round computed by rank 0 and broadcast to every rank."""
        if not self.world.distributed:
            return super().bootstrap()
        result = super().bootstrap() if self.world.writer else None
        shared = [(self.pseudo, self.bootstrap_done, self.bootstrap_stats, result)
                  if self.world.writer else None]
        dist.broadcast_object_list(shared, src=0)
        self.pseudo, self.bootstrap_done, self.bootstrap_stats, result = shared[0]
        self._update_pools()
        return result

    def save(self):
        if self.world.writer:
            return super().save()
        self.last_checkpoint = self.out_dir / 'checkpoints' / \
            f'step_{self.step_count:06d}.pt'
        return self.last_checkpoint

    def _log(self, terms):
        if self.world.writer:
            super()._log(terms)

    def _truncate_log(self):
        if self.world.writer:
            super()._truncate_log()

    def run(self, steps=None, progress=True):
        summary = super().run(steps, progress=progress and self.world.writer)
        summary['world_size'] = self.world.world_size
        summary['per_rank_batch'] = self.per_rank_batch
        return summary

    @classmethod
    def resume(cls, out_dir, data, config=None, device=None, model=None):
        """Trainer.resume on every rank: rank 0 first (it removes a killed write's
        temporaries and truncates the log), then the others read the same state."""
        world = current_world()
        trainer = super().resume(out_dir, data, config, device, model) if world.writer \
            else None
        if world.distributed:
            dist.barrier()
        if not world.writer:
            trainer = super().resume(out_dir, data, config, device, model)
        return trainer


def shared_training_data(recording, config, input_size, heatmap_size, holdout=()):
    """trainer.TrainingData on every rank, its spatiotemporal pseudo-labels (optical-flow
    tracking of the labels, every labelled subject's) computed once by rank 0 and
    broadcast; holdout: TrainingData's (the instants of --holdout-labelled)."""
    from monet_ros.learning.trainer import TrainingData

    world = current_world()
    if not world.distributed:
        return TrainingData(recording, config, input_size, heatmap_size, holdout=holdout)
    data, failure = None, None
    if world.writer:
        try:
            data = TrainingData(recording, config, input_size, heatmap_size, holdout=holdout)
            if config.spec.temporal:
                data.tracked_labels()
                for s in data.other_subject_ids:       # each subject's own tracks
                    data.subject_tracks(int(s))
        except ValueError as error:        # every rank stops with rank 0's message
            failure = str(error)
    shared = [(data._tracked if data is not None else None,
               data._subject_tracked if data is not None else None, failure)]
    dist.broadcast_object_list(shared, src=0)
    tracked, subject_tracked, failure = shared[0]
    if failure is not None:
        raise ValueError(failure)
    if data is None:
        data = TrainingData(recording, config, input_size, heatmap_size, tracked=tracked,
                            subject_tracked=subject_tracked, holdout=holdout)
    return data

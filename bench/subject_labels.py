"""Labels of several subjects for training (issue 39 item 6): a detector trained on the
labels of BOTH subjects of a two-subject recording against the same detector trained on
subject 0's labels only (the same labelled instants, the same steps and seed), each scored
on the held-out tail in crops around each subject's ground truth.

Data: `monet synth --subjects 2 --label-subjects` (human14, --cameras cameras, --frames
instants, --label-fraction of them labelled for both subjects: labels.csv with a subject
column); the 'subject 0 only' arm drops the subject 1 rows. Training: mode supervised (L_L
only), the small network at --input-size, box source labels, eval_fraction 0.25 (the last
quarter of the instants is never trained on). Score: for every held-out instant, view and
subject, a crop around that subject's ground-truth projection (the labels crop rule:
learning.dataset.boxes_from_points, the training margin), the heatmap peaks mapped back to
the image; the distance to the ground-truth projection of every keypoint inside the image
and not hidden, median (px) and PCK@10 px. Printed as a markdown table with the load
average and the CPU (2 threads, niced: figures of a shared machine).

usage: python bench/subject_labels.py [--steps 800] [--seeds 0 1] > bench/results/subject_labels.md
"""
import argparse
import os
from pathlib import Path
import tempfile
import time

import numpy as np
import torch

from monet_ros.labels import read_labels, write_labels
from monet_ros.learning.config import TrainConfig
from monet_ros.learning.dataset import CropCache, boxes_from_points
from monet_ros.learning.recording import load_recording
from monet_ros.learning.trainer import Trainer, TrainingData
from monet_ros.models import decode_heatmaps
from monet_ros.synth.recording import SynthConfig, synthesize


def cpu_name():
    try:
        with open('/proc/cpuinfo') as f:
            for line in f:
                if line.startswith('model name'):
                    return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return 'unknown CPU'


def held_out_errors(trainer, rec, gt, held, size, margin):
    """{subject: (N,) px} distances of the detections in crops around each subject's
    ground truth, on the held-out instants, for keypoints inside the image and not hidden."""
    V = rec.num_views
    out = {}
    for s in (0, 1):
        uv = gt['subjects_keypoints2d'][held, :, s]                          # (H, V, C, 2)
        inside = gt['subjects_in_image'][held, :, s]
        seen = inside & ~gt['subjects_occluded'][held, :, s]
        boxes = boxes_from_points(np.where(inside[..., None], uv, np.nan), margin=margin)
        full = [0.0, 0.0, float(rec.cameras[0].width), float(rec.cameras[0].height)]
        boxes = np.where(np.isfinite(boxes), boxes, full)                # unseen: not scored
        cache = CropCache(rec, boxes, (size, size), (size // 4, size // 4), 1.3,
                          instants=held)
        rows = np.repeat(np.arange(len(held)), V)
        views = np.tile(np.arange(V), len(held))
        points = []
        trainer.model.eval()
        for a in range(0, len(rows), 64):
            batch = cache.views(rows[a:a + 64], views[a:a + 64])
            with torch.no_grad():
                heat = trainer.model(batch.images)[-1].float()
            peaks, _ = decode_heatmaps(heat)
            A_inv = np.linalg.inv(batch.A)
            points.append(np.einsum('nij,ncj->nci', A_inv[:, :2, :2],
                                    peaks.numpy().astype(np.float64)) + A_inv[:, None, :2, 2])
        points = np.concatenate(points).reshape(uv.shape)
        out[s] = np.linalg.norm(points - uv, axis=-1)[seen]
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--frames', type=int, default=200)
    parser.add_argument('--cameras', type=int, default=4)
    parser.add_argument('--label-fraction', type=float, default=0.05)
    parser.add_argument('--steps', type=int, default=800)
    parser.add_argument('--seeds', type=int, nargs='+', default=[0, 1])
    parser.add_argument('--input-size', type=int, default=96)
    parser.add_argument('--threads', type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print('# Labels of two subjects vs one\n')
    print('`PYTHONPATH=. .venv/bin/python bench/subject_labels.py` (defaults)\n')
    print(f'CPU: {cpu_name()}; loadavg at start {os.getloadavg()}; {args.threads} torch '
          f'threads\n')
    print(f'monet synth --subjects 2 --label-subjects, {args.cameras} cameras 320x240, '
          f'{args.frames} instants, --label-fraction {args.label_fraction}; supervised, '
          f'small network {args.input_size} px, {args.steps} steps, held-out tail 25%; '
          'median px / PCK@10 px in crops around each subject (visible keypoints)\n')
    print('<!-- --8<-- [start:table] -->')
    print('| labels | seed | labelled crops | subject 0 median px | subject 0 PCK@10 | '
          'subject 1 median px | subject 1 PCK@10 | train s |')
    print('|---|---|---|---|---|---|---|---|')
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / 'two'
        synthesize(SynthConfig(cameras=args.cameras, frames=args.frames, width=320,
                               height=240, label_fraction=args.label_fraction, subjects=2,
                               label_subjects=True), root, progress=False)
        gt = np.load(root / 'ground_truth.npz')
        only0 = Path(tmp) / 'labels0.csv'
        write_labels(only0, [r for r in read_labels(root / 'labels.csv').subject_rows()
                             if r[5] == 0])
        for seed in args.seeds:
            for name, labels in (('both subjects', root / 'labels.csv'),
                                 ('subject 0 only', only0)):
                rec = load_recording(root, labels=labels)
                config = TrainConfig(
                    mode='supervised', steps=args.steps, architecture='small',
                    input_size=args.input_size, width=16, batch_labelled=8, batch_pseudo=0,
                    batch_unlabeled=0, eval_fraction=0.25, device='cpu',
                    box_source='labels', seed=seed, lr=1e-3)
                size = (args.input_size, args.input_size)
                data = TrainingData(rec, config, size, (size[0] // 4, size[1] // 4))
                trainer = Trainer(config, data, warn=lambda message: None)
                start = time.perf_counter()
                trainer.run(progress=False)
                wall = time.perf_counter() - start
                err = held_out_errors(trainer, rec, gt, data.held_out, args.input_size,
                                      config.box_margin)
                cells = ' | '.join(f'{np.median(err[s]):.2f} | {100 * (err[s] <= 10).mean():.1f}%'
                                   for s in (0, 1))
                print(f'| {name} | {seed} | {len(trainer.labelled_pool)} | {cells} | '
                      f'{wall:.0f} |', flush=True)
    print('<!-- --8<-- [end:table] -->')
    print(f'\nloadavg at end {os.getloadavg()}')


if __name__ == '__main__':
    main()

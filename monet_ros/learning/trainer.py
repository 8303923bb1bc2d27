"""The semi-supervised trainer: a reusable object with a step() API.

    data = TrainingData(recording, config)        # splits, crops, labels, virtual cameras
    trainer = Trainer(config, data, out_dir)      # or Trainer.resume(out_dir, data)
    while trainer.step_count < config.steps:
        terms = trainer.step()                    # {'loss', 'L', 'E', 'B', 'lr', 'step'}
    trainer.save()

Modes (config.mode) are the paper's rows: supervised (L_L), spatial / spatiotemporal
(L_L + lambda_p L_B on augmented labels), bootstrap1 / bootstrap2 (the spatiotemporal
augmentation plus one or two rounds of detections -> RANSAC triangulation -> reprojection
as labels, at evenly spaced steps), monet (the paper's: L_L + lambda_e L_E on unlabeled
instants, after a warm-up of epipolar_warmup x steps without L_E, + lambda_p L_B on the
spatiotemporal augmentation; monet_bootstrap_rounds > 0 adds bootstrapped labels),
reprojection_epipolar (the default recipe, reprojection, + L_E on the same instants as L_R),
and the ablations bootstrap2_epipolar (Bootstrapping II from spatial labels + L_E) and
epipolar (L_L + lambda_e L_E only). L_E is losses.epipolar_loss, the anchored one-sided
epipolar term (issue 36), on the raw last-stage heatmaps of every view (views_per_instant =
0) of batch_unlabeled unlabeled instants per step, anchored at L_R's confidence cut-off
(anchor_cutoff); it starts after the warm-up at the first step whose labelled crops the
detector fits (epipolar_fit_heat_px). Every mode sees
the same number of images per step, and the batch plan never depends on lambda_e /
lambda_p: a run with a weight of 0 is that term's exact control (see _batch_plan).
State (weights, Adam, schedule, step, RNG, pseudo-labels) is checkpointed atomically and
resumes exactly.
Precision (config.precision): bfloat16 runs the network forward under torch.autocast
(about 2x the steps/s on a CPU with AVX512-BF16 / AMX, bench/train_recipe.py); the stages are
cast to float32 before the losses, and weights, Adam and checkpoints stay float32. It is
refused (ConfigError naming precision) where bfloat16 is not native: the inference rule,
models.detector.check_precision; auto picks bfloat16 there where native, else float32
(models.detector.resolve_precision; Trainer.precision / precision_note say which).

Problems that make a run quietly useless are warned about loudly (stderr by default, and in
`warnings` of the run summary): a semi-supervised term with no data (no pseudo-labels, a
bootstrapping round that keeps nothing, no unlabeled instant for L_E) and a detector that
does not fit its own labelled views at the end (median error >
fit_warning_heat_px heatmap pixels).
"""
from contextlib import contextmanager
import csv
from dataclasses import replace
import json
import os
from pathlib import Path
import signal
import sys
import threading
import time

import numpy as np
import torch
from tqdm import tqdm

from monet_ros.atomic import atomic_write, write_error
from monet_ros.config import ConfigError
from monet_ros.crop_rule import recording_boxes, subject_label_boxes
from monet_ros.evaluation.reprojection import multiview_reprojection
from monet_ros.learning.config import LOSS_TERMS, TrainConfig
from monet_ros.learning.dataset import CropCache
from monet_ros.learning.losses import (
    anchored_epipolar_terms,
    masked_heatmap_mse,
    objective,
    reduce_anchored_terms,
    soft_argmax,
    temporal_difference_loss,
)
from monet_ros.learning.pseudo_labels import (
    PseudoLabels,
    bootstrap_pseudo_labels,
    spatial_pseudo_labels,
    spatiotemporal_pseudo_labels,
)
from monet_ros.learning.symmetric_epipolar import symmetric_epipolar_loss
from monet_ros.models import build_model, decode_heatmaps, save_checkpoint
from monet_ros.models.detector import check_precision, resolve_precision

STATE_FORMAT = 'monet_ros.trainer_state/1'
LOG_FIELDS = ('step', 'loss', *LOSS_TERMS, 'lr', 'pseudo_labels', 'seconds')


def nonnegative(heat):
    """(..., h, w) heatmaps shifted so that each map's minimum is 0: the input of L_E.

    The epipolar divergence clamps negative values; on raw network outputs an all-negative
    map is an empty distribution with zero divergence, a degenerate minimum that wrecks the
    heatmaps. Shifting by the minimum keeps each map's shape (and its row maxima's order).
    The shift is detached: through amin, every row maximum's gradient would also flow, with
    the opposite sign, into the map's single minimum pixel (about a third of L_E's gradient,
    spent moving a pixel no detection uses). Detached, L_E's gradient reaches the row-maximum
    pixels only. (A spatial softmax would change what the maps mean, Gaussians of peak 1
    trained by L_L's MSE; a non-negative head would change every network and checkpoint.)"""
    return heat - heat.amin(dim=(-2, -1), keepdim=True).detach()


def pick_device(name):
    if name == 'auto':
        return torch.device('cuda' if torch.cuda.is_available() else 'cpu')
    return torch.device(name)


def check_training_precision(precision, device):
    """ConfigError naming TrainConfig.precision unless it runs well on `device` (torch device
    or string): the inference rule, models.detector.check_precision (bfloat16 only where the
    CPU has AVX512-BF16 / AMX or the GPU bfloat16; elsewhere it is emulated, slower). int8
    is refused by name: an inference precision (ONNX Runtime quantisation), not a training
    one."""
    if precision == 'int8':
        raise ConfigError('TrainConfig', 'precision', 'int8 is an inference precision (ONNX '
                          'Runtime static quantisation of a trained network), not a training '
                          'one: train in auto, float32 or bfloat16')
    try:
        check_precision(precision, 'torch', device)
    except ValueError as error:
        raise ConfigError('TrainConfig', 'precision', str(error)) from None


def split_instants(num_instants, eval_fraction):
    """(train (T_tr,), held_out (T_ev,)) index arrays: the held-out split is the contiguous
    tail of the recording, so tracking and training never see it."""
    n_eval = int(np.ceil(num_instants * eval_fraction)) if eval_fraction > 0 else 0
    n_eval = min(n_eval, num_instants - 1)
    return np.arange(num_instants - n_eval), np.arange(num_instants - n_eval, num_instants)


def spread_instants(candidates, n):
    """n of the `candidates` (sorted instant indices), evenly spread: the middle of each of n
    equal runs (deterministic; the rule of validation_split and `monet train
    --holdout-labelled`). n >= len(candidates) gives them all."""
    candidates = np.asarray(candidates)
    if n <= 0:
        return candidates[:0]
    if n >= len(candidates):
        return candidates.copy()
    picks = np.round((np.arange(n) + 0.5) * len(candidates) / n - 0.5).astype(int)
    return candidates[np.unique(picks)]


def validation_split(labelled, held_out, fraction):
    """(K,) sorted instants whose labels are held out for validation (never trained on).

    labelled (L,) the labelled instants to choose among: those where ANY subject is
    labelled (Recording.labelled_instants; a labels table of several subjects counts an
    instant labelled for subject 1 only too); held_out: the eval_fraction tail (already
    never trained on). fraction 0 -> none; else the target is max(1, round(fraction x
    labelled instants)): the tail's labelled instants count first, the rest are
    spread_instants of the labelled instants before the tail, always leaving at least one
    of those to train on. Deterministic: a resumed run (same labels, tail and fraction)
    gets the same split."""
    labelled = np.unique(np.asarray(labelled, np.int64))
    if fraction <= 0 or labelled.size == 0:
        return np.zeros(0, dtype=np.int64)
    target = max(1, int(round(fraction * labelled.size)))
    tail = np.intersect1d(labelled, held_out)
    train = np.setdiff1d(labelled, held_out)
    extra = min(max(0, target - tail.size), max(0, train.size - 1))
    return np.sort(np.concatenate([tail, spread_instants(train, extra)])).astype(np.int64)


def no_validation_text(fraction, option='validation_labels', after=''):
    """Why validation_split held out no labelled instant at `fraction` (the one-line warning
    of `monet train --validation-labels` and of the learner's publish_metric auto): none
    asked for, or only one labelled instant to train on (one is always left to train on).
    option: the setting as the caller's user spells it; after: what left one instant
    (e.g. 'after --holdout-labelled 1')."""
    why = (f'{option} is 0' if fraction <= 0 else
           f'{option} {fraction:g}: only one labelled instant to train on'
           + (f' {after}' if after else '') + ', and one is always left to train on')
    return f'no labelled instant can be held out for validation ({why})'


def crop_boxes(recording, source, aspect, margin, pseudo=None):
    """(T, V, 4) training crop boxes (crop_rule.recording_boxes). 'auto' = 'pseudo_labels'
    when `pseudo` (spatiotemporal tracks of the labels) is given, else 'labels': boxes a
    user has, never the ground truth unless asked for explicitly."""
    if source == 'auto':
        source = 'pseudo_labels' if pseudo is not None else 'labels'
    return recording_boxes(recording, source, aspect, margin, pseudo=pseudo)


class TrainingData:
    """A recording prepared for training: train / held-out split, crops, label arrays.

    labels (T, V, C, 2) are the recording's labels on the train split (NaN on the held-out
    split and on the validation instants); validation_instants (K,) (validation_split of
    config.validation_labels) and validation_labels (K, V, C, 2) px: held-out labelled views,
    in no training pool (no L_L, no pseudo-label, not an unlabeled instant of L_E), and their
    crop boxes do not come from their own labels. Every index is an instant of the full
    recording.

    Several subjects (Recording.other_labels, a labels table with a subject column): each
    other labelled (instant, subject) j is one more row T + j of the crop cache, the
    instant's images cropped around THAT subject's labels by the same crop rule
    (crop_rule.subject_label_boxes), supervised by that subject's labels only (L_L;
    label_points): the other subject seen in such a crop is not a positive, and neither is
    subject j in subject 0's crops. other_labels (J, V, C, 2) are those labels on the train
    split (NaN at held-out and validation instants), other_instants (J,) their instants.

    Unlabelled instants per subject: when the mode trains on unlabelled instants (L_E, L_T,
    L_R, tracked or bootstrapped pseudo-labels) or distils (config.distill_rounds: the
    teacher's 3D of each subject goes to its own rows) and the crops follow the labels (box_source
    auto, labels or pseudo_labels), each labelled subject s >= 1 (other_subject_ids: a label
    in the train split) gets one more crop row T + J + m per unlabelled instant (m runs over
    the subjects, then unlabeled_instants): that instant's views cropped by subject 0's crop
    rule (crop_boxes) on subject s's own labels (subject_labels) and, for auto /
    pseudo_labels, their tracks (subject_tracks). Subject 0's unlabelled rows are the
    instants themselves. unlabeled_rows (U_0 + sum U_s,) are every subject's; row_instants /
    row_subjects (num_rows,) give each crop row's instant and subject; next_row (num_rows,)
    the same subject's unlabelled row at the next instant (-1 none: L_T's pairs).
    initial_pseudo_labels gives each row its own subject's pseudo-labels. A labels table of
    one subject has num_rows = T and unlabeled_rows = unlabeled_instants: it trains as
    before.

    Validation labels of several subjects: the validation instants are chosen among the
    instants where any subject is labelled (validation_split of Recording.
    labelled_instants) and every subject labelled there is held out and scored:
    validation_rows (M,) crop rows (the instants for subject 0, T + j for other subject j),
    validation_row_labels (M, V, C, 2) px and validation_row_subjects (M,) (scored_rows); an
    other subject's validation row is framed without its labels, by framing_boxes (its
    crop rule over its other instants' labels and tracks), as subject 0's validation views
    are. Distillation's pseudo-labels go to every subject's rows (Trainer.set_distilled,
    commands.train_distill).

    holdout (H,) instants (`monet train --holdout-labelled`, commands.train_holdout): every
    subject's labels there are removed before anything is made of them (self.recording is
    the recording without them: as before subjects, the instants stay unlabelled training
    instants, their images used without labels) and scored as the validation labels are:
    holdout_instants, holdout_rows / holdout_row_labels / holdout_row_subjects (the
    recording's labels there, every subject's; framed without them). Validation instants
    are chosen among the other labelled instants."""

    def __init__(self, recording, config, input_size, heatmap_size, tracked=None,
                 subject_tracked=None, holdout=()):
        self.holdout_instants = np.unique(np.asarray(holdout, np.int64))
        source = recording          # the labels scored at the holdout instants
        if len(self.holdout_instants):
            labels = recording.labels.copy()
            labels[self.holdout_instants] = np.nan
            other = recording.other_labels.copy()
            other[np.isin(recording.other_instants, self.holdout_instants)] = np.nan
            recording = replace(recording, labels=labels, other_labels=other)
        self.recording = recording
        self.config = config
        self.train, self.held_out = split_instants(recording.num_instants, config.eval_fraction)
        # among the instants where any subject is labelled; every subject of those instants
        # is held out of training with them and scored (validation_rows)
        self.validation_instants = validation_split(recording.labelled_instants, self.held_out,
                                                    config.validation_labels)
        self.validation_labels = recording.labels[self.validation_instants].copy()
        self.labels = recording.labels.copy()
        self.labels[self.held_out] = np.nan
        self.labels[self.validation_instants] = np.nan
        self.other_instants = recording.other_instants.copy()
        self.other_labels = recording.other_labels.copy()
        self.other_labels[np.isin(self.other_instants, np.union1d(
            self.held_out, self.validation_instants))] = np.nan
        labelled = np.isfinite(self.labels[..., 0]).any(axis=2)             # (T, V)
        other = np.isfinite(self.other_labels[..., 0]).any(axis=(1, 2))       # (J,)
        self.labelled_instants = np.union1d(np.flatnonzero(labelled.any(axis=1)),
                                            self.other_instants[other]).astype(np.int64)
        self.unlabeled_instants = np.setdiff1d(self.train, np.union1d(
            self.labelled_instants, self.validation_instants))
        if self.labelled_instants.size == 0:
            raise ValueError(f'{recording.name}: no labelled instant to train on')
        h_in, w_in = input_size
        self.cache_input_size = (h_in, w_in)
        self._tracked = tracked       # tracks() given (rank 0's, in a torchrun job)
        # subject_tracks(s) given (rank 0's): {subject: PseudoLabels}
        self._subject_tracked = dict(subject_tracked or {})
        # pseudo_max_frames' counts of view x keypoint cells (initial_pseudo_labels): tracked,
        # dropped (beyond the gate, unconfirmed), confirmed (beyond, kept by agreement)
        self.pseudo_gate = None
        tracked_boxes = config.box_source in ('auto', 'pseudo_labels')
        pseudo = self.tracked_labels() if tracked_boxes else None
        boxed = recording
        if self.validation_instants.size:      # validation views framed without their labels
            masked = recording.labels.copy()
            masked[self.validation_instants] = np.nan
            boxed = replace(recording, labels=masked)
        self.boxes = crop_boxes(boxed, config.box_source, w_in / h_in, config.box_margin,
                                pseudo)
        T = recording.num_instants
        J = len(self.other_instants)
        # the labelled subjects other than 0 (a label in the train split), each with its own
        # rows of unlabelled instants when the mode trains on unlabelled instants (L_E, L_T,
        # L_R, tracked or bootstrapped pseudo-labels, distillation's) and the crops follow
        # the labels (a
        # fixed or full crop, or the ground truth's subject 0, frames every subject alike)
        spec = config.spec
        self.other_subject_ids = np.unique(recording.other_subjects[other]) \
            if (spec.unlabeled or spec.temporal or spec.bootstrap_rounds or
                config.distill_rounds) and \
            config.box_source in ('auto', 'labels', 'pseudo_labels') \
            else np.zeros(0, np.int64)
        U = len(self.unlabeled_instants)
        self.row_instants = np.concatenate([
            np.arange(T), self.other_instants,
            np.tile(self.unlabeled_instants, len(self.other_subject_ids))]).astype(np.int64)
        self.row_subjects = np.concatenate([
            np.zeros(T, np.int64), recording.other_subjects,
            np.repeat(self.other_subject_ids, U)]).astype(np.int64)
        # subject 0's unlabelled rows are the instants; subject s's follow row T + J
        self.unlabeled_rows = np.concatenate([
            self.unlabeled_instants,
            T + J + np.arange(U * len(self.other_subject_ids))]).astype(np.int64)
        # the validation rows: subject 0's at the validation instants (the instants' rows),
        # then every other subject labelled there (its row T + j); the holdout's alike
        (self.validation_rows, self.validation_row_labels, self.validation_row_subjects,
         at_validation) = self.scored_rows(self.validation_instants, recording)
        (self.holdout_rows, self.holdout_row_labels, self.holdout_row_subjects,
         at_holdout) = self.scored_rows(self.holdout_instants, source)
        self._framing_boxes = {}
        boxes, rows = self.boxes, None
        if J:       # one more row of crops per other subject
            other_boxes = self.boxes[self.other_instants] if config.box_source in (
                'fixed', 'full') else subject_label_boxes(
                    self.other_labels, self.other_instants, self.boxes, recording.cameras,
                    w_in / h_in, config.box_margin)
            if config.box_source not in ('fixed', 'full'):
                # a validation row is framed without its labels, as subject 0's are: by
                # its subject's crop rule over the other instants' labels (and tracks)
                for j in np.flatnonzero(at_validation | at_holdout):
                    s = int(recording.other_subjects[j])
                    other_boxes[j] = self.framing_boxes(s)[self.other_instants[j]]
            own = [other_boxes]
            for s in self.other_subject_ids:     # subject s's boxes: subject 0's crop rule
                own.append(self.framing_boxes(s)[self.unlabeled_instants])
            boxes = np.concatenate([self.boxes, *own])
            rows = self.row_instants
        self.row_boxes = boxes        # (num_rows, V, 4) px: each crop row's nominal box
        self.cache = CropCache(recording, boxes, input_size, heatmap_size,
                               config.cache_scale, instants=rows)
        # L_T's pairs: the unlabelled row of the same subject at the next instant, -1 none
        key = self.row_subjects[self.unlabeled_rows] * (T + 1) + \
            self.row_instants[self.unlabeled_rows]
        order = np.argsort(key)
        at = np.searchsorted(key[order], key + 1).clip(max=len(key) - 1)
        found = (key[order][at] == key + 1) if len(key) else np.zeros(0, bool)
        self.next_row = np.full(len(self.row_instants), -1, np.int64)
        self.next_row[self.unlabeled_rows[found]] = self.unlabeled_rows[order[at[found]]]

    def scored_rows(self, instants, source):
        """The crop rows that score the labels of `instants` (K,) (validation or holdout),
        every subject's: (rows (M,): the instants for subject 0, then T + j for each other
        labelled (instant, subject) j there; labels (M, V, C, 2) px from `source` (a
        Recording: its labels and other_labels); subjects (M,); at (J,) bool: the other
        rows j among them)."""
        T = self.recording.num_instants
        at = np.isin(self.other_instants, instants) & \
            np.isfinite(source.other_labels[..., 0]).any(axis=(1, 2))
        rows = np.concatenate([instants, T + np.flatnonzero(at)]).astype(np.int64)
        labels = np.concatenate([source.labels[instants], source.other_labels[at]])
        subjects = np.concatenate([np.zeros(len(instants), np.int64),
                                   source.other_subjects[at]]).astype(np.int64)
        return rows, labels, subjects, at

    def framing_boxes(self, subject):
        """(T, V, 4) crop boxes of subject `subject` (>= 1) at every instant: subject 0's
        crop rule (crop_boxes; box_source ground_truth, which is subject 0's, takes the
        labels rule) on subject_labels(subject, framing=True) and, with box_source auto /
        pseudo_labels, its tracks (subject_tracks); an instant without its labels takes the
        nearest instant's box. Computed once per subject."""
        if subject not in self._framing_boxes:
            c = self.config
            h_in, w_in = self.cache_input_size
            source = 'labels' if c.box_source == 'ground_truth' else c.box_source
            tracked = c.box_source in ('auto', 'pseudo_labels')
            self._framing_boxes[subject] = crop_boxes(
                replace(self.recording, labels=self.subject_labels(subject, framing=True)),
                source, w_in / h_in, c.box_margin,
                self.subject_tracks(subject).points if tracked else None)
        return self._framing_boxes[subject]

    def subject_labels(self, subject, framing=False):
        """(T, V, C, 2) px labels of subject `subject` (>= 1) at their instants, NaN elsewhere:
        the train split's (other_labels), or with `framing` the recording's less the
        validation instants (what frames the crops, as subject 0's recording.labels)."""
        source = self.recording.other_labels if framing else self.other_labels
        out = np.full(self.labels.shape, np.nan)
        mine = self.recording.other_subjects == subject
        out[self.other_instants[mine]] = source[mine]
        if framing:
            out[self.validation_instants] = np.nan
        return out

    def subject_tracks(self, subject):
        """tracks() of subject `subject`'s own labels (subject_labels; subject 0: tracks());
        computed once per subject."""
        if subject == 0:
            return self.tracks()
        if subject not in self._subject_tracked:
            self._subject_tracked[subject] = self._track(self.subject_labels(subject))
        return self._subject_tracked[subject]

    @property
    def num_rows(self):
        """Rows of the crop cache: the T instants (subject 0), the J labelled (instant,
        subject) rows of other subjects, then each other subject's unlabelled instants."""
        return len(self.row_instants)

    @property
    def row_labels(self):
        """(num_rows, V, C, 2) px labels of every crop row (NaN: none, e.g. unlabelled rows)."""
        extra = len(self.row_instants) - len(self.labels) - len(self.other_labels)
        return np.concatenate([self.labels, self.other_labels,
                               np.full((extra,) + self.labels.shape[1:], np.nan)])

    def unlabeled_rows_per_subject(self):
        """{subject: number of its unlabelled (instant, subject) rows}, subject 0 first."""
        subjects = self.row_subjects[self.unlabeled_rows]
        return {0: int((subjects == 0).sum()),
                **{int(s): int((subjects == s).sum()) for s in self.other_subject_ids}}

    @property
    def num_other_labelled(self):
        """Labelled (instant, subject) rows of subjects other than 0 in the train split."""
        return int(np.isfinite(self.other_labels[..., 0]).any(axis=(1, 2)).sum())

    def label_points(self, pairs):
        """(N, C, 2) px labels of crop rows x views `pairs` (N, 2): subject 0's labels for a
        row t < T (an instant), the other subject's for a row T + j (other_labels[j])."""
        pairs = np.asarray(pairs, np.int64)
        T, J = self.recording.num_instants, len(self.other_labels)
        row, view = pairs[:, 0], pairs[:, 1]
        own = row < T
        other = ~own & (row < T + J)
        out = np.full((len(pairs),) + self.labels.shape[2:], np.nan)   # unlabelled rows
        out[own] = self.labels[row[own], view[own]]
        out[other] = self.other_labels[row[other] - T, view[other]]
        return out

    @property
    def cameras(self):
        return self.recording.cameras

    def tracked_labels(self):
        """(T, V, C, 2) spatiotemporal pseudo-labels of the train split (labels triangulated,
        tracked config.tracking.horizon frames each way, verified), NaN elsewhere; computed
        once (crop boxes and the temporal modes share it)."""
        return self.tracks().points

    def tracks(self):
        """pseudo_labels.PseudoLabels of tracked_labels over the whole recording (points
        (T, V, C, 2) px, points3d (T, C, 3), frames_from_seed (T, C), agreement (T, V, C)
        px); computed once."""
        if self._tracked is None:
            self._tracked = self._track(self.labels)
        return self._tracked

    def _track(self, labels):
        """The spatiotemporal tracks (PseudoLabels, NaN outside the train split) of one
        subject's train-split labels (T, V, C, 2): triangulated, tracked
        config.tracking.horizon frames each way, verified."""
        T, V, C, _ = labels.shape
        spatial = spatial_pseudo_labels(labels, self.cameras)
        seeds = np.full((len(self.train), C, 3), np.nan)
        seeds[:] = spatial.points3d[self.train]
        frames = _Frames(self.recording, self.train)
        tracked = spatiotemporal_pseudo_labels(frames, self.cameras, seeds,
                                               self.config.tracking)
        points = np.full((T, V, C, 2), np.nan)
        points3d = np.full((T, C, 3), np.nan)
        distance = np.full((T, C), np.inf)
        agreement = np.full((T, V, C), np.nan)
        points[self.train] = tracked.points
        points3d[self.train] = tracked.points3d
        distance[self.train] = tracked.frames_from_seed
        agreement[self.train] = tracked.agreement
        return PseudoLabels(points, points3d, distance, agreement)

    def initial_pseudo_labels(self, spec, tracking):
        """Spatial (and spatiotemporal) pseudo-labels of the train split, (num_rows, V, C, 2)
        px by crop row: each row's from its own subject's labels (subject 0's on the
        instants' rows; subject s's, subject_labels / subject_tracks, on its labelled and
        unlabelled rows), by the same rule and pseudo_max_frames gate (pseudo_gate sums the
        subjects' counts)."""
        if spec.temporal and tracking != self.config.tracking:
            raise ValueError('initial_pseudo_labels: tracking settings differ from the '
                             "data's config")
        T = self.recording.num_instants
        points, gate = self._subject_pseudo(spec, self.labels, self.tracks)
        if self.num_rows == T:
            self.pseudo_gate = gate
            return points
        out = np.full((self.num_rows,) + points.shape[1:], np.nan)
        out[:T] = points
        for s in np.unique(self.row_subjects[T:]):
            mine = self.row_subjects == s
            mine[:T] = False
            own, own_gate = self._subject_pseudo(spec, self.subject_labels(s),
                                                 lambda s=s: self.subject_tracks(s))
            out[mine] = own[self.row_instants[mine]]
            if gate is not None:
                gate = {k: gate[k] + own_gate[k] for k in gate}
        self.pseudo_gate = gate
        return out

    def _subject_pseudo(self, spec, labels, tracks):
        """(points (T, V, C, 2), gate counts or None) of one subject: its labels' spatial
        pseudo-labels, with spec.temporal its tracks (tracks(): PseudoLabels) filling the rest,
        past pseudo_max_frames only where verified; NaN on the held-out and validation
        instants."""
        T, V, C, _ = labels.shape
        points = np.full((T, V, C, 2), np.nan)
        if not spec.spatial:
            return points, None
        spatial = spatial_pseudo_labels(labels, self.cameras)
        points = spatial.points.copy()
        gate_counts = None
        if spec.temporal:
            track = tracks()
            tracked = track.points
            gate = self.config.pseudo_max_frames
            if gate:      # drift: keep the tracks' first frames (the boxes keep all of them)
                far = np.broadcast_to((track.frames_from_seed > gate)[:, None],
                                      tracked.shape[:3])                        # (T, V, C)
                with np.errstate(invalid='ignore'):      # NaN agreement: a single track
                    verified = track.agreement <= self.config.pseudo_agreement_px
                drop = far & ~verified & np.isfinite(tracked[..., 0])
                has = np.isfinite(tracked[..., 0])
                has[self.held_out] = drop[self.held_out] = False
                has[self.validation_instants] = drop[self.validation_instants] = False
                gate_counts = {'tracked': int(has.sum()), 'dropped': int(drop.sum()),
                               'confirmed': int((far & verified & has).sum())}
                tracked = np.where(drop[..., None], np.nan, tracked)
            points = np.where(np.isnan(points), tracked, points)
        points[self.held_out] = np.nan
        points[self.validation_instants] = np.nan
        return points, gate_counts


class _Frames:
    """Indexable view of some instants' images (for optical-flow tracking)."""

    def __init__(self, recording, instants):
        self.recording, self.instants = recording, instants

    def __len__(self):
        return len(self.instants)

    def __getitem__(self, i):
        return self.recording.images(int(self.instants[i]))


def _labelled_peak(heat, points):
    """Median heatmap peak (detached) of the labelled keypoints' maps (heat (N, C, h, w),
    points (N, C, 2) with NaN where unlabelled): the detector's confidence scale on data it
    fits, this step (L_R's cut-off is a share of it); None when nothing is labelled."""
    labelled = torch.as_tensor(np.isfinite(points[..., 0]), device=heat.device)
    if not bool(labelled.any()):
        return None
    return float(heat.detach().float().amax(dim=(-2, -1))[labelled].median())


def _fmt(value):
    return 'n/a' if value is None else f'{value:.3g}'


def _stderr_warning(message):
    tqdm.write(f'WARNING: {message}', file=sys.stderr)       # above a running progress bar


def _atomic_torch_save(payload, path):
    with atomic_write(path) as stream:
        torch.save(payload, stream)


def _read_state(path):
    """The dict of a trainer_state.pt (FileNotFoundError, or ValueError naming the file: a
    corrupt file, one holding pickled objects (refused, never loaded unsafely), another
    format)."""
    from monet_ros.models.checkpoint import torch_load_problem
    try:
        state = torch.load(path, map_location='cpu', weights_only=True)
    except FileNotFoundError:
        raise FileNotFoundError(f'{path}: no trainer state to resume from') from None
    except Exception as error:  # noqa: BLE001 - corrupt, truncated or pickled objects
        raise ValueError(f'{path}: {torch_load_problem(error, "monet trainer state")}') \
            from error
    if not isinstance(state, dict) or state.get('format') != STATE_FORMAT:
        raise ValueError(f'{path}: field format is not {STATE_FORMAT!r}')
    return state


def saved_skeleton(out_dir, state=None):
    """(skeleton name or None, keypoint names or None) of the run saved in out_dir: from its
    trainer_state.pt, else (a state written before it recorded them) the keypoints of its
    model.pt; (None, None) when neither says. state: the loaded trainer_state.pt dict."""
    out_dir = Path(out_dir)
    if state is None:
        state = _read_state(out_dir / 'trainer_state.pt')
    if 'keypoints' in state:
        return json.loads(state.get('skeleton', 'null')), list(json.loads(state['keypoints']))
    from monet_ros.models.checkpoint import read_checkpoint
    try:
        return None, list(read_checkpoint(out_dir / 'model.pt')[0]['keypoints'])
    except Exception:  # noqa: BLE001 - no readable model.pt: the weights' shapes will say
        return None, None


def check_resume_keypoints(out_dir, keypoints, skeleton_name=None, state=None):
    """ValueError (one line naming both skeletons) when the run saved in out_dir trained
    other keypoints than `keypoints` (names, in heatmap channel order): checked before any
    network is built, so no weight shapes are compared."""
    saved_name, saved = saved_skeleton(out_dir, state)
    if saved is None or list(saved) == list(keypoints):
        return

    def named(name, names):
        shown = ', '.join(names[:6]) + (', ...' if len(names) > 6 else '')
        return f'{name + " " if name else ""}({len(names)} keypoints: {shown})'
    raise ValueError(f'{Path(out_dir) / "trainer_state.pt"}: --resume: the saved run trained '
                     f'skeleton {named(saved_name, list(saved))}, this run has skeleton '
                     f'{named(skeleton_name, list(keypoints))}; give the same --skeleton or '
                     'a new --out')


class Trainer:
    """Semi-supervised trainer of one detector on one TrainingData.

    out_dir (optional): checkpoints/step_NNNNNN.pt (models.save_checkpoint), model.pt (the
    latest weights), trainer_state.pt (everything needed to resume) and train_log.csv.
    """

    def __init__(self, config, data, out_dir=None, model=None, device=None, warn=None):
        if not isinstance(config, TrainConfig):
            raise TypeError('config must be a TrainConfig')
        self.config = config
        self.spec = config.spec
        self.data = data
        self.device = torch.device(device) if device is not None else pick_device(config.device)
        check_training_precision(config.precision, self.device)
        # auto -> bfloat16 where native on the device, else float32 (the inference rule)
        self.precision, self.precision_note = resolve_precision(config.precision, 'torch',
                                                                self.device)
        self.out_dir = Path(out_dir) if out_dir is not None else None
        torch.manual_seed(config.seed)
        self.keypoints = list(data.recording.keypoints)
        self.skeleton_name = None      # the skeleton's name, kept in trainer_state.pt
        if model is None:
            model = build_model(config.architecture, len(self.keypoints),
                                **config.model_options())
        self.model = model.to(self.device)
        self.optimizer = torch.optim.Adam(self.model.parameters(), lr=config.lr)
        self.scheduler = torch.optim.lr_scheduler.LambdaLR(
            self.optimizer, lambda step: config.lr_factor(step))
        self.rng = np.random.default_rng(config.seed)
        self.step_count = 0
        self.bootstrap_done = 0
        self.heatmap_size = tuple(self.model.heatmap_size)
        self.pseudo = data.initial_pseudo_labels(self.spec, config.tracking)
        self._update_pools()
        self.last_terms = {}
        self.last_plan = None            # the latest step's batch plan (see batch_plan)
        self.last_pair_share = None      # share of L_E's (pair, keypoint) terms used, latest
        # L_E starts at the first step after the warm-up whose labelled crops the detector
        # fits (epipolar_fit_heat_px); latched, saved with the state
        self.epipolar_started = None
        # distillation (learning.distill): the round trained now (0: none yet) and its
        # pseudo-labels (num_rows, V, C, 2) px with weights (num_rows, V, C) by crop row
        # (each row's own subject's); set_distilled
        self.distill_round = 0
        self.distilled = None
        self.distilled_weight = None
        self.distill_pool = np.zeros((0, 2), np.int64)
        self.last_checkpoint = None      # path of the latest checkpoints/step_N.pt written
        self._started = time.monotonic()
        self.warnings = []
        self._warn_sink = warn if warn is not None else _stderr_warning
        self.bootstrap_stats = []
        self._warn_missing_data()

    # ----------------------------------------------------------------- warnings
    def warn(self, message):
        """Record a warning (run summary `warnings`) and say it (stderr by default)."""
        self.warnings.append(message)
        self._warn_sink(message)

    def _warn_missing_data(self):
        spec, c = self.spec, self.config
        others = spec.unlabeled and (c.lambda_e or c.lambda_t or c.lambda_r)
        if (spec.spatial or spec.temporal) and spec.bootstrap_rounds == 0 and \
                c.lambda_p > 0 and len(self.pseudo_pool) == 0:
            self.warn(f'mode {c.mode}: no pseudo-labels (spatial: no keypoint labelled in 2 '
                      'views of an instant that has another view to label; spatiotemporal: no '
                      f'track verified in track_min_views {c.track_min_views} views): L_B gets '
                      'no data' + ('' if others else ', this run is supervised only'))
        unlabeled = len(self.data.unlabeled_instants)
        for on, weight, term, name in (
                (spec.epipolar, c.lambda_e, 'L_E', 'the anchored epipolar term'),
                (spec.temporal_difference, c.lambda_t, 'L_T', 'the temporal-difference loss'),
                (spec.reprojection, c.lambda_r, 'L_R', 'the reprojection-consistency loss')):
            if not (on and weight > 0):
                continue
            if unlabeled == 0:
                self.warn(f'mode {c.mode}: no unlabeled instant in the training split: {name} '
                          f'{term} gets no data')
            elif c.batch_unlabeled == 0:
                self.warn(f'mode {c.mode}: batch_unlabeled 0: {name} {term} gets no data')
        if spec.temporal_difference and c.lambda_t > 0 and unlabeled and c.batch_unlabeled:
            if len(self._consecutive()) == 0:
                self.warn(f'mode {c.mode}: no two consecutive unlabeled instants in the '
                          'training split: the temporal-difference loss L_T gets no data')
            elif c.batch_unlabeled < 2:
                self.warn(f'mode {c.mode}: batch_unlabeled {c.batch_unlabeled} < 2: L_T needs '
                          'pairs of consecutive instants, it gets no data')
        k = self.views_per_instant()
        if spec.reprojection and c.lambda_r > 0 and unlabeled and c.batch_unlabeled and \
                k < c.bootstrap_min_views:
            self.warn(f'mode {c.mode}: L_R triangulates from bootstrap_min_views '
                      f'{c.bootstrap_min_views} inlier views but gets {k} views of each '
                      f'unlabeled instant (views_per_instant {c.views_per_instant}, '
                      f'{self.data.recording.num_views} cameras): it gets no data')

    def objective_text(self):
        """The loss of this run in words, e.g. 'L_L + 1 L_B + 1 L_R from step 600' (terms of
        weight 0 left out)."""
        spec, c = self.spec, self.config
        parts = ['L_L']
        if self.spec_uses_pseudo and c.lambda_p:
            parts.append(f'{c.lambda_p:g} L_B')
        start = int(round(c.epipolar_warmup * c.steps))
        for on, weight, term in ((spec.epipolar, c.lambda_e, 'L_E'),
                                 (spec.temporal_difference, c.lambda_t, 'L_T'),
                                 (spec.reprojection, c.lambda_r, 'L_R')):
            if on and weight:
                when = f' from step {start}' if start else ''
                if term == 'L_E':
                    when += (' once the detector fits its labelled crops (median <= '
                             f'{c.epipolar_fit_heat_px:g} heatmap px)')
                parts.append(f'{weight:g} {term}' + when)
        return ' + '.join(parts)

    # ----------------------------------------------------------------- sampling
    def _update_pools(self):
        # (N, 2) (crop row, view): the instants' (subject 0), then the other subjects' rows
        # T + j and their unlabelled rows (TrainingData); a single-subject table gives the
        # instants' pools alone
        labelled = np.isfinite(self.data.row_labels[..., 0])          # (num_rows, V, C)
        pseudo = np.isfinite(self.pseudo[..., 0]) & ~labelled
        self.pseudo_only = np.where(pseudo[..., None], self.pseudo, np.nan)
        self.labelled_pool = np.argwhere(labelled.any(axis=2)).astype(np.int64)
        self.pseudo_pool = np.argwhere(pseudo.any(axis=2))
        if self.labelled_pool.size == 0:
            raise ValueError('no labelled view in the training split')

    def set_distilled(self, points, weight, round_index):
        """Start distillation round `round_index` (1-based) with its pseudo-labels: points
        (R, V, C, 2) source px (NaN = none) and weight (R, V, C) (learning.distill.Distilled)
        by crop row (R = data.num_rows: each row's are its own subject's, TrainingData; R = T
        with one subject); labelled cells and rows of instants outside the training pools
        (held out, validation) never get one. Its crops are the plan's 'D' part from the next
        step (batch_distill)."""
        _, V, C, _ = self.data.labels.shape
        R = self.data.num_rows
        points = np.array(points, np.float64)
        weight = np.array(weight, np.float64)
        if points.shape != (R, V, C, 2) or weight.shape != (R, V, C):
            raise ValueError(f'set_distilled: points must be {(R, V, C, 2)} and weight '
                             f'{(R, V, C)}, got {points.shape} and {weight.shape}')
        off = np.isfinite(self.data.row_labels[..., 0]) | ~np.isfinite(weight) | (weight <= 0)
        out = np.isin(self.data.row_instants, np.union1d(self.data.held_out,
                                                         self.data.validation_instants))
        off[out] = True
        points[off] = np.nan
        weight[off] = 0.0
        self.distilled, self.distilled_weight = points, weight
        self.distill_round = int(round_index)
        self.distill_pool = np.argwhere(np.isfinite(points[..., 0]).any(axis=2))

    @property
    def distilled_count(self):
        """Distilled pseudo-labels of the current round (view x keypoint cells)."""
        return 0 if self.distilled is None else int(np.isfinite(self.distilled[..., 0]).sum())

    @property
    def pseudo_label_count(self):
        return int(np.isfinite(self.pseudo_only[..., 0]).sum())

    @property
    def pseudo_label_coverage(self):
        """Share of the unlabeled training (view, keypoint) cells that hold a pseudo-label
        (every subject's unlabelled rows)."""
        cells = self.pseudo_only[self.data.unlabeled_rows, ..., 0]
        return float(np.isfinite(cells).mean()) if cells.size else 0.0

    def _sample(self, pool, n):
        idx = self.rng.choice(len(pool), size=n, replace=len(pool) < n)
        return pool[idx]

    def views_per_instant(self):
        """Views of each unlabeled instant in L_E's part: views_per_instant, 0 = all."""
        V = self.data.recording.num_views
        return V if self.config.views_per_instant == 0 else min(self.config.views_per_instant, V)

    def _consecutive(self):
        """(P,) unlabeled rows whose subject's row at the next instant is unlabeled too (L_T's
        pairs; TrainingData.next_row)."""
        u = self.data.unlabeled_rows
        return u[self.data.next_row[u] >= 0]

    def _unlabeled_part(self, n_inst, k):
        """The part of n_inst unlabeled rows x k views: (kind, (n_inst k, 2) pairs, k);
        kind 'E' (L_E) or 'U' (L_T / L_R). A row is an unlabelled (instant, subject)
        (TrainingData.unlabeled_rows: the instant itself for subject 0), its views cropped
        around that subject. For L_T the rows come as consecutive pairs (t, t + 1 of the same
        subject, same views; an odd last one alone)."""
        V = self.data.recording.num_views
        unlabeled = self.data.unlabeled_rows
        consecutive = self._consecutive() if self.spec.temporal_difference else unlabeled[:0]
        if len(consecutive):
            first = self.rng.choice(consecutive, size=n_inst // 2,
                                    replace=len(consecutive) < n_inst // 2)
            inst = np.stack([first, self.data.next_row[first]], axis=1).ravel()
            if n_inst % 2:
                inst = np.append(inst, self.rng.choice(unlabeled))
            views = [self.rng.choice(V, size=k, replace=False) for _ in range(len(first))]
            views = np.stack([v for v in views for _ in (0, 1)] +
                             [self.rng.choice(V, size=k, replace=False)] * (n_inst % 2))
        else:
            inst = self.rng.choice(unlabeled, size=n_inst, replace=len(unlabeled) < n_inst)
            views = np.stack([self.rng.choice(V, size=k, replace=False) for _ in inst])
        pairs = np.stack([np.repeat(inst, k), views.ravel()], axis=1)
        # 'U': L_T / L_R (+ L_E with them); 'E': L_E alone. A mode with L_E added to L_R
        # draws the plan of L_R's mode: lambda_e = 0 is that mode's exact control
        alone = self.spec.epipolar and not (self.spec.temporal_difference or
                                            self.spec.reprojection)
        return ('E' if alone else 'U', pairs, k)

    def _batch_plan(self):
        """The (instant, view) crops of one step: parts ('L', pairs), ('B', pairs),
        ('E' or 'U', pairs, views per instant), pairs (N, 2) int (instant, view); each step's
        plan is kept as `last_plan`. The plan depends on the mode, the batch sizes, the step
        and the RNG only, never on the weights (lambda_e, lambda_p, lambda_t, lambda_r): a run
        with a term's weight 0 draws the same crops (its exact control). Every mode sees the
        same number of images per step, batch_labelled + batch_pseudo + batch_unlabeled x
        views: a part a mode does not use (or cannot fill yet: no pseudo-labels, L_E in its
        warm-up) gives its share to pseudo-labels when the mode has some, else to labels."""
        c = self.config
        k = self.views_per_instant()
        total = c.batch_labelled + c.batch_pseudo + c.batch_unlabeled * k
        n_inst = c.batch_unlabeled if (self.unlabeled_active and
                                       len(self.data.unlabeled_rows)) else 0
        use_b = self.spec_uses_pseudo and c.batch_pseudo and len(self.pseudo_pool)
        n_b = (total - c.batch_labelled - n_inst * k) if use_b else 0
        parts = [('L', self._sample(self.labelled_pool, total - n_b - n_inst * k))]
        if n_b:
            parts.append(('B', self._sample(self.pseudo_pool, n_b)))
        if n_inst:
            parts.append(self._unlabeled_part(n_inst, k))
        # a distillation round adds batch_distill crops of its pseudo-labels (also at
        # lambda_d = 0: the round's exact control draws them too)
        if self.distilled is not None and c.batch_distill and len(self.distill_pool):
            parts.append(('D', self._sample(self.distill_pool, c.batch_distill)))
        return parts

    @property
    def unlabeled_active(self):
        """The loss on unlabeled instants (L_E, L_T or L_R) is on: a mode with one, past the
        warm-up (epipolar_warmup x steps trained with L_L + L_B only)."""
        return self.spec.unlabeled and \
            self.step_count >= int(round(self.config.epipolar_warmup * self.config.steps))

    @property
    def spec_uses_pseudo(self):
        return self.spec.uses_pseudo

    # ----------------------------------------------------------------- losses
    def _terms(self, parts, rng, augment):
        """Loss terms of one batch plan: list of (kind, (N, 2) (instant, view) pairs[, views
        per instant for 'E'], kind in 'L' (labels), 'B' (pseudo-labels), 'E' (epipolar)."""
        pairs = np.concatenate([p[1] for p in parts])
        batch = self.data.cache.views(pairs[:, 0], pairs[:, 1], rng, augment)
        with self.autocast():
            stages = self.forward_batch(batch.images.to(self.device, non_blocking=True))
        stages = [s.float() for s in stages]     # the losses in float32 (no-op in float32)
        terms = {}
        start = 0
        labelled_peak = None
        for kind, p, *rest in parts:
            n = len(p)
            sl = slice(start, start + n)
            if kind in ('L', 'B'):
                heat_pts = batch.to_heatmap(self.data.label_points(p) if kind == 'L' else
                                            self.pseudo_only[p[:, 0], p[:, 1]], sl)
                terms[kind] = masked_heatmap_mse([s[sl] for s in stages], heat_pts,
                                                 self.config.sigma)
                if kind == 'L' and (self.spec.reprojection or self.spec.epipolar):
                    # L_R's / L_E's cut-off (a host sync)
                    labelled_peak = _labelled_peak(stages[-1][sl], heat_pts)
                if kind == 'L' and self.spec.epipolar and self.epipolar_started is None \
                        and rng is not None and self.unlabeled_active:
                    self._check_epipolar_start(stages[-1][sl], heat_pts)
            elif kind == 'D':
                heat_pts = batch.to_heatmap(self.distilled[p[:, 0], p[:, 1]], sl)
                terms['D'] = masked_heatmap_mse([s[sl] for s in stages], heat_pts,
                                                self.config.sigma,
                                                self.distilled_weight[p[:, 0], p[:, 1]])
            elif kind == 'U':
                terms.update(self._unlabeled_terms([s[sl] for s in stages], batch, sl, p,
                                                   rest[0], labelled_peak))
            else:
                terms.update(self._epipolar_terms(stages[-1][sl], batch, sl, rest[0],
                                                  labelled_peak, rng is None))
            start += n
        return terms

    def anchor_cutoff(self, labelled_peak):
        """The least heatmap peak of a view that anchors L_E or votes in L_R's consensus:
        the larger of bootstrap_confidence and bootstrap_relative_confidence x the median
        peak of the step's labelled views (labelled_peak; None: the absolute floor only)."""
        c = self.config
        return max(c.bootstrap_confidence, c.bootstrap_relative_confidence *
                   (labelled_peak if labelled_peak is not None else 0.0))

    def _check_epipolar_start(self, heat, points):
        """Start L_E (latched) once the detector fits the step's labelled crops: the median
        distance of their peaks to their labels is at most epipolar_fit_heat_px (heatmap px).
        Before that its anchors would be a detector's guesses."""
        peaks, _ = decode_heatmaps(heat.detach().float())
        err = torch.linalg.norm(peaks.cpu().double() - torch.as_tensor(points).double().cpu(),
                                dim=-1)
        err = err[torch.isfinite(err)]
        if err.numel() and float(err.median()) <= self.config.epipolar_fit_heat_px:
            self.epipolar_started = self.step_count

    def _epipolar_terms(self, heat, batch, sl, k, labelled_peak, always=False):
        """{'E': L_E} of a part of instants x k views (heat (N, C, h, w) raw last-stage maps,
        batch[sl] their geometry): losses.epipolar_loss anchored at anchor_cutoff; {} before
        L_E has started (unless `always`: evaluation)."""
        if not (always or self.epipolar_started is not None):
            return {}
        n = heat.shape[0]
        B = n // k
        f32 = dict(dtype=torch.float32, device=heat.device)
        K = torch.as_tensor(batch.K[sl], **f32).reshape(B, k, 3, 3)
        R = torch.as_tensor(batch.R[sl], **f32).reshape(B, k, 3, 3)
        t = torch.as_tensor(batch.t[sl], **f32).reshape(B, k, 3)
        e = anchored_epipolar_terms(heat.reshape(B, k, *heat.shape[1:]), K, R, t,
                                    anchor_confidence=self.anchor_cutoff(labelled_peak),
                                    kernel_px=self.config.epipolar_kernel_px,
                                    agreement_px=self.config.epipolar_agreement_px)
        self.last_pair_share = float(e['used'].float().mean()) if e['used'].numel() else 0.0
        return {'E': reduce_anchored_terms(e, heat)}

    def _unlabeled_terms(self, stages, batch, sl, pairs, k, labelled_peak):
        """L_T and / or L_R of the 'U' part: stages (N, C, h, w) of its crops, batch[sl] their
        geometry, pairs (N, 2) (instant, view), k views per instant."""
        spec, c = self.spec, self.config
        terms = {}
        heat = stages[-1]
        if spec.temporal_difference:
            # consecutive pairs (t, t + 1) of k views each: both frames' soft-argmax in the
            # heatmap px of t's crop (the crops differ: their own box and augmentation)
            n_inst = len(pairs) // k
            n_pairs = n_inst // 2 if len(self._consecutive()) else 0
            if n_pairs:
                A = torch.as_tensor(batch.A[sl], dtype=torch.float64, device=heat.device)
                mean = soft_argmax(heat)                                       # (N, C, 2)
                grid = mean.reshape(n_inst, k, *mean.shape[1:])
                A = A.reshape(n_inst, k, 3, 3)
                now, nxt = grid[0:2 * n_pairs:2], grid[1:2 * n_pairs:2]
                A_now, A_nxt = A[0:2 * n_pairs:2], A[1:2 * n_pairs:2]
                M = A_now @ torch.linalg.inv(A_nxt)                # next crop -> this crop
                nxt = (M[..., None, :2, :2] @ nxt[..., None])[..., 0] + M[..., None, :2, 2]
                terms['T'] = temporal_difference_loss(now.flatten(0, 1), nxt.flatten(0, 1),
                                                      c.temporal_epsilon).float()
            else:
                terms['T'] = heat.sum() * 0.0
        if spec.reprojection:
            terms['R'] = masked_heatmap_mse(stages, self._reprojection_targets(
                heat, batch, sl, pairs, k, labelled_peak), c.sigma)
        if spec.epipolar:
            terms.update(self._epipolar_terms(heat, batch, sl, k, labelled_peak))
        return terms

    def _reprojection_targets(self, heat, batch, sl, pairs, k, labelled_peak):
        """(N, C, 2) heatmap px targets of L_R (NaN: none): each instant's detections in its
        k views (peaks of at least bootstrap_cutoff's share of the step's labelled peak),
        RANSAC-triangulated (bootstrap_threshold_px, bootstrap_min_views) and reprojected into
        each view (pseudo_labels.bootstrap_pseudo_labels, as a bootstrapping round, online)."""
        c = self.config
        peaks, conf = decode_heatmaps(heat.detach().float())
        A_inv = np.linalg.inv(batch.A[sl])
        points = np.einsum('nij,ncj->nci', A_inv[:, :2, :2], peaks.cpu().numpy()) + \
            A_inv[:, None, :2, 2]
        V, C = self.data.recording.num_views, heat.shape[1]
        n_inst = len(pairs) // k
        det = np.full((n_inst, V, C, 2), np.nan)
        score = np.zeros((n_inst, V, C))
        row = np.repeat(np.arange(n_inst), k)
        det[row, pairs[:, 1]] = points
        score[row, pairs[:, 1]] = conf.cpu().numpy()
        cutoff = self.anchor_cutoff(labelled_peak)
        boot = bootstrap_pseudo_labels(det, score, self.data.cameras, cutoff,
                                       c.bootstrap_threshold_px, c.bootstrap_min_views)
        return batch.to_heatmap(boot.points[row, pairs[:, 1]], sl)

    def autocast(self):
        """The context of the training forward: torch.autocast to bfloat16 when
        the precision run (config.precision, auto resolved) is bfloat16 (weights, gradients
        and Adam stay float32), else none.
        Detections (detect: bootstrapping, fit_error) run in float32."""
        return torch.autocast(self.device.type, dtype=torch.bfloat16,
                              enabled=self.precision == 'bfloat16')

    def forward_batch(self, images):
        """The network's stages on a batch of crops (B, 3, H, W); learning.distributed
        replaces it with a rank's share of the batch + all-gather."""
        return self.model(images)

    def step(self):
        """One optimisation step; returns the loss terms as floats (and runs a bootstrapping
        round or writes a checkpoint when the schedule says so)."""
        c = self.config
        self.model.train()
        parts = self._batch_plan()
        self.last_plan = parts
        terms = self._terms(parts, self.rng, c.augment)
        loss = objective(terms, c.lambda_e, c.lambda_p, c.lambda_t, c.lambda_r, c.lambda_d)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        lr = self.optimizer.param_groups[0]['lr']
        self.scheduler.step()
        self.step_count += 1
        out = {'step': self.step_count, 'loss': float(loss.detach()), 'lr': lr}
        out.update({k: float(v.detach()) for k, v in terms.items()})
        if 'E' in terms:
            out['E_pair_share'] = self.last_pair_share
        self.last_terms = out
        self._log(out)
        if self.bootstrap_due():
            self.bootstrap()
        if self.out_dir is not None and (self.step_count % c.checkpoint_every == 0
                                         or self.step_count == c.steps):
            self.save()
        return out

    @torch.no_grad()
    def evaluate_terms(self, num=8, seed=12345):
        """Loss terms on a fixed batch (no augmentation, no update, eval mode): comparable
        between steps; uses `num` samples of each part."""
        saved = self.rng
        self.rng = np.random.default_rng(seed)
        try:
            parts = [('L', self._sample(self.labelled_pool, num))]
            if len(self.pseudo_pool):
                parts.append(('B', self._sample(self.pseudo_pool, num)))
            if len(self.data.unlabeled_instants):
                k = self.views_per_instant()
                n = max(2 if self.spec.temporal_difference else 1, num // k)
                if self.spec.unlabeled:
                    parts.append(self._unlabeled_part(n, k))
                else:     # L_E's value for every other mode (how epipolar its maps are)
                    V = self.data.recording.num_views
                    inst = self.rng.choice(self.data.unlabeled_rows, size=n)
                    views = np.stack([self.rng.choice(V, size=k, replace=False) for _ in inst])
                    parts.append(('E', np.stack([np.repeat(inst, k), views.ravel()], axis=1),
                                  k))
        finally:
            self.rng = saved
        self.model.eval()
        terms = self._terms(parts, None, None)
        self.model.train()
        return {k: float(v) for k, v in terms.items()}

    @torch.no_grad()
    def validate(self, instants=None, max_instants=16):
        """Validation of the current weights, for the online learner's model selection.

        On some instants (default: the held-out split, at most max_instants evenly spread),
        without labels: mean epipolar divergence over all views (`epipolar_divergence`) and
        the reprojection error (px) of the all-view triangulation of the detections
        (`reprojection_px`, `reprojection_std_px`): agreement between views, not accuracy.
        When the data holds validation labels (config.validation_labels): the error of the
        detections on every validation instant against those labels (validation_error's
        overall figure, every subject's, original image px): `labelled_median_px`,
        `labelled_mean_px`, `labelled_keypoints`. Returns {} when there is no instant to
        validate on."""
        labelled = {}
        if len(self.data.validation_instants):
            err = self.validation_error()
            labelled = {'labelled_median_px': err['median_px'],
                        'labelled_mean_px': err['mean_px'], 'labelled_keypoints': err['count']}
        if instants is None:
            held = self.data.held_out
            instants = held[np.linspace(0, len(held) - 1, min(max_instants, len(held)))
                            .round().astype(int)] if len(held) else held
        instants = np.asarray(instants, dtype=np.int64)
        if instants.size == 0:
            return labelled
        points, _ = self.detect(instants)
        reproj = multiview_reprojection(points, self.data.cameras).consistency_stats
        V = self.data.recording.num_views
        pairs = np.stack(np.meshgrid(instants, np.arange(V), indexing='ij'), -1).reshape(-1, 2)
        was_training = self.model.training
        self.model.eval()
        batch = self.data.cache.views(pairs[:, 0], pairs[:, 1])
        heat = self.model(batch.images.to(self.device))[-1].float()
        self.model.train(was_training)
        f32 = dict(dtype=torch.float32, device=heat.device)
        n = len(instants)
        # the symmetric form as a score of agreement (as before issue 36), not the loss
        divergence = symmetric_epipolar_loss(
            heat.reshape(n, V, *heat.shape[1:]),
            torch.as_tensor(batch.K, **f32).reshape(n, V, 3, 3),
            torch.as_tensor(batch.R, **f32).reshape(n, V, 3, 3),
            torch.as_tensor(batch.t, **f32).reshape(n, V, 3))
        return {'epipolar_divergence': float(divergence), 'reprojection_px': reproj.mean,
                'reprojection_std_px': reproj.std, 'instants': int(instants.size), **labelled}

    # ----------------------------------------------------------------- bootstrapping
    def bootstrap_steps(self):
        r = self.spec.bootstrap_rounds
        return [int(round(self.config.steps * (k + 1) / (r + 1))) for k in range(r)]

    def bootstrap_due(self):
        sched = self.bootstrap_steps()
        return self.bootstrap_done < len(sched) and self.step_count >= sched[self.bootstrap_done]

    @torch.no_grad()
    def detect(self, instants, chunk=64):
        """Detections of every view of `instants` on the cached crops (no augmentation).

        Returns (points (N, V, C, 2) original image pixels, confidence (N, V, C))."""
        instants = np.asarray(instants, dtype=np.int64)
        V = self.data.recording.num_views
        pairs = np.stack(np.meshgrid(instants, np.arange(V), indexing='ij'), -1).reshape(-1, 2)
        C = len(self.keypoints)
        points = np.empty((len(pairs), C, 2))
        conf = np.empty((len(pairs), C))
        was_training = self.model.training
        self.model.eval()
        for s in range(0, len(pairs), chunk):
            p = pairs[s:s + chunk]
            batch = self.data.cache.views(p[:, 0], p[:, 1])
            heat = self.model(batch.images.to(self.device))[-1].float().cpu()
            peaks, c = decode_heatmaps(heat)
            A_inv = np.linalg.inv(batch.A)
            pk = peaks.numpy().astype(np.float64)
            points[s:s + chunk] = np.einsum('nij,ncj->nci', A_inv[:, :2, :2], pk) + \
                A_inv[:, None, :2, 2]
            conf[s:s + chunk] = c.numpy()
        self.model.train(was_training)
        return points.reshape(len(instants), V, C, 2), conf.reshape(len(instants), V, C)

    def labelled_peaks(self):
        """(N,) heatmap peak values of the detector at the labelled keypoints of the labelled
        views (no augmentation): its confidence scale on data it was trained on."""
        inst = self.data.labelled_instants
        _, conf = self.detect(inst)
        return conf[np.isfinite(self.data.labels[inst][..., 0])]

    def bootstrap_cutoff(self):
        """(cut-off, median labelled peak): the minimum heatmap peak of a bootstrapped
        detection, the larger of bootstrap_confidence and bootstrap_relative_confidence x the
        median peak on the labelled views."""
        peaks = self.labelled_peaks()
        median = float(np.median(peaks)) if peaks.size else float('nan')
        relative = self.config.bootstrap_relative_confidence * median if peaks.size else 0.0
        return max(self.config.bootstrap_confidence, relative), median

    def bootstrap(self):
        """One round: detect on the unlabeled train rows (every subject's: TrainingData.
        unlabeled_rows), keep confident views (peak at least bootstrap_cutoff()),
        RANSAC-triangulate, reproject -> pseudo-labels (replacing the previous round's);
        warns when the round keeps nothing."""
        c = self.config
        inst = self.data.unlabeled_rows
        det, conf = self.detect(inst)
        cutoff, median = self.bootstrap_cutoff()
        boot = bootstrap_pseudo_labels(det, conf, self.data.cameras, cutoff,
                                       c.bootstrap_threshold_px, c.bootstrap_min_views)
        stats = {'round': self.bootstrap_done + 1, 'step': self.step_count,
                 'cutoff': cutoff, 'median_labelled_peak': median,
                 'median_unlabeled_peak': float(np.median(conf)) if conf.size else None,
                 'confident_views': int((conf >= cutoff).sum()), 'pseudo_labels': boot.count}
        self.bootstrap_stats.append(stats)
        if boot.count == 0 and c.lambda_p > 0:
            self.warn(f'bootstrapping round {stats["round"]} (step {self.step_count}) kept no '
                      f'pseudo-label: {stats["confident_views"]} detections reached the cut-off '
                      f'{cutoff:.3g} (median peak {median:.3g} on labelled views, '
                      f'{_fmt(stats["median_unlabeled_peak"])} on unlabeled ones) and none '
                      f'agreed in '
                      f'{c.bootstrap_min_views} views within {c.bootstrap_threshold_px} px: L_B '
                      'gets no bootstrapped data this round')
        base = self.data.initial_pseudo_labels(self.spec, c.tracking)
        base[inst] = np.where(np.isfinite(base[inst]), base[inst], boot.points)
        self.pseudo = base
        self.bootstrap_done += 1
        self._update_pools()
        return PseudoLabels(boot.points, boot.points3d)

    # ----------------------------------------------------------------- persistence
    def metadata(self):
        return {'keypoints': self.keypoints, 'step': self.step_count,
                'metrics': {k: v for k, v in self.last_terms.items() if k != 'step'},
                'mode': self.config.mode, 'train_config': self.config.to_dict(),
                'recording': self.data.recording.name,
                'held_out_from_stamp_ns': int(self.data.recording.stamps[self.data.held_out[0]])
                if len(self.data.held_out) else None}

    def save(self):
        """Write checkpoints/step_N.pt, model.pt and trainer_state.pt (each atomic)."""
        if self.out_dir is None:
            raise ValueError('Trainer.save: no out_dir')
        meta = self.metadata()
        ckpt = self.out_dir / 'checkpoints' / f'step_{self.step_count:06d}.pt'
        save_checkpoint(ckpt, self.model, meta)
        save_checkpoint(self.out_dir / 'model.pt', self.model, meta)
        state = {
            'format': STATE_FORMAT,
            'config': json.dumps(self.config.to_dict()),
            'step': self.step_count,
            'bootstrap_done': self.bootstrap_done,
            'epipolar_started': json.dumps(self.epipolar_started),
            'model': {k: v.detach().cpu() for k, v in self.model.state_dict().items()},
            'optimizer': self.optimizer.state_dict(),
            'scheduler': self.scheduler.state_dict(),
            'numpy_rng': json.dumps(self.rng.bit_generator.state),
            'torch_rng': torch.get_rng_state(),
            'pseudo': torch.from_numpy(self.pseudo.astype(np.float64)),
            'last_terms': json.dumps(self.last_terms),
            'keypoints': json.dumps(list(self.keypoints)),
            'skeleton': json.dumps(self.skeleton_name),
            'distill_round': self.distill_round,
        }
        if self.distilled is not None:
            state['distilled'] = torch.from_numpy(self.distilled)
            state['distilled_weight'] = torch.from_numpy(self.distilled_weight)
        _atomic_torch_save(state, self.out_dir / 'trainer_state.pt')
        self.last_checkpoint = ckpt
        return ckpt

    @classmethod
    def resume(cls, out_dir, data, config=None, device=None, model=None):
        """A trainer continuing from out_dir/trainer_state.pt (config: the saved one unless
        given; only `steps`, `checkpoint_every`, `device` and `precision` may differ; model:
        the network to load the saved weights into, default one built from the config)."""
        path = Path(out_dir) / 'trainer_state.pt'
        state = _read_state(path)
        check_resume_keypoints(out_dir, data.recording.keypoints, state=state)
        saved = TrainConfig.from_dict(json.loads(state['config']), str(path))
        if config is None:
            config = saved
        else:
            for name, value in saved.to_dict().items():
                if name not in ('steps', 'checkpoint_every', 'device', 'precision') and \
                        getattr(config, name) != value:
                    raise ValueError(f'{path}: config field {name} is {value!r} in the saved '
                                     f'state but {getattr(config, name)!r} now')
        for stale in Path(out_dir).rglob('.*.tmp'):      # temporaries of a killed write
            stale.unlink()
        trainer = cls(config, data, out_dir, model=model, device=device)
        trainer.model.load_state_dict(state['model'])
        trainer.optimizer.load_state_dict(state['optimizer'])
        trainer.scheduler.load_state_dict(state['scheduler'])
        trainer.step_count = int(state['step'])
        trainer.bootstrap_done = int(state['bootstrap_done'])
        trainer.epipolar_started = json.loads(state.get('epipolar_started', 'null'))
        trainer.rng.bit_generator.state = json.loads(state['numpy_rng'])
        torch.set_rng_state(state['torch_rng'])
        pseudo = state['pseudo'].numpy().copy()
        if pseudo.shape != trainer.pseudo.shape:
            raise ValueError(f'{path}: field pseudo holds pseudo-labels of {pseudo.shape[0]} '
                             f'crop rows, this data has {trainer.pseudo.shape[0]} (other labels, '
                             'subjects, or a run saved before each subject had its own '
                             'unlabelled rows): give the same labels or a new --out')
        trainer.pseudo = pseudo
        trainer._update_pools()
        if 'distilled' in state:
            trainer.set_distilled(state['distilled'].numpy(), state['distilled_weight'].numpy(),
                                  int(state.get('distill_round', 1)))
        trainer.last_terms = json.loads(state['last_terms'])
        trainer._truncate_log()
        return trainer

    # ----------------------------------------------------------------- logging / loop
    def _log_path(self):
        return None if self.out_dir is None else self.out_dir / 'train_log.csv'

    def _log(self, terms):
        path = self._log_path()
        if path is None:
            return
        path.parent.mkdir(parents=True, exist_ok=True)
        new = not path.exists() or terms['step'] == 1        # a fresh run starts a new log
        row = {k: terms.get(k, '') for k in LOG_FIELDS}
        row['pseudo_labels'] = self.pseudo_label_count
        row['seconds'] = round(time.monotonic() - self._started, 3)
        try:
            with open(path, 'w' if new else 'a', newline='') as f:
                writer = csv.DictWriter(f, fieldnames=LOG_FIELDS)
                if new:
                    writer.writeheader()
                writer.writerow(row)
        except OSError as error:      # e.g. a full disk: say which file and why
            raise write_error(path, error) from error

    def _truncate_log(self):
        """Drop log rows past the resumed step (they were lost with the killed run)."""
        path = self._log_path()
        if path is None or not path.exists():
            return
        with open(path, newline='') as f:
            rows = [r for r in csv.DictReader(f) if int(r['step']) <= self.step_count]
        tmp = path.with_suffix('.tmp')
        with open(tmp, 'w', newline='') as f:
            writer = csv.DictWriter(f, fieldnames=LOG_FIELDS)
            writer.writeheader()
            writer.writerows(rows)
        os.replace(tmp, path)

    def fit_error(self):
        """How well the detector fits its own labelled views (no augmentation): label_error
        over every labelled keypoint of every labelled view of the training split (every
        subject's: the other subjects' crop rows too)."""
        inst = self.data.labelled_instants
        labels = self.data.labels[inst]
        if len(self.data.other_instants):
            T = self.data.recording.num_instants
            inst = np.concatenate([inst, T + np.arange(len(self.data.other_instants))])
            labels = np.concatenate([labels, self.data.other_labels])
        return self.label_error(inst, labels)

    def validation_error(self):
        """label_error of every subject's validation labels (TrainingData.validation_rows:
        each subject's detections in the crops of its own row) pooled over the subjects;
        with several subjects labelled there, `subjects` {subject: its own label_error} too
        (a subject with no validation label is left out): scored_error. Raises ValueError
        when there is no validation label."""
        d = self.data
        return self.scored_error(d.validation_rows, d.validation_row_labels,
                                 d.validation_row_subjects)

    def holdout_error(self):
        """scored_error of the holdout instants' labels (TrainingData.holdout_rows: `monet
        train --holdout-labelled`), every subject's, as validation_error scores the
        validation labels. Raises ValueError when there is none."""
        d = self.data
        return self.scored_error(d.holdout_rows, d.holdout_row_labels, d.holdout_row_subjects)

    def scored_error(self, rows, labels, subjects):
        """label_error of crop rows (M,) against labels (M, V, C, 2) px pooled over the
        subjects, and with several subjects (subjects (M,)) `subjects`: {subject: its own
        label_error} for each subject with a label among them."""
        out = self.label_error(rows, labels)
        if len(np.unique(subjects)) > 1:
            out['subjects'] = {}
            for s in np.unique(subjects):
                mine = subjects == s
                if np.isfinite(labels[mine][..., 0]).any():
                    out['subjects'][int(s)] = self.label_error(rows[mine], labels[mine])
        return out

    def label_error(self, instants, labels):
        """Distance between the detections (detect: cached crops, no augmentation) of every
        view of `instants` (N,) (crop rows: T + j is other subject j, TrainingData) and
        `labels` (N, V, C, 2) original image px, NaN = not
        labelled: dict of `count` (labelled keypoints) and the median, mean and 90th
        percentile in original image pixels (`*_px`) and in heatmap pixels (`*_heat`: the
        network's output grid, independent of the image resolution); a lost keypoint counts
        as infinitely far. Raises ValueError when `labels` holds no label."""
        inst = np.asarray(instants, dtype=np.int64)
        labels = np.asarray(labels, dtype=np.float64)
        ok = np.isfinite(labels[..., 0])                                     # (N, V, C)
        if not ok.any():
            raise ValueError('label_error: no label at the given instants')
        points, _ = self.detect(inst)
        V = self.data.recording.num_views
        pairs = np.stack(np.meshgrid(inst, np.arange(V), indexing='ij'), -1).reshape(-1, 2)
        A = self.data.cache.views(pairs[:, 0], pairs[:, 1]).A[:, :2, :2]
        scale = np.sqrt(np.abs(np.linalg.det(A))).reshape(len(inst), V)      # heat px / px
        err = np.linalg.norm(points - labels, axis=-1)
        err = np.where(np.isfinite(err), err, np.inf)[ok]
        heat = err * np.broadcast_to(scale[..., None], ok.shape)[ok]
        out = {'count': int(err.size)}
        for suffix, e in (('px', err), ('heat', heat)):
            out.update({f'median_{suffix}': float(np.median(e)),
                        f'mean_{suffix}': float(np.mean(e)),
                        f'p90_{suffix}': float(np.percentile(e, 90))})
        return out

    def check_fit(self):
        """fit_error(), with a warning when its median in heatmap pixels exceeds
        config.fit_warning_heat_px."""
        fit = self.fit_error()
        if not fit['median_heat'] <= self.config.fit_warning_heat_px:
            self.warn(f'the detector does not fit its own labels: median error '
                      f'{fit["median_heat"]:.2f} heatmap px = {fit["median_px"]:.1f} image px '
                      f'(p90 {fit["p90_px"]:.1f} px) on {fit["count"]} labelled keypoints after '
                      f'{self.step_count} steps (> fit_warning_heat_px '
                      f'{self.config.fit_warning_heat_px}): train longer or with a higher '
                      'learning rate (--steps, --lr)')
        return fit

    @contextmanager
    def _stop_between_steps(self):
        """While run() trains: SIGINT / SIGTERM end the current step, then run() writes a
        checkpoint and raises KeyboardInterrupt (nothing trained is lost); a second signal
        stops at once. Yields a list that holds the signal's name once one came. Only in
        the main thread of a single process (the ranks of a torchrun job stop together, by
        the signal torchrun forwards)."""
        stop = []
        world = getattr(self, 'world', None)             # learning.distributed's
        if threading.current_thread() is not threading.main_thread() or \
                (world is not None and world.distributed):
            yield stop
            return

        def handler(signum, frame):
            if stop:
                raise KeyboardInterrupt
            stop.append(signal.Signals(signum).name)

        previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield stop
        finally:
            for s, h in previous.items():
                signal.signal(s, h)

    def run(self, steps=None, progress=True):
        """Train until `steps` (default config.steps); tqdm bar on stderr; returns a summary
        (with `fit`, the fit to the labelled views, and `warnings`)."""
        total = self.config.steps if steps is None else steps
        bar = tqdm(total=total, initial=self.step_count, file=sys.stderr, disable=not progress,
                   desc=f'train {self.config.mode}', dynamic_ncols=True)
        start = time.monotonic()
        first = self.step_count
        with self._stop_between_steps() as stop:
            try:
                while self.step_count < total and not stop:
                    t = self.step()
                    bar.update(1)
                    bar.set_postfix({k: f'{t[k]:.4g}' for k in LOSS_TERMS if k in t})
            finally:
                bar.close()
            if stop:             # a signal: keep what was trained, then stop (exit 0)
                if self.out_dir is not None:
                    path = self.save()
                    print(f'stopped by {stop[0]} after step {self.step_count}: wrote {path} '
                          f'and {self.out_dir / "trainer_state.pt"} (--resume continues)',
                          file=sys.stderr, flush=True)
                raise KeyboardInterrupt
        if self.out_dir is not None and self.step_count % self.config.checkpoint_every and \
                self.step_count != self.config.steps:
            self.save()
        seconds = time.monotonic() - start
        fit = self.check_fit()
        if self.spec.epipolar and self.config.lambda_e and self.epipolar_started is None \
                and self.step_count >= total:
            self.warn(f'mode {self.config.mode}: L_E never started: the detector did not fit its '
                      f'labelled crops to epipolar_fit_heat_px '
                      f'{self.config.epipolar_fit_heat_px:g} heatmap px in a step after the '
                      'warm-up (train longer, or raise epipolar_fit_heat_px)')
        validation = self.validation_error() if len(self.data.validation_instants) else None
        return {'mode': self.config.mode, 'steps': self.step_count, 'seconds': seconds,
                'steps_per_s': (self.step_count - first) / max(seconds, 1e-9),
                'pseudo_labels': self.pseudo_label_count,
                'pseudo_label_coverage': self.pseudo_label_coverage, 'last': self.last_terms,
                'pseudo_label_gate': self.data.pseudo_gate,
                'distill_round': self.distill_round, 'distilled_labels': self.distilled_count,
                'fit': fit, 'validation': validation, 'bootstrap': self.bootstrap_stats,
                'warnings': list(self.warnings)}


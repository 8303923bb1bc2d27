"""`monet train`'s options that do not apply, or that would do nothing, are said: refused in
one line naming the option (exit 2) before any file is read where that is known then
(--holdout-labelled -1, the distillation rounds' options without --distill-rounds,
--batch-distill 0 with it), after reading where the labels decide (--distill-rounds on
labels that leave nothing to distil), or said in one line and run (--validation-labels
that holds out nothing, a weight of a term the mode does not train, --resume past
--steps); and what it writes on stdout is valid JSON. Real runs on small blob folders."""
import json
import math

from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
import numpy as np
import pytest

from monet_ros.cli import main as monet
from monet_ros.commands.train import holdout_text
from monet_ros.learning.config import MODE_SPECS, TrainConfig

TRAIN = ['--architecture', 'small', '--input-size', '48', '--width', '16',
         '--batch-labelled', '2', '--batch-pseudo', '2', '--batch-unlabeled', '1',
         '--views-per-instant', '2', '--device', 'cpu', '--threads', '1', '--no-progress']


def strict_json(text):
    """json.loads that rejects NaN / Infinity (not JSON)."""
    def refuse(token):
        raise ValueError(f'not JSON: {token}')
    return json.loads(text, parse_constant=refuse)


@pytest.fixture(scope='module')
def folders(tmp_path_factory):
    """Blob folders (keypoints k0 k1 k2): two labelled instants in two views; every view
    of every instant labelled; and the skeleton of their keypoints."""
    base = tmp_path_factory.mktemp('train_options')
    two = write_blob_folder(blob_recording(num_views=4, T=24, C=3, labelled=(2, 9),
                                           label_views=(0, 1)), base / 'two')
    every = write_blob_folder(blob_recording(num_views=4, T=6, C=3, labelled=range(6)),
                              base / 'every')
    skeleton = base / 'blob3.yaml'
    skeleton.write_text('name: blob3\nkeypoints: [k0, k1, k2]\n')
    return two, every, skeleton


def one_line(capsys):
    err = capsys.readouterr().err.strip()
    assert '\n' not in err, err
    return err


@pytest.mark.parametrize('extra, line', [
    (['--holdout-labelled', '-1'], "monet train: error: --holdout-labelled: TrainRunOptions: "
     "parameter 'holdout_labelled': must be >= 0, got -1"),
    *[([option, value], f'monet train: error: {option} applies only with --distill-rounds N '
       '(N >= 1); monet train has no distillation round without it')
      for option, value in (('--lambda-d', '2'), ('--distill-steps', '3'),
                            ('--distill-gate-px', '4'), ('--distill-min-views', '2'),
                            ('--distill-residual-px', '1'), ('--batch-distill', '4'))],
    (['--batch-distill', '0', '--distill-rounds', '1'],
     "monet train: error: --batch-distill: TrainConfig: parameter 'batch_distill': 0 with "
     'distill_rounds 1: no distilled crop would be trained on (nothing would use the '
     "teacher's labels); give batch_distill >= 1, or distill_rounds 0"),
])
def test_an_option_that_would_do_nothing_is_one_line_before_reading(extra, line, capsys,
                                                                   tmp_path):
    missing = tmp_path / 'no_such_recording'
    assert monet(['train', str(missing), '--out', str(tmp_path / 'run'), *extra]) == 2
    assert one_line(capsys) == line
    assert not (tmp_path / 'run').exists()


@pytest.mark.parametrize('option, value', [
    ('--lambda-d', '0'), ('--distill-steps', '3'), ('--batch-distill', '4')])
def test_the_distillation_options_are_taken_with_distill_rounds(option, value, capsys,
                                                                tmp_path):
    # accepted: the run fails on the missing recording instead
    missing = tmp_path / 'no_such_recording'
    assert monet(['train', str(missing), '--out', str(tmp_path / 'run'), '--distill-rounds',
                  '1', option, value]) == 2
    err = one_line(capsys)
    assert 'no_such_recording' in err and 'applies only' not in err


def test_distillation_with_nothing_unlabelled_is_refused(folders, capsys, tmp_path):
    _, every, skeleton = folders
    code = monet(['train', str(every), '--out', str(tmp_path / 'run'), '--skeleton',
                  str(skeleton), '--steps', '1', '--distill-rounds', '1', *TRAIN])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err[-1] == ('monet train: error: --distill-rounds 1: every view x keypoint of the 6 '
                       'training instants is labelled: nothing unlabelled to distil (the '
                       'teacher would run for nothing); train with --distill-rounds 0')
    assert not (tmp_path / 'run' / 'distill').exists() and 'train supervised' not in err


def test_validation_labels_that_hold_out_nothing_warn_and_the_summary_is_json(
        folders, capsys, tmp_path):
    """Two labelled instants, one held out by --holdout-labelled: --validation-labels has
    none left to hold out (one is always left to train on): one warning naming it and why;
    the summary on stdout parses as strict JSON (a non-finite figure is null)."""
    two, _, skeleton = folders
    assert monet(['train', str(two), '--out', str(tmp_path / 'run'), '--skeleton',
                  str(skeleton), '--steps', '2', '--validation-labels', '0.5',
                  '--holdout-labelled', '1', '--mode', 'supervised', *TRAIN]) == 0
    out, err = capsys.readouterr()
    warning = ('WARNING: no labelled instant can be held out for validation '
               '(--validation-labels 0.5: only one labelled instant to train on after '
               "--holdout-labelled 1, and one is always left to train on); the summary's "
               'validation is null')
    assert err.splitlines().count(warning) == 1, err
    summary = strict_json(out)
    assert summary['validation'] is None
    assert any(w in warning for w in summary['warnings'])
    assert 'inf px' not in err and 'nan px' not in err
    # the figures a non-finite median had: null, each, and the rest as they were
    for key, value in summary['holdout'].items():
        assert value is None or not isinstance(value, float) or math.isfinite(value), key


def test_resume_past_steps_and_an_unused_weight_are_said(folders, capsys, tmp_path):
    two, _, skeleton = folders
    run = ['train', str(two), '--out', str(tmp_path / 'run'), '--skeleton', str(skeleton),
           '--mode', 'supervised', '--checkpoint-every', '2', '--lambda-e', '3', *TRAIN]
    assert monet([*run, '--steps', '2']) == 0
    capsys.readouterr()
    assert monet([*run, '--steps', '1', '--resume']) == 0
    err = capsys.readouterr().err.splitlines()
    assert 'monet train: already at step 2 >= --steps 1: nothing to train' in err, err
    start, = [line for line in err if 'mode supervised (' in line]
    assert 'mode supervised (L_L; mode supervised has no L_E (--lambda-e 3 not used))' in start


def test_a_holdout_median_of_misses_is_said_in_words():
    figures = {'px_median': math.inf, 'pck2d@10px': 0.02, 'views_2d': 56,
               'mm_median': 24.5, 'mm_mean': 30.0, 'coverage': 0.3}
    text = holdout_text(figures, 'm')
    assert text.startswith('2D median: more than half of the labelled views missed, '
                           'PCK@10px 2% (56 views); 3D median 24.5 mm')
    text = holdout_text({**figures, 'px_median': 3.14, 'mm_median': math.nan}, 'm')
    assert text.startswith('2D median 3.1 px, ') and '3D: no point scored (rig in m)' in text


def test_epipolar_warmup_names_every_mode_it_delays():
    description = TrainConfig.__dataclass_fields__['epipolar_warmup'].metadata['description']
    listed = description.split(':')[0].split(', ')
    assert listed == [m for m, spec in MODE_SPECS.items() if spec.unlabeled]
    assert {'reprojection_epipolar', 'bootstrap2_epipolar'} <= set(listed)
    assert np.all([MODE_SPECS[m].unlabeled for m in listed])

"""Generated bad option values for every `monet` subcommand: each is refused at start with
one line naming the option (exit 2) - never a traceback, a silent 0-frame run, an
allocation error or a hang."""
from dataclasses import fields
import math

from helpers.reliability import RELIABILITY, outcome, record, run_monet
from hypothesis import given, settings
from hypothesis import strategies as st
import pytest

from monet_ros.learning.config import TrainConfig

BAD_TEXT = st.sampled_from(['', 'abc', 'nan', 'inf', '-inf', '1e400', '0x10', '1,2', '--', ' '])


def bad_numbers(minimum=None, maximum=None, integer=False, exclusive_minimum=False):
    """Values outside [minimum, maximum] (or not numbers at all), as command-line text."""
    options = [BAD_TEXT]
    if minimum is not None:
        low = minimum if exclusive_minimum else minimum - (1 if integer else 1e-6)
        options.append((st.integers(-10**12, math.floor(low)) if integer else
                        st.floats(-1e12, low, allow_nan=False)).map(str))
    if maximum is not None:
        options.append((st.integers(math.floor(maximum) + 1, 10**15) if integer else
                        st.floats(maximum * 1.0001 + 1e-9, 1e300)).map(str))
    if integer:
        options.append(st.sampled_from(['1.5', '2e3x', 'ten']))
    return st.one_of(*options)


def names_for(flag):
    return (flag, flag.lstrip('-').replace('-', '_'))


# ------------------------------------------------------------------ monet synth
SYNTH_BAD = {
    '--cameras': bad_numbers(1, 64, integer=True),
    '--frames': bad_numbers(1, 1_000_000, integer=True),
    '--fps': bad_numbers(0, 1000, exclusive_minimum=True),
    '--width': bad_numbers(16, 8192, integer=True),
    '--height': bad_numbers(16, 8192, integer=True),
    '--label-fraction': bad_numbers(0, 1),
    '--seed': bad_numbers(0, None, integer=True),
    '--hfov': bad_numbers(10, 150),
    '--noise': bad_numbers(0, 50),
    '--radius': bad_numbers(0, None, exclusive_minimum=True),
    '--skeleton': st.sampled_from(['nope', '/nonexistent/skeleton.yaml', '']),
    '--layout': st.sampled_from(['grid', '']),
    '--distortion': st.one_of(BAD_TEXT, st.lists(
        st.floats(allow_nan=True, allow_infinity=True), min_size=6, max_size=8)
        .map(lambda v: ','.join(map(str, v)))),
}


@settings(RELIABILITY, max_examples=25)
@given(flag=st.sampled_from(sorted(SYNTH_BAD)), data=st.data())
def test_synth_bad_options(tmp_path_factory, flag, data):
    value = data.draw(SYNTH_BAD[flag])
    out = tmp_path_factory.mktemp('synth_bad') / 'out'
    kind, _, _ = outcome('synth', ['synth', '--out', out, '--cameras', '2', '--frames', '2',
                                   '--width', '48', '--height', '32', '--quiet',
                                   f'{flag}={value}'], names=names_for(flag) + ('synth',))
    # the radius / cameras bounds are not all known here: a value accepted must have made a
    # whole recording
    if kind == 'right result':
        assert (out / 'rig.yaml').is_file() and (out / 'recording').is_dir()


@settings(RELIABILITY, max_examples=8)
@given(values=st.lists(st.floats(-20, 20, allow_nan=False), min_size=1, max_size=5))
def test_synth_distortion_is_refused_or_renders_finite_images(tmp_path_factory, values):
    """Any distortion is either refused naming the field or renders (kind 8: 1,2,3 gave NaN
    casts and a run that did not end)."""
    out = tmp_path_factory.mktemp('synth_dist') / 'out'
    text = ','.join(f'{v:.4g}' for v in values)

    def check(stdout, stderr):
        assert 'invalid value encountered' not in stderr, stderr
        assert (out / 'recording').is_dir()
        return 'right result'

    outcome('synth', ['synth', '--out', out, '--cameras', '2', '--frames', '1', '--width',
                      '48', '--height', '32', '--quiet', f'--distortion={text}'],
            names=('distortion',), check=check)


# ------------------------------------------------------------------ monet train
def _train_field_bad(f):
    meta = f.metadata
    kind = f.type if isinstance(f.type, str) else f.type.__name__
    if meta.get('choices'):
        return st.sampled_from(['nope', '', 'SUPERVISED'])
    if kind == 'bool':
        return st.sampled_from(['maybe', '2', ''])
    if kind in ('int', 'float'):
        return bad_numbers(meta.get('minimum'), meta.get('maximum'), integer=kind == 'int',
                           exclusive_minimum=meta.get('exclusive_minimum'))
    return None


TRAIN_BAD = {'--' + f.name.replace('_', '-'): s for f in fields(TrainConfig)
             if (s := _train_field_bad(f)) is not None and f.name not in ('seed',)}
TRAIN_BAD.update({
    '--seed': bad_numbers(0, None, integer=True),
    '--max-instants': bad_numbers(0, 100_000_000, integer=True),
    '--threads': bad_numbers(0, 256, integer=True),
    '--device': st.sampled_from(['tpu', 'cuda:x', 'gpu', 'cpu:0', 'cuda', 'cuda:7']),
    '--input-size': st.sampled_from(['100000', '12', '30', '-8', '1000001', '4100']),
    '--width': st.sampled_from(['100000', '2', '-16', '5000']),
})


@settings(RELIABILITY, max_examples=40)
@given(flag=st.sampled_from(sorted(TRAIN_BAD)), data=st.data())
def test_train_bad_options(synth_folder, tmp_path_factory, flag, data):
    import torch
    value = data.draw(TRAIN_BAD[flag])
    if flag == '--device' and value.startswith('cuda') and torch.cuda.is_available():
        value = 'cuda:99'
    out = tmp_path_factory.mktemp('train_bad') / 'out'
    outcome('train', ['train', synth_folder, '--out', out, '--steps', '1', '--no-progress',
                      f'{flag}={value}'], names=names_for(flag), expect='clear error')
    assert not (out / 'model.pt').exists()


# ------------------------------------------------------------------ monet process
PROCESS_BAD = {
    '--slop-ms': bad_numbers(0, 10_000),
    '--threshold-px': bad_numbers(0, None, exclusive_minimum=True),
    '--confidence-threshold': bad_numbers(0, None),
    '--min-views': st.one_of(bad_numbers(2, None, integer=True),
                             st.integers(4, 10**6).map(str)),      # > the 3 cameras
    '--method': st.sampled_from(['median', '']),
    '--device': st.sampled_from(['tpu', 'cuda:x', 'gpu']),
    '--cameras': st.sampled_from(['cam9', 'cam0', 'cam0 cam0']),
    '--skeleton': st.sampled_from(['quadruped13', 'nope', '/nonexistent.yaml']),
}


@settings(RELIABILITY, max_examples=30)
@given(flag=st.sampled_from(sorted(PROCESS_BAD)), data=st.data())
def test_process_bad_options(process_inputs, tmp_path_factory, flag, data):
    value = data.draw(PROCESS_BAD[flag])
    rec, model = process_inputs
    out = tmp_path_factory.mktemp('process_bad') / 'out'
    values = value.split(' ') if flag == '--cameras' else [value]
    argv = ['process', rec, '--model', model, '--out', out, '--quiet', flag, *values]
    if flag != '--cameras':
        argv[-2:] = [f'{flag}={value}']
    outcome('process', argv, names=names_for(flag) + ('camera', 'skeleton'),
            expect='clear error')
    assert not out.exists()


@pytest.mark.parametrize('argv, names', [
    (['--model', '{tmp}/missing.pt'], ('missing.pt',)),
    (['--model', '{rec}'], ('rec',)),                      # a folder is not a checkpoint
    (['--rig', '{tmp}/nope.yaml'], ('nope.yaml',)),
])
def test_process_bad_files(process_inputs, tmp_path, argv, names):
    rec, model = process_inputs
    argv = [a.format(tmp=tmp_path, rec=rec) for a in argv]
    base = ['process', rec, '--out', tmp_path / 'out', '--quiet']
    if '--model' not in argv:
        base += ['--model', model]
    outcome('process', base + argv, names=names, expect='clear error')


# ------------------------------------------------------------------ monet eval
EVAL_BAD = {
    '--threads': bad_numbers(0, 256, integer=True),
    '--device': st.sampled_from(['tpu', 'cuda:x']),
    '--instants': st.sampled_from(['some', '']),
}


@settings(RELIABILITY, max_examples=15)
@given(flag=st.sampled_from(sorted(EVAL_BAD)), data=st.data())
def test_eval_bad_options(process_inputs, synth_folder, tmp_path_factory, flag, data):
    value = data.draw(EVAL_BAD[flag])
    _, model = process_inputs
    out = tmp_path_factory.mktemp('eval_bad') / 'report'
    outcome('eval', ['eval', model, '--data', synth_folder, '--out', out, f'{flag}={value}'],
            names=names_for(flag), expect='clear error')


# ------------------------------------------------------------------ monet demo
DEMO_BAD = {
    '--threshold-px': bad_numbers(0, None, exclusive_minimum=True),
    '--likelihood': bad_numbers(0, 1),
}


@settings(RELIABILITY, max_examples=10)
@given(flag=st.sampled_from(sorted(DEMO_BAD)), data=st.data())
def test_demo_bad_options(flag, data):
    value = data.draw(DEMO_BAD[flag])
    outcome('demo', ['demo', '--synthetic', f'{flag}={value}'], names=names_for(flag),
            expect='clear error')


# ------------------------------------------------------------------ monet pipeline
PIPELINE_BAD = {
    '--rate': bad_numbers(0, 1000),
    '--duration': bad_numbers(0, None),
    '--start-delay': bad_numbers(0, 3600),
    '--device': st.sampled_from(['tpu', 'cuda:x', 'gpu']),
    '--learn-every': st.sampled_from(['ten', '1.5']),
}


@settings(RELIABILITY, max_examples=20)
@given(flag=st.sampled_from(sorted(PIPELINE_BAD)), data=st.data())
def test_pipeline_bad_options(process_inputs, flag, data):
    """Refused before any node starts (no rclpy context needed)."""
    value = data.draw(PIPELINE_BAD[flag])
    rec, model = process_inputs
    outcome('pipeline', ['pipeline', '--bag', rec, '--model', model, '--quiet',
                         f'{flag}={value}'], names=names_for(flag), expect='clear error')


def test_pipeline_without_model_is_named(process_inputs):
    rec, _ = process_inputs
    outcome('pipeline', ['pipeline', '--bag', rec], names=('model',), expect='clear error')


@pytest.mark.parametrize('argv', [[], ['frobnicate'], ['train'], ['process', '--nope']])
def test_unknown_commands_and_missing_arguments(argv):
    """argparse's own errors are one line too (no usage block)."""
    code, out, err = outcome_raw(argv)
    assert code == 2 and len(err.strip().splitlines()) == 1 and 'error' in err


def outcome_raw(argv):
    result = run_monet(argv)
    record('monet (argument parsing)', 'clear error')
    return result

"""The demo assets of `monet pipeline` with no arguments (not a subcommand).

A small synthetic recording (`monet synth`) and a small detector trained for it
(`monet train`, supervised on the synthetic labels), made once and cached in
~/.cache/monet_ros/demo (or --workdir); later runs start at once.
"""
from dataclasses import dataclass
import os
from pathlib import Path
import shutil
import sys
import time

DEFAULT_WORKDIR = Path.home() / '.cache' / 'monet_ros' / 'demo'
# Small enough to make and learn in about a minute on two CPU cores.
SYNTH_ARGS = ['--cameras', '4', '--frames', '90', '--fps', '30', '--width', '320',
              '--height', '240', '--label-fraction', '1.0', '--seed', '0', '--quiet']
# One torch thread: on a busy 2-core machine two threads made each step 10x slower.
TRAIN_ARGS = ['--mode', 'supervised', '--architecture', 'small', '--input-size', '128',
              '--steps', '150', '--lr', '0.003', '--lr-decay-every', '50',
              '--batch-labelled', '8', '--eval-fraction', '0.0', '--checkpoint-every', '150',
              '--threads', '1', '--no-progress']


@dataclass(frozen=True)
class DemoAssets:
    bag: Path
    rig: Path
    model: Path
    skeleton: str = 'human14'


def _say(text):
    print(f'monet pipeline: {text}', file=sys.stderr, flush=True)


def prepare_demo(workdir=None):
    """Make (once) and return the demo recording, rig and model."""
    from monet_ros.cli import main as monet

    root = Path(workdir or os.environ.get('MONET_DEMO_DIR', DEFAULT_WORKDIR))
    root.mkdir(parents=True, exist_ok=True)       # OSError naming the folder when it cannot
    data = root / 'synth'
    model = root / 'model.pt'
    if not (data / 'recording' / 'metadata.yaml').is_file():
        start = time.monotonic()
        _say(f'generating a synthetic recording in {data} (once) ...')
        shutil.rmtree(data, ignore_errors=True)
        if monet(['synth', '--out', str(data), *SYNTH_ARGS]) != 0:
            raise ValueError(f'--workdir {root}: the demo recording could not be made')
        _say(f'recording ready ({time.monotonic() - start:.0f} s)')
    if not model.is_file():
        start = time.monotonic()
        train_dir = root / 'train'
        _say(f'training a small detector for it in {train_dir} (once, about a minute) ...')
        shutil.rmtree(train_dir, ignore_errors=True)
        if monet(['train', str(data), '--out', str(train_dir), *TRAIN_ARGS]) != 0:
            raise ValueError(f'--workdir {root}: the demo model could not be trained')
        shutil.copyfile(train_dir / 'model.pt', root / '.model.pt.tmp')
        os.replace(root / '.model.pt.tmp', model)
        _say(f'model ready ({time.monotonic() - start:.0f} s)')
    return DemoAssets(bag=data / 'recording', rig=data / 'rig.yaml', model=model)

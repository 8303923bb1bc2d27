"""`monet synth` speed: an 8-camera 640x480 100-frame recording, end to end and by stage.

Rows (median of --runs runs, wall and CPU seconds of this process):
  synth end to end   synthesize(): plan + room + outlines + render + MCAP writing + files
  write-only floor   BagWriter writing the same number of identical-size rgb8 images,
                     CameraInfo and ground truth (no rendering): the cost of the bag itself
and per-stage CPU times of one run (plan, room ray casting per camera, capsule outlines
per camera, one image render). The 2-core machine is shared with other jobs: wall time
varies with their load, CPU time much less.

usage: python bench/synth.py [--cameras 8] [--frames 100] [--width 640] [--height 480]
                             [--runs 3]
"""
import argparse
from pathlib import Path
import shutil
import statistics
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from monet_ros.io import BagWriter  # noqa: E402
from monet_ros.synth.recording import SynthConfig, plan, synthesize  # noqa: E402
from monet_ros.synth.render import RenderConfig, Scene, capsule_outlines  # noqa: E402


def timed(fn, *args, **kwargs):
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - wall, time.process_time() - cpu


def write_only(config, path):
    cams = plan(config)['cameras']
    image = np.random.default_rng(0).integers(0, 256, (config.height, config.width, 3),
                                              dtype=np.uint8)
    X = np.zeros((14, 3))
    with BagWriter(path) as bag:
        bag.write_tf_static(config.start_ns, cams)
        for stamp in config.stamps():
            for cam in cams:
                bag.write_image(f'/{cam.name}/image_raw', int(stamp), image,
                                f'{cam.name}_optical')
                bag.write_camera_info(f'/{cam.name}/camera_info', int(stamp), cam,
                                      f'{cam.name}_optical')
            bag.write_keypoints3d('/ground_truth/keypoints3d', int(stamp), 'world', X,
                                  units='m')


def stages(config):
    (p, _, plan_cpu) = timed(lambda: plan(config))
    cams, subject = p['cameras'], p['subject']
    scene, _, scene_cpu = timed(lambda: Scene(cams, subject.parts, seed=config.seed))
    bg, _, bg_cpu = timed(lambda: scene.background(cams[0]))
    out, _, outline_cpu = timed(lambda: capsule_outlines(
        cams[0], p['A'], p['B'], subject.radii, scene.light, RenderConfig().levels))
    scene.noise_bank(config.height, config.width)
    n = min(20, config.frames)
    _, _, render_cpu = timed(lambda: [scene.render(0, t, cams[0], bg, out[0][t], out[1][t],
                                                   out[2][t], root=p['root'][t])
                                      for t in range(n)])
    return {'plan (all frames)': plan_cpu, 'scene textures': scene_cpu,
            'room ray cast (per camera)': bg_cpu,
            'capsule outlines (per camera, all frames)': outline_cpu,
            'render one image': render_cpu / n}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--cameras', type=int, default=8)
    parser.add_argument('--frames', type=int, default=100)
    parser.add_argument('--width', type=int, default=640)
    parser.add_argument('--height', type=int, default=480)
    parser.add_argument('--runs', type=int, default=3)
    args = parser.parse_args()
    config = SynthConfig(cameras=args.cameras, frames=args.frames, width=args.width,
                         height=args.height, seed=0)
    rows = {'synth end to end': [], 'write-only floor': []}
    size = 0
    with tempfile.TemporaryDirectory() as tmp:
        for run in range(args.runs):
            out = Path(tmp) / f'synth{run}'
            result, wall, cpu = timed(synthesize, config, out, progress=False)
            size = result.bag_bytes
            rows['synth end to end'].append((wall, cpu))
            shutil.rmtree(out)
            _, wall, cpu = timed(write_only, config, Path(tmp) / f'w{run}')
            rows['write-only floor'].append((wall, cpu))
            shutil.rmtree(Path(tmp) / f'w{run}')
    images = args.cameras * args.frames
    real_time = args.frames / config.fps
    print(f'monet synth: {args.cameras} cameras x {args.frames} frames, '
          f'{args.width}x{args.height} rgb8, {size / 1e6:.0f} MB bag, median of {args.runs} '
          f'runs (shared 2-core machine)')
    print(f'{"":22} {"wall s":>8} {"CPU s":>8} {"images/s (wall)":>16} {"x real time":>12}')
    for name, values in rows.items():
        wall = statistics.median(v[0] for v in values)
        cpu = statistics.median(v[1] for v in values)
        print(f'{name:22} {wall:8.2f} {cpu:8.2f} {images / wall:16.1f} '
              f'{real_time / wall:12.2f}')
    print('stages (CPU s, one run):')
    for name, value in stages(config).items():
        print(f'  {name:42} {value:8.4f}')


if __name__ == '__main__':
    main()

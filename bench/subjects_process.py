"""`monet process --subjects N` on synthetic humans, as a user runs it (issue 39 item 5,
offline with our detector): identity switches, IDF1, 3D error per subject, subjects found
and frames/s for 1, 2 and 3 subjects, against the same model's one-subject figure.

1. A detector the way a user trains one: `monet synth` a one-subject human14 recording
   with labels (--train-frames instants, --label-fraction of them labelled in every view,
   left limbs in their own colour; --train-seed, default --seed: the rig, the subjects'
   look and the room of the recordings scored; --train-motion-seed: another motion, so no
   scored frame is a training frame, and not one of the scored subjects' motion seeds
   seed * 1000 + k), then `monet train` on it (the default mode, the small net at input
   128: the CPU recipe of docs/train.md with --train-steps steps, one torch thread). The checkpoint
   is cached in WORK/model-<settings>/model.pt: a rerun with the same settings skips it.
   --train-subjects K (default 1): the training recording has K subjects (`monet synth
   --subjects K --label-subjects`, the same options otherwise: every subject labelled at
   the labelled instants, motion seeds train_motion_seed * 1000 + k); the model is then
   WORK/model-<settings>-kK and the outputs WORK/out-...-tK, beside the one-subject ones.
2. For each N of --subjects-list: `monet synth --subjects N` (--cameras, --width x
   --height, --frames at 30/s, --seed; the subjects walk rings of 0.7 / 1.4 / 2.1 m and
   pass and hide each other; cached in WORK), then `monet process REC --model M --subjects
   N --threads 1 --export csv` (a subprocess: the command a user types); the baseline is
   `monet process` without --subjects on the N = 1 recording. keypoints3d.csv (its
   `subject` column; none without --subjects) is read back and scored against
   ground_truth.npz (subjects_keypoints3d; keypoints3d for one subject) with
   subjects.metrics.identity_scores: a subject and an output identity match in a frame when
   their mean keypoint distance is <= --match-m; identity switches, IDF1, the mean 3D error
   of each ground-truth subject over its matched frames (mm), its share of frames found;
   ratio = that error / the baseline's. Speed: the command's wall time (start-up and
   writing included), its CPU time (getrusage of the child), and the frame loop's own
   seconds from its summary line.
3. A markdown table to --out (default bench/results/subjects_process.md) with the command,
   the CPU, the load average at start and end and the settings, and a PNG beside it (per N:
   each ground-truth subject's 3D error per frame and the identity matched to it).

    nice .venv/bin/python bench/subjects_process.py --work /tmp/subjects_process
        [--subjects-list 1 2 3] [--frames 300] [--cameras 8] [--width 320 --height 240]
        [--train-steps 1500] [--train-subjects 1] [--[no-]rival-peaks] [--[no-]foreign-views]
        [--min-score X] [--out bench/results/subjects_process.md]
"""
import argparse
import csv
import json
import os
from pathlib import Path
import re
import resource
import shutil
import subprocess
import sys
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from monet_ros.cores import cpu_model  # noqa: E402
from monet_ros.subjects.metrics import identity_scores  # noqa: E402

LOOP = re.compile(r'monet process: (\d+) frames .* in ([0-9.]+) s')
IDENTITIES = re.compile(r'subjects: (\d+) identities .* (\d+) births, (\d+) deaths')




def load():
    return ' '.join(f'{x:.2f}' for x in os.getloadavg())


def say(text):
    print(f'subjects_process: {text}', flush=True)


def monet(args, log=None):
    """Run `monet ARGS` as a user does (python -m monet_ros.cli in a child process) ->
    (stdout, wall s, CPU s of the child). Raises SystemExit with its output on failure."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(REPO)] + [p for p in os.environ.get('PYTHONPATH', '').split(os.pathsep) if p]))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    result = subprocess.run([sys.executable, '-m', 'monet_ros.cli', *map(str, args)],
                            cwd=REPO, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if log is not None:
        Path(log).write_text(result.stdout + result.stderr)
    if result.returncode:
        raise SystemExit(f'monet {" ".join(map(str, args))} failed ({result.returncode}):\n'
                         f'{result.stdout[-3000:]}{result.stderr[-3000:]}')
    return result.stdout, wall, cpu


def cached(folder, settings, make):
    """make(folder) once per settings (json in folder/settings.json); the folder is remade
    when the settings differ or an earlier run did not finish."""
    folder = Path(folder)
    stamp = folder / 'settings.json'
    if stamp.is_file() and json.loads(stamp.read_text()) == settings:
        return False
    shutil.rmtree(folder, ignore_errors=True)
    make(folder)
    stamp.write_text(json.dumps(settings))
    return True


def read_keypoints3d(path, keypoints, stamps):
    """keypoints3d.csv (anipose layout, optional `subject` column) -> (X (T, H, C, 3),
    ids (T, H)) aligned with the ground truth's stamps (T,); H: the most subjects in a
    frame. Rows whose stamp is not a ground-truth stamp raise ValueError."""
    index = {int(s): t for t, s in enumerate(stamps)}
    rows = []
    with open(path, newline='') as f:
        for row in csv.DictReader(f):
            stamp = int(row['stamp_ns'])
            if stamp not in index:
                raise ValueError(f'{path}: stamp {stamp} is not in the ground truth')
            X = np.array([[float(row[f'{k}_{a}']) if row[f'{k}_{a}'] != '' else np.nan
                           for a in 'xyz'] for k in keypoints])
            rows.append((index[stamp], int(row.get('subject') or 0), X))
    T, C = len(stamps), len(keypoints)
    per_frame = np.bincount([t for t, _, _ in rows], minlength=T) if rows else np.zeros(T)
    H = max(1, int(per_frame.max()))
    out = np.full((T, H, C, 3), np.nan)
    ids = np.full((T, H), -1)
    slot = np.zeros(T, int)
    for t, ident, X in rows:
        if np.isfinite(X).all(-1).any():
            out[t, slot[t]], ids[t, slot[t]] = X, ident
            slot[t] += 1
    return out, ids


def ground_truth(folder):
    """(stamps (T,), keypoints (C,), X (T, S, C, 3) m) of a `monet synth` folder."""
    d = np.load(Path(folder) / 'ground_truth.npz', allow_pickle=False)
    X = d['subjects_keypoints3d'] if 'subjects_keypoints3d' in d else d['keypoints3d'][:, None]
    return d['stamps'].astype(np.int64), [str(k) for k in d['keypoint_names']], X


def closest_pass(X):
    """Smallest horizontal distance (m) between two subjects' mean keypoints; None for one."""
    S = X.shape[1]
    if S < 2:
        return None
    root = X[..., :2].mean(2)
    gaps = np.linalg.norm(root[:, :, None] - root[:, None], axis=-1)
    return float(gaps[:, ~np.eye(S, dtype=bool)].min())


def score(csv_path, gt_folder, match_m):
    stamps, keypoints, truth = ground_truth(gt_folder)
    X, ids = read_keypoints3d(csv_path, keypoints, stamps)
    return identity_scores(truth, X, ids, match_m), len(np.unique(ids[ids >= 0]))


def process(rec, model, out, subjects, threads, extra=()):
    """One `monet process` run (extra: more options, with --subjects) -> dict(wall, cpu,
    frames, loop_s, identities, births, deaths, stdout)."""
    shutil.rmtree(out, ignore_errors=True)
    args = ['process', Path(rec) / 'recording', '--model', model, '--out', out,
            '--threads', threads, '--export', 'csv', '--quiet']
    if subjects is not None:
        # the --subjects-only options are refused with one subject (they would be ignored)
        args += ['--subjects', subjects, *(extra if int(subjects) > 1 else ())]
    stdout, wall, cpu = monet(args, log=Path(str(out) + '.log'))
    loop = LOOP.search(stdout)
    ident = IDENTITIES.search(stdout)
    for line in stdout.splitlines():
        if line.startswith('monet process:'):
            say(f'  {line}')
    return dict(wall=wall, cpu=cpu, frames=int(loop.group(1)) if loop else 0,
                loop_s=float(loop.group(2)) if loop else float('nan'),
                births=int(ident.group(2)) if ident else None,
                deaths=int(ident.group(3)) if ident else None, stdout=stdout)


def plot(path, runs, match_m):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(runs), 2, figsize=(12, 2.6 * len(runs)), squeeze=False,
                             sharex=True)
    colors = plt.get_cmap('tab10')
    for row, (name, s, T) in enumerate(runs):
        ax, ax_id = axes[row]
        t = np.arange(T) / 30.0
        for g in range(s.distance.shape[1]):
            ax.plot(t, 1000 * s.distance[:, g], lw=0.8, color=colors(g), label=f'subject {g}')
            ax_id.plot(t, np.where(s.track[:, g] >= 0, s.track[:, g], np.nan), '.', ms=2,
                       color=colors(g), label=f'subject {g}')
        ax.set_ylabel('3D error (mm)')
        ax.set_title(f'{name}: mean keypoint error of each subject (matched within '
                     f'{match_m * 1000:.0f} mm)', fontsize=9)
        ax.legend(fontsize=7, loc='upper right')
        ax_id.set_ylabel('identity')
        ax_id.set_title(f'{name}: output identity matched to each ground-truth subject',
                        fontsize=9)
    for ax in axes[-1]:
        ax.set_xlabel('time (s)')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def detector_commands(args, rig):
    """The detector's `monet synth` and `monet train` arguments for the parsed options args
    (train_frames, label_fraction, train_seed, train_motion_seed, train_subjects, train_steps,
    threads, cameras, width, height) and the synth's rig options -> (synth args, train args,
    settings dict (the cache stamp), folder name). With train_subjects K > 1 the recording
    has K subjects, every one labelled (--subjects K --label-subjects), and the name ends
    in -kK; with K = 1 the settings and name are those of before the option (cache kept)."""
    several = args.train_subjects > 1
    train_synth = ['synth', '--frames', args.train_frames, '--label-fraction',
                   args.label_fraction, '--seed', args.train_seed, '--motion-seed',
                   args.train_motion_seed, *rig]
    if several:
        train_synth += ['--subjects', args.train_subjects, '--label-subjects']
    train_args = ['--input-size', 128, '--steps', args.train_steps, '--threads', args.threads,
                  '--checkpoint-every', args.train_steps, '--no-progress']
    settings = dict(synth=list(map(str, train_synth)), train=list(map(str, train_args)))
    key = f'model-f{args.train_frames}-c{args.cameras}-{args.width}x{args.height}-' \
          f's{args.train_seed}-m{args.train_motion_seed}-steps{args.train_steps}' \
          f'{f"-k{args.train_subjects}" if several else ""}'
    return train_synth, train_args, settings, key


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.add_argument('--work', required=True, help='recordings, model and outputs (cached)')
    p.add_argument('--subjects-list', type=int, nargs='+', default=[1, 2, 3])
    p.add_argument('--frames', type=int, default=300)
    p.add_argument('--cameras', type=int, default=8)
    p.add_argument('--width', type=int, default=320)
    p.add_argument('--height', type=int, default=240)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--train-frames', type=int, default=300)
    p.add_argument('--label-fraction', type=float, default=0.05)
    p.add_argument('--train-seed', type=int, default=None,
                   help='seed (rig, look, room) of the training recording (default --seed)')
    p.add_argument('--train-motion-seed', type=int, default=7,
                   help='motion seed of the training recording (default %(default)s)')
    p.add_argument('--train-steps', type=int, default=1500)
    p.add_argument('--train-subjects', type=int, default=1,
                   help='subjects in the training recording, every one labelled (`monet synth '
                   '--subjects K --label-subjects`; default %(default)s: one subject); with '
                   'K > 1 the model is WORK/model-...-kK and the outputs WORK/out-...-tK')
    p.add_argument('--threads', type=int, default=1, help='torch threads of train/process')
    p.add_argument('--match-m', type=float, default=0.3,
                   help='largest mean keypoint distance (m) of a match')
    p.add_argument('--rival-peaks', action=argparse.BooleanOptionalAction, default=None,
                   help='pass --rival-peaks / --no-rival-peaks to monet process --subjects '
                   "(default: neither, the command's default); outputs in WORK/out-nN-rival "
                   '/ out-nN-norival')
    p.add_argument('--foreign-views', action=argparse.BooleanOptionalAction, default=None,
                   help='pass --foreign-views / --no-foreign-views to monet process --subjects '
                   "(default: neither, the command's default); outputs in WORK/out-nN-foreign "
                   '/ out-nN-noforeign')
    p.add_argument('--min-score', type=float, default=None,
                   help="pass --min-score to monet process --subjects (default: the command's "
                   'default); outputs in WORK/out-nN-msX')
    p.add_argument('--out', default=str(REPO / 'bench' / 'results' / 'subjects_process.md'))
    args = p.parse_args(argv)
    if not 1 <= args.train_subjects <= 3:
        p.error(f'--train-subjects: must be 1, 2 or 3, got {args.train_subjects}')
    extra, suffix = {None: ([], ''), True: (['--rival-peaks'], '-rival'),
                     False: (['--no-rival-peaks'], '-norival')}[args.rival_peaks]
    if args.foreign_views is not None:
        extra = extra + ['--foreign-views' if args.foreign_views else '--no-foreign-views']
        suffix += '-foreign' if args.foreign_views else '-noforeign'
    if args.min_score is not None:
        extra, suffix = extra + ['--min-score', str(args.min_score)], \
            suffix + f'-ms{args.min_score:g}'

    if args.train_seed is None:
        args.train_seed = args.seed
    # the K = 1 names are those of before the option, so its cache and outputs stay valid
    several = args.train_subjects > 1
    suffix += f'-t{args.train_subjects}' if several else ''
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    start_load = load()
    started = time.perf_counter()
    say(f'CPU {cpu_model()}; load average {start_load}')
    rig = ['--cameras', args.cameras, '--width', args.width, '--height', args.height,
           '--distinct-sides', '--quiet']

    # 1. the detector
    train_synth, train_args, settings, key = detector_commands(args, rig)

    def make_model(folder):
        folder.mkdir(parents=True)
        say(f'{folder}: monet synth ({args.train_subjects} subject(s), labels) ...')
        monet([*train_synth[:1], '--out', folder / 'data', *train_synth[1:]])
        say(f'{folder}: monet train ({args.train_steps} steps, input 128; load {load()}) ...')
        _, wall, cpu = monet(['train', folder / 'data', '--out', folder / 'train', *train_args],
                             log=folder / 'train.log')
        shutil.copyfile(folder / 'train' / 'model.pt', folder / 'model.pt')
        (folder / 'train_time.json').write_text(json.dumps(dict(wall=wall, cpu=cpu)))

    cached(work / key, settings, make_model)
    model = work / key / 'model.pt'
    train_wall = json.loads((work / key / 'train_time.json').read_text())
    say(f'model {model} (training took {train_wall["wall"]:.0f} s wall, '
        f'{train_wall["cpu"]:.0f} s CPU)')

    # 2. recordings, processing, scores
    recordings = {}
    for n in sorted(set(args.subjects_list) | {1}):
        folder = work / f'rec-n{n}-f{args.frames}-c{args.cameras}-{args.width}x{args.height}-' \
                        f's{args.seed}'
        synth = ['synth', '--frames', args.frames, '--seed', args.seed, '--subjects', n, *rig]

        def make_recording(folder, synth=synth, n=n):
            say(f'{folder}: monet synth --subjects {n} ...')
            monet([*synth[:1], '--out', folder, *synth[1:]])

        cached(folder, list(map(str, synth)), make_recording)
        recordings[n] = folder

    say(f'baseline: monet process (one subject) on {recordings[1].name}; load {load()}')
    base_out = work / f'out-baseline{"-t%d" % args.train_subjects if several else ""}'
    base_run = process(recordings[1], model, base_out, None, args.threads)
    base, base_ids = score(base_out / 'keypoints3d.csv', recordings[1], args.match_m)
    base_mm = 1000 * float(base.error[0])
    rows, plots = [], [('one subject, no --subjects', base, args.frames)]
    for n in args.subjects_list:
        say(f'N={n}: monet process --subjects {n} {" ".join(extra)}; load {load()}')
        run = process(recordings[n], model, work / f'out-n{n}{suffix}', n, args.threads, extra)
        s, identities = score(work / f'out-n{n}{suffix}' / 'keypoints3d.csv', recordings[n],
                              args.match_m)
        _, _, truth = ground_truth(recordings[n])
        rows.append((n, run, s, identities, closest_pass(truth)))
        plots.append((f'--subjects {n}', s, args.frames))
        say(f'N={n}: IDSW {s.switches}, IDF1 {s.idf1:.3f}, error '
            f'{", ".join(f"{1000 * e:.0f}" for e in s.error)} mm, found '
            f'{", ".join(f"{f / args.frames:.0%}" for f in s.found)}')
    end_load = load()

    # 3. the report
    out = Path(args.out)
    png = out.with_suffix('.png')
    out.parent.mkdir(parents=True, exist_ok=True)
    plot(png, plots, args.match_m)
    command = ' '.join(['nice .venv/bin/python bench/subjects_process.py',
                        *(sys.argv[1:] if argv is None else argv)])
    lines = [
        '# `monet process --subjects N` on synthetic humans (our detector)', '',
        f'`{command}`', '',
        f'Measured {time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())} on {cpu_model()} '
        f'({os.cpu_count()} cores, shared), load average {start_load} at start, {end_load} '
        f'at end; {time.perf_counter() - started:.0f} s in all.', '',
        f'- Detector: `monet synth --frames {args.train_frames} --label-fraction '
        f'{args.label_fraction} --seed {args.train_seed} --motion-seed '
        f'{args.train_motion_seed} --cameras {args.cameras} --width '
        f'{args.width} --height {args.height} --distinct-sides'
        + (f' --subjects {args.train_subjects} --label-subjects` (every subject labelled)'
           if several else '` (one subject)') + ', then `monet '
        f'train DATA --input-size 128 --steps {args.train_steps} --threads {args.threads}` '
        f'(default mode, small net, precision auto): {train_wall["wall"]:.0f} s wall, '
        f'{train_wall["cpu"]:.0f} s CPU (cached when rerun).',
        f'- Recordings: `monet synth --subjects N --frames {args.frames} --seed {args.seed} '
        f'--cameras {args.cameras} --width {args.width} --height {args.height} '
        '--distinct-sides` (30 frames/s; rings of 0.7 / 1.4 / 2.1 m); processed with '
        f'`monet process REC/recording --model M --subjects N --threads {args.threads} '
        f'--export csv{"".join(" " + e for e in extra)}` (the other options at their '
        'defaults); baseline: the same without '
        '`--subjects` on the N = 1 recording.',
        f'- Scores: keypoints3d.csv against ground_truth.npz, match within {args.match_m} m '
        '(mean keypoint distance); 3D error: mean over matched frames; found: frames matched '
        "/ frames; ratio: 3D error / the baseline's; frames/s: frames / wall of the whole "
        'command (start-up included), loop: the frame loop only (its summary line); CPU: the '
        "command's process CPU time per frame.", '',
        '<!-- --8<-- [start:table] -->',
        '| subjects | closest pass (m) | identities (births) | IDSW | IDF1 | 3D error per '
        'subject (mm) | ratio to one subject | found | frames/s (loop) | CPU ms/frame |',
        '|---|---|---|---|---|---|---|---|---|---|',
        f'| baseline: 1, no --subjects | - | {base_ids} | {base.switches} | {base.idf1:.3f} | '
        f'{base_mm:.0f} | 1.00 | {base.found[0] / args.frames:.0%} | '
        f'{base_run["frames"] / base_run["wall"]:.1f} '
        f'({base_run["frames"] / base_run["loop_s"]:.1f}) | '
        f'{1000 * base_run["cpu"] / max(base_run["frames"], 1):.0f} |']
    for n, run, s, identities, gap in rows:
        err = 1000 * s.error
        births = '-' if run['births'] is None else run['births']
        lines.append(
            f'| {n} | {"-" if gap is None else f"{gap:.2f}"} | {identities} ({births}) | '
            f'{s.switches} | {s.idf1:.3f} | {", ".join(f"{e:.0f}" for e in err)} | '
            f'{", ".join(f"{e / base_mm:.2f}" for e in err)} | '
            f'{", ".join(f"{f / args.frames:.0%}" for f in s.found)} | '
            f'{run["frames"] / run["wall"]:.1f} ({run["frames"] / run["loop_s"]:.1f}) | '
            f'{1000 * run["cpu"] / max(run["frames"], 1):.0f} |')
    lines += ['<!-- --8<-- [end:table] -->', '',
              f'![3D error and identity per frame]({png.name})', '']
    out.write_text('\n'.join(lines))
    print('\n'.join(lines))
    say(f'wrote {out} and {png}')


if __name__ == '__main__':
    main()

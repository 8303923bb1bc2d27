"""`monet synth`: render a synthetic calibrated rig + moving subject to a recording folder."""

HELP = ('render a synthetic calibrated rig and a moving articulated subject to a rosbag2 '
        'MCAP, with rig file, sparse 2D labels and 3D ground truth')


def _floats(text):
    try:
        return tuple(float(v) for v in text.split(',') if v.strip())
    except ValueError:
        raise ValueError(f'expected comma-separated numbers, got {text!r}') from None


def add_arguments(parser):
    from monet_ros.synth.recording import SynthConfig

    d = SynthConfig.__dataclass_fields__
    parser.add_argument('--out', required=True,
                        help='output folder (must not exist or be empty)')
    parser.add_argument('--cameras', type=int, default=d['cameras'].default,
                        help='number of cameras (default %(default)s)')
    parser.add_argument('--frames', type=int, default=d['frames'].default,
                        help='number of instants (default %(default)s)')
    parser.add_argument('--fps', type=float, default=d['fps'].default,
                        help='frame rate (default %(default)s)')
    parser.add_argument('--width', type=int, default=d['width'].default,
                        help='image width in pixels (default %(default)s)')
    parser.add_argument('--height', type=int, default=d['height'].default,
                        help='image height in pixels (default %(default)s)')
    parser.add_argument('--skeleton', default=d['skeleton'].default,
                        help='human14 | quadruped13 | path to a skeleton YAML whose keypoints '
                             'are joints of one of those bodies (default %(default)s)')
    parser.add_argument('--layout', choices=('ring', 'dome'), default=d['layout'].default,
                        help='camera layout (default %(default)s)')
    parser.add_argument('--label-fraction', type=float, default=d['label_fraction'].default,
                        help='fraction of instants labelled in every view, at least one '
                             '(default %(default)s)')
    parser.add_argument('--seed', type=int, default=d['seed'].default,
                        help='random seed: same seed, same bytes (default %(default)s)')
    parser.add_argument('--motion-seed', type=int, default=None,
                        help="seed of the subjects' motion only (paths, speeds, gestures): "
                        'the rig, look and room stay those of --seed (default: --seed)')
    parser.add_argument('--distortion', default=','.join(
        str(v) for v in d['distortion'].default),
        help='OpenCV distortion k1[,k2,p1,p2,k3] of every camera, e.g. '
             '--distortion=-0.1,0.02 (seeded +-10%% per camera; default %(default)s; '
             '0 = none)')
    parser.add_argument('--radius', type=float, default=None,
                        help='camera distance from the centre in metres (default 4 for a '
                             'human, 2.5 for a quadruped)')
    parser.add_argument('--hfov', type=float, default=d['hfov_deg'].default,
                        help='horizontal field of view in degrees (default %(default)s)')
    parser.add_argument('--noise', type=float, default=d['noise'].default,
                        help='sensor noise standard deviation in grey levels '
                             '(default %(default)s)')
    parser.add_argument('--visible-labels-only', action='store_true',
                        help='label only keypoints not hidden by another limb (default: '
                             'every keypoint inside the image)')
    parser.add_argument('--distinct-sides', action='store_true',
                        help="render the subject's left limbs in their own colour (default: "
                        'left and right look alike)')
    parser.add_argument('--height-spread', type=float, default=d['height_spread'].default,
                        help='ring: cameras alternately up to this many metres above / below '
                             'the nominal height (non-coplanar; default %(default)s)')
    parser.add_argument('--occluders', type=int, default=d['occluders'].default,
                        help='static pillars (up to hip height) between the path and that '
                             'many cameras, hiding limbs from some views (default %(default)s)')
    parser.add_argument('--subjects', type=int, default=d['subjects'].default,
                        help='subjects (1-3) walking rings that pass and hide each other; '
                        'with 2 or more, ground_truth.npz holds them all and points2d.csv '
                        'their per-camera instances, shuffled (default %(default)s)')
    parser.add_argument('--label-subjects', action='store_true',
                        help='with --subjects 2 or more: labels.csv labels every subject '
                        '(a subject column: slot s of ground_truth.npz is subject s; default: '
                        'subject 0 only)')
    parser.add_argument('--quiet', action='store_true', help='no progress bar')


def config_from_args(args):
    """SynthConfig from parsed arguments (SynthError / ValueError naming the option)."""
    from monet_ros.synth.recording import SynthConfig, SynthError

    try:
        distortion = _floats(args.distortion)
    except ValueError as error:
        raise SynthError(f'--distortion: {error}') from None
    return SynthConfig(
        cameras=args.cameras, frames=args.frames, fps=args.fps, width=args.width,
        height=args.height, skeleton=args.skeleton, layout=args.layout,
        label_fraction=args.label_fraction, seed=args.seed, distortion=distortion,
        radius=args.radius, hfov_deg=args.hfov, noise=args.noise,
        label_occluded=not args.visible_labels_only, height_spread=args.height_spread,
        occluders=args.occluders, distinct_sides=args.distinct_sides,
        subjects=args.subjects, motion_seed=args.motion_seed,
        label_subjects=args.label_subjects)


def run(args):
    """Writes the recording atomically: a run that fails or is stopped leaves no folder."""
    from dataclasses import replace
    from pathlib import Path

    from monet_ros.commands.common import atomic_output_dir, check_new_output
    from monet_ros.synth.recording import synthesize

    config = config_from_args(args)
    out = Path(args.out)
    check_new_output(out, 'monet synth')
    with atomic_output_dir(out) as staging:
        result = synthesize(config, staging, progress=not args.quiet)
        readme = staging / 'README.md'          # it names the folder: the final one
        readme.write_text(readme.read_text().replace(str(staging), str(out)))
    print(replace(result, out=out).summary())
    return 0

"""The --filter options of `monet process` and `monet triangulate` (one spelling for both):
the fields of monet_ros.temporal.FilterConfig as command-line options."""
from dataclasses import fields

import numpy as np

from monet_ros.commands.common import (
    add_config_options,
    config_from_options,
    config_options,
    options_named,
)
from monet_ros.temporal import LOSSES, METHODS, FilterConfig

FILTER_TOPIC = '/monet/keypoints3d_filtered'


def filter_options():
    """{option: field} of the FilterConfig settings typed as --its-name (--max-gap-s,
    --measurement-noise-mm, ...): every field but the method and loss (--filter, --loss:
    choices) and the thresholds that come from the fusion's options."""
    return config_options(FilterConfig, exclude=('method', 'loss', 'confidence_threshold',
                                                 'threshold_px'))


def add_filter_arguments(parser):
    """--filter {none,kalman,optim} and the filter's parameters (physical units)."""
    meta = {f.name: f for f in fields(FilterConfig)}
    parser.add_argument('--filter', choices=METHODS, default='none',
                        help='3D over time: none (frame-by-frame robust triangulation), '
                        'kalman (constant-velocity Kalman + RTS smoother with outlier gating; '
                        'fast) or optim (least squares over the recording: robust '
                        'reprojection + smoothness + bone lengths of --skeleton)')
    add_config_options(parser, FilterConfig, filter_options())
    parser.add_argument('--loss', choices=LOSSES, default=meta['loss'].default,
                        help=f'{meta["loss"].metadata["description"]} (default '
                        f'{meta["loss"].default})')


def filter_config_from_args(args, confidence_threshold, threshold_px):
    """FilterConfig of the options above; the fusion's thresholds decide which views count.
    Its Kalman numbers depend on the rig's unit: check_filter_units checks them once the
    rig is loaded. Raises ValueError naming the option (commands.common.config_from_options;
    ConfigError naming the field for the others)."""
    return config_from_options(args, FilterConfig, filter_options(), method=args.filter,
                               loss=args.loss, confidence_threshold=confidence_threshold,
                               threshold_px=threshold_px)


def check_filter_units(filter_config, units):
    """Check the numbers of `filter_config` (None or a temporal.FilterConfig) in the rig's
    length unit `units` ('m', 'cm', 'mm') before any work (FilterConfig.in_units, where
    kalman and optim convert them); nothing for None or method 'none'. Raises ValueError
    naming the option, e.g. --measurement-noise-mm 1e200, whose square overflows (1e155
    only with a rig in mm)."""
    if filter_config is not None and filter_config.method != 'none':
        with options_named(FilterConfig, filter_options()):
            filter_config.in_units(units)


def write_filtered_subjects(writer, frame_id, smoothed, stamps_ns, units, topic=FILTER_TOPIC):
    """The filtered rows of a subjects.offline.SmoothedSubjects (rig unit `units`) as the
    several-subject /monet/keypoints3d messages (metres, `subject` field, one point per
    keypoint and subject in identity order, as the live fusion publishes them) on `topic`,
    one per instant of stamps_ns (an empty cloud where no identity has a row)."""
    rows = smoothed.rows
    C = rows.X.shape[1] if rows.X.ndim == 3 else 0
    order = np.lexsort((rows.subject, rows.frame))
    frame = rows.frame[order]
    bounds = np.searchsorted(frame, np.arange(len(stamps_ns) + 1))
    for t, stamp in enumerate(stamps_ns):
        at = order[bounds[t]:bounds[t + 1]]
        ids = rows.subject[at].astype(np.int64)
        writer.write_keypoints3d(topic, int(stamp), frame_id, rows.X[at].reshape(-1, 3),
                                 rows.score[at].reshape(-1), rows.error[at].reshape(-1),
                                 rows.ncams[at].reshape(-1), units=units,
                                 keypoint=np.tile(np.arange(C), len(ids)),
                                 subject=np.repeat(ids, C))


def write_filtered(writer, frame_id, smoothed, stamps_ns, units, topic=FILTER_TOPIC):
    """The filtered points of a temporal.Smoothed (in the rig's length unit `units`) as
    /monet/keypoints3d messages (same layout, metres) on `topic`, one per instant of
    stamps_ns."""
    for t, stamp in enumerate(stamps_ns):
        writer.write_keypoints3d(topic, int(stamp), frame_id, smoothed.X[t], smoothed.score[t],
                                 smoothed.error[t], smoothed.ncams[t], units=units)

"""`monet process`: the detector + fusion core over a recording, offline and as fast as
possible, writing /monet/keypoints3d (and optionally the heatmaps) to a rosbag2 MCAP.

    monet process REC --model CKPT --out OUT [--rig RIG] [--heatmaps]

The same functions as the live nodes: Detector.predict (one batched forward per instant),
crop_rule.TrackedCrops (the detector node's crop rule: around the previous instant's 3D
keypoints), fusion.fuse_heatmaps.
"""
from pathlib import Path
import sys
import time

import numpy as np

HELP = 'run detector + fusion over a recording offline, write keypoints3d to an MCAP'


def add_arguments(parser):
    parser.add_argument('bag', help='recording: rosbag2 folder or .mcap')
    parser.add_argument('--model', required=True, help='detector checkpoint')
    parser.add_argument('--out', required=True, help='output rosbag2 folder (must not exist)')
    parser.add_argument('--rig', help="rig file (default: the recording's camera_info + "
                        '/tf_static)')
    parser.add_argument('--cameras', nargs='+', help='cameras to use (default: all)')
    parser.add_argument('--skeleton', default=None,
                        help='skeleton preset or YAML; checked against the model keypoints')
    parser.add_argument('--slop-ms', type=float, default=0.0,
                        help='stamp tolerance between cameras (0 = exact)')
    parser.add_argument('--threshold-px', type=float, default=15.0,
                        help='fusion inlier threshold (image pixels)')
    parser.add_argument('--confidence-threshold', type=float, default=0.1,
                        help='heatmap peak value below which a view is ignored')
    parser.add_argument('--min-views', type=int, default=2, help='fewest inlier views')
    parser.add_argument('--method', choices=('exclusion', 'ransac'), default='exclusion')
    parser.add_argument('--no-track', action='store_true',
                        help='full-frame crops instead of following the subject')
    parser.add_argument('--heatmaps', action='store_true',
                        help='also write /monet/<cam>/heatmaps')
    parser.add_argument('--device', default=None, help='torch device (default: auto)')
    parser.add_argument('--quiet', action='store_true', help='no progress bar')


def process_recording(bag, model, out, rig=None, cameras=(), fusion_config=None, slop_ns=0,
                      track=True, heatmaps=False, skeleton=None, device=None, progress=True):
    """Detect + fuse every instant of `bag`; write `out`. Returns a dict of figures."""
    from tqdm import tqdm

    from monet_ros.crop_rule import TrackedCrops
    from monet_ros.fusion import FusionConfig, fuse_heatmaps
    from monet_ros.io import BagWriter, iter_multiview_frames, open_bag
    from monet_ros.models import Detector
    from monet_ros.nodes.rig import load_node_rig, select_cameras
    from monet_ros.skeleton import load_skeleton

    if Path(out).exists():
        raise FileExistsError(f'{out}: output exists; choose a new folder')
    fusion_config = fusion_config or FusionConfig()
    rig_cameras, frame_id = load_node_rig(rig or bag)
    cameras = select_cameras('monet process', rig_cameras, cameras or (), minimum=2)
    detector = Detector.from_checkpoint(model, device=device)
    if skeleton is not None:
        names = list(load_skeleton(skeleton).keypoints)
        if names != list(detector.keypoints):
            raise ValueError(f'skeleton {skeleton} keypoints {names} differ from the model '
                             f'keypoints {list(detector.keypoints)}')
    reader = open_bag(bag)
    topics = {}
    for cam in cameras:
        topic = cam.topic or f'/{cam.name}/image_raw'
        if topic not in reader.topics and topic + '/compressed' in reader.topics:
            topic += '/compressed'
        if topic not in reader.topics:
            raise ValueError(f'{bag}: no image topic {topic!r} for camera {cam.name!r}')
        topics[cam.name] = topic
    by_name = {cam.name: cam for cam in cameras}
    figures = dict(frames=0, views=0, missing_views=0, seconds=0.0, errors=[], num_views=[])
    tracker = TrackedCrops()          # the detector node's defaults (track_* parameters)
    start = time.perf_counter()
    with BagWriter(out) as writer:
        frames = iter_multiview_frames(reader, topics, slop_ns=slop_ns)
        for frame in tqdm(frames, desc='monet process', unit='frame', disable=not progress,
                          file=sys.stderr):
            present = [by_name[n] for n in topics if n in frame.images]
            figures['missing_views'] += len(topics) - len(present)
            if len(present) < fusion_config.min_views:
                continue
            images = [np.asarray(frame.images[cam.name]) for cam in present]
            images = [np.repeat(im[..., None], 3, axis=2) if im.ndim == 2 else im
                      for im in images]
            boxes = tracker.boxes(present, frame.stamp_ns if track else None)
            boxes = detector.boxes_for(present, boxes)
            heat, heat_cameras = detector.predict(images, present, boxes, keep_aspect=False)
            result = fuse_heatmaps(heat, np.stack([c.K for c in heat_cameras]), present,
                                   fusion_config)
            writer.write_keypoints3d('/monet/keypoints3d', frame.stamp_ns, frame_id,
                                     result.X, result.confidence, result.reprojection_error,
                                     result.num_views)
            if heatmaps:
                for cam, hm in zip(present, heat):
                    writer.write_heatmaps(f'/monet/{cam.name}/heatmaps', frame.stamp_ns, hm,
                                          cam.name)
            finite = np.isfinite(result.X).all(axis=1)
            if track:
                tracker.update(result.X, frame.stamp_ns)
            figures['frames'] += 1
            figures['views'] += len(present)
            figures['errors'].append(float(np.nanmean(result.reprojection_error))
                                     if finite.any() else np.nan)
            figures['num_views'].append(float(result.num_views.mean()))
    figures['seconds'] = time.perf_counter() - start
    figures['report'] = reader.report
    return figures


def run(args):
    from monet_ros.fusion import FusionConfig
    from monet_ros.nodes.runner import start_error

    try:
        config = FusionConfig(threshold_px=args.threshold_px,
                              confidence_threshold=args.confidence_threshold,
                              min_views=args.min_views, method=args.method)
        figures = process_recording(
            args.bag, args.model, args.out, rig=args.rig, cameras=args.cameras or (),
            fusion_config=config, slop_ns=int(args.slop_ms * 1e6), track=not args.no_track,
            heatmaps=args.heatmaps, skeleton=args.skeleton, device=args.device,
            progress=not args.quiet)
    except (ValueError, OSError) as error:
        start_error('monet process', error)
        return 2
    errors = np.array(figures['errors'], float)
    fps = figures['frames'] / figures['seconds'] if figures['seconds'] else 0.0
    print(f'monet process: {figures["frames"]} frames ({figures["views"]} views, '
          f'{figures["missing_views"]} missing) in {figures["seconds"]:.1f} s '
          f'({fps:.1f} frames/s); mean reprojection error '
          f'{np.nanmean(errors) if np.isfinite(errors).any() else float("nan"):.2f} px; '
          f'mean inlier views {np.mean(figures["num_views"]) if figures["num_views"] else 0:.2f}'
          f' -> {args.out}')
    report = figures['report']
    if report is not None and not report.ok:
        print(f'monet process: reading {args.bag}: {report.summary()}', file=sys.stderr)
    return 0

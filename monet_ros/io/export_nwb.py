"""Per-frame keypoints as NWB with ndx-pose (pynwb 4.2 + ndx-pose 0.4; no ROS).

write_nwb(path, result) writes one NWBFile holding, in processing module 'behavior':
- Skeletons with one Skeleton (nodes = keypoints, edges = the skeleton's bones when given);
- MultiCameraPoseEstimation 'monet_pose': one PoseEstimationSeries per keypoint with the
  3D points (T, 3) in the rig's world frame and unit (unit 'meters', 'centimeters' or
  'millimeters', Camera.units), confidence = mean peak value of the
  inlier views, timestamps = seconds from the time origin (export_tables.TIME_BASE: the
  TRC Time of the same instant; for 2D tables source frame / fps); and one
  PoseEstimation per camera ('<camera>_2d', device = a CalibratedCamera with K, R, t, dist
  of the source image) whose PoseEstimationSeries hold the 2D detections (T, 2) in source
  image pixels with the heatmap peak value as confidence (NaN where not detected).
With a filter (`--filter kalman|optim`) the 3D series hold the filtered points and their
confidence, and the module also holds two TimeSeries (T, C), columns in keypoint order:
'filter_change_mm' (|filtered - raw|, mm) and 'filter_bridged' (1 where the raw point was
missing and the filter bridged the gap).
session_start_time = the time origin (the first stamp, or origin_ns when given; UTC, to the
microsecond: datetime's resolution), so session_start_time + timestamp is the header stamp
within 1 us. With fnum (the source's frame numbers, `monet triangulate`) the module also
holds a TimeSeries 'source_frame' (T,) of them. Read back with
pynwb.NWBHDF5IO (ndx_pose imported).
"""
from datetime import datetime, timedelta, timezone
import os
from pathlib import Path

import numpy as np


def write_nwb(path, keypoints, stamps_ns, X, score, cameras, points2d, confidence2d,
              edges=None, description='monet_ros multiview keypoints', filtered=None,
              fnum=None, origin_ns=None, subjects=None):
    """keypoints (C,); stamps_ns (T,); X (T, C, 3); score (T, C); cameras: V Camera;
    points2d (T, V, C, 2) source px or None (no 2D series); confidence2d (T, V, C);
    subjects: None, or several subjects [(identity, X (T, C, 3), score (T, C)), ...]
    (X and score then unused, NaN where a subject is absent): one
    MultiCameraPoseEstimation 'monet_pose_subject<identity>' per subject;
    filtered: None or dict(method, change_mm (T, C), bridged (T, C)) when X is a filter's
    output; with subjects dict(method, subjects={identity: (change_mm (T, C), bridged
    (T, C))}), written as filter_change_mm_subject<identity> / filter_bridged_subject<id>.
    X and the cameras' t are in the cameras' length unit (Camera.units), stated as
    the 3D series' unit; fnum: None or (T,) int source frame numbers (recorded as
    'source_frame'); origin_ns: the time origin (int ns, default the first stamp). Atomic
    (tmp + os.replace)."""
    from ndx_pose import (
        CalibratedCamera,
        MultiCameraPoseEstimation,
        PoseEstimation,
        PoseEstimationSeries,
        Skeleton,
        Skeletons,
    )
    from pynwb import NWBHDF5IO, NWBFile, TimeSeries

    import monet_ros
    from monet_ros.geometry.units import NWB_NAMES, rig_units
    from monet_ros.io.export_tables import export_times, source_frames

    stamps = np.asarray(stamps_ns, dtype=np.int64)
    origin = origin_ns if origin_ns is not None else int(stamps[0]) if len(stamps) else None
    start = datetime.fromtimestamp(0, tz=timezone.utc) + timedelta(
        microseconds=int(origin) // 1000) if origin is not None else datetime.now(timezone.utc)
    times = export_times(stamps, origin_ns)
    nwb = NWBFile(session_description=description, identifier=f'monet-{int(stamps[0])}'
                  if len(stamps) else 'monet', session_start_time=start)
    behavior = nwb.create_processing_module('behavior', 'keypoints from monet_ros')
    # (E, 2) node index pairs; a skeleton without bones has none: (0, 2), never (0,)
    skeleton = Skeleton(name='skeleton', nodes=list(keypoints),
                        edges=np.asarray(edges if edges is not None else (),
                                         dtype='uint8').reshape(-1, 2))
    behavior.add(Skeletons(skeletons=[skeleton]))
    version = getattr(monet_ros, '__version__', '')
    if fnum is not None:
        behavior.add(TimeSeries(
            name='source_frame', data=source_frames(stamps, fnum), unit='frames',
            timestamps=times, description="the source's frame number of each instant "
            '(0-based video frame, as the 2D tables number it)'))
    per_camera = []
    for v, cam in enumerate(cameras):
        device = CalibratedCamera(name=cam.name, intrinsic_matrix=np.asarray(cam.K),
                                  rotation_matrix=np.asarray(cam.R),
                                  translation_vector=np.asarray(cam.t),
                                  distortion_coefficients=np.asarray(cam.dist),
                                  description=f'{cam.width}x{cam.height} px; '
                                  f'translation in {NWB_NAMES[cam.units]}')
        nwb.add_device(device)
        if points2d is None:
            continue
        series = [PoseEstimationSeries(
            name=k, data=np.asarray(points2d[:, v, c], float), unit='pixels',
            reference_frame=f'{cam.name} source image, pixel centres on integers',
            confidence=np.asarray(confidence2d[:, v, c], float),
            confidence_definition='heatmap peak value', timestamps=times)
            for c, k in enumerate(keypoints)]
        per_camera.append(PoseEstimation(
            name=f'{cam.name}_2d', pose_estimation_series=series, device=device,
            description=f'2D detections of {cam.name}', scorer='monet_ros detector',
            source_software='monet_ros', source_software_version=str(version),
            skeleton=skeleton))
    unit = NWB_NAMES[rig_units(cameras)]

    def series3d(X, score):
        return [PoseEstimationSeries(
            name=k, data=np.asarray(X[:, c], float), unit=unit,
            reference_frame='rig world frame', confidence=np.asarray(score[:, c], float),
            confidence_definition='mean heatmap peak value of the inlier views',
            timestamps=times) for c, k in enumerate(keypoints)]
    how = 'triangulated keypoints (robust DLT over inlier views)'
    if filtered is not None:
        how += f', filtered over time ({filtered["method"]})'
        order = ', '.join(keypoints)
        series = filtered['subjects'] if 'subjects' in filtered else \
            {None: (filtered['change_mm'], filtered['bridged'])}
        for ident, (change, bridged) in series.items():
            tail, whose = ('', '') if ident is None else (f'_subject{ident}',
                                                          f' of subject {ident}')
            behavior.add(TimeSeries(
                name=f'filter_change_mm{tail}', data=np.asarray(change, float),
                unit='mm', timestamps=times,
                description=f'|filtered - raw| per keypoint{whose} ({order})'))
            behavior.add(TimeSeries(
                name=f'filter_bridged{tail}', data=np.asarray(bridged, np.uint8),
                unit='n.a.', timestamps=times,
                description=f'1 where the raw point{whose} was missing and the filter '
                f'bridged the gap ({order})'))
    poses = [('monet_pose', X, score, how)] if subjects is None else [
        (f'monet_pose_subject{int(i)}', Xs, ss, f'{how}; subject {int(i)} (NaN where absent)')
        for i, Xs, ss in subjects]
    for name, Xs, ss, text in poses:
        behavior.add(MultiCameraPoseEstimation(
            name=name, pose_estimation_series=series3d(Xs, ss),
            pose_estimations=per_camera or None, description=text,
            scorer='monet_ros fusion', source_software='monet_ros',
            source_software_version=str(version), skeleton=skeleton))
    path = Path(path)
    tmp = path.with_name(f'.{path.stem}.tmp.nwb')
    with NWBHDF5IO(str(tmp), 'w') as io:
        io.write(nwb)
    os.replace(tmp, path)
    return path

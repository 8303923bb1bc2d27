"""Two subjects of three coloured blobs each (blob_net's keypoints a, b, c in its colours)
walking past each other in front of a ring rig, written as a `monet synth --subjects`
style folder (rosbag2 + rig.yaml + ground_truth.npz with subjects_keypoints3d), and the
blob net as a checkpoint: a real recording and a real trained detector for `monet process
--subjects` in seconds."""
from pathlib import Path

import numpy as np

from helpers.blob_net import COLOURS, NAMES, train_blob_net
from helpers.ring import ring_rig
from monet_ros.geometry import save_rig
from monet_ros.io import BagWriter
from monet_ros.models import save_checkpoint

T0 = 1_767_225_600_000_000_000
PERIOD = 33_333_333
# each subject's blobs about its centre (m): a above, b and c below, 0.32 m across
SHAPE = np.array([[0.0, 0.0, 0.2], [-0.16, 0.06, -0.1], [0.16, -0.06, -0.1]])


def two_subjects(T, spacing=0.7, speed=1.5):
    """(T, 2, 3, 3) m: subject 0 walks +x at y = -spacing / 2, subject 1 -x at
    y = +spacing / 2, passing each other at the middle frame, at `speed` m/s (30 fps)."""
    t = (np.arange(T) - (T - 1) / 2) / 30.0
    centres = np.zeros((T, 2, 3))
    centres[:, 0] = np.stack([speed * t, np.full(T, -spacing / 2), np.ones(T)], -1)
    centres[:, 1] = np.stack([-speed * t, np.full(T, spacing / 2), np.ones(T)], -1)
    return centres[:, :, None] + SHAPE


def render(cameras, X, sigma_px=2.2):
    """V frame arrays (T, H, W, 3) uint8: every subject's blobs (keypoint c in COLOURS[c])
    on blob_net's grey, nearer blobs drawn last."""
    T = len(X)
    frames = []
    for cam in cameras:
        yy, xx = np.mgrid[0:cam.height, 0:cam.width]
        f = np.empty((T, cam.height, cam.width, 3), np.uint8)
        for t in range(T):
            pts = X[t].reshape(-1, 3)
            depth = (pts @ cam.R.T + cam.t)[:, 2]
            img = np.full((cam.height, cam.width, 3), 70.0)
            for i in np.argsort(-depth):
                u, v = cam.project(pts[i:i + 1])[0]
                g = np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * sigma_px ** 2))[..., None]
                img = img * (1 - g) + COLOURS[i % len(NAMES)] * g
            f[t] = np.clip(img, 0, 255).astype(np.uint8)
        frames.append(f)
    return frames


def write_two_subjects(out, T=12, width=96, height=96, focal=190.0, camera_info=False,
                       sigma_px=2.2):
    """Write the folder (rig.yaml, recording/, ground_truth.npz: stamps, keypoints3d
    (subject 0's) and subjects_keypoints3d (T, 2, 3, 3) m); with camera_info, the
    recording also holds /<cam>/camera_info per frame (what `monet pipeline` replays);
    sigma_px: the blobs' size (render's); returns (out, cameras, X)."""
    out = Path(out)
    out.mkdir(parents=True)
    cams = ring_rig(4, radius=3.0, width=width, height=height, focal=focal)
    cams = [c.replace(topic=f'/{c.name}/image_raw') for c in cams]
    X = two_subjects(T)
    save_rig(out / 'rig.yaml', cams)
    stamps = T0 + PERIOD * np.arange(T, dtype=np.int64)
    frames = render(cams, X, sigma_px)
    with BagWriter(out / 'recording') as bag:
        for t, stamp in enumerate(stamps):
            for cam, f in zip(cams, frames):
                bag.write_image(cam.topic, int(stamp), f[t], f'{cam.name}_optical')
                if camera_info:
                    bag.write_camera_info(f'/{cam.name}/camera_info', int(stamp), cam,
                                          f'{cam.name}_optical')
    np.savez_compressed(out / 'ground_truth.npz', stamps=stamps, keypoints3d=X[:, 0],
                        subjects_keypoints3d=X)
    return out, cams, X


def blob_checkpoint(model, path):
    """The blob net as a checkpoint of keypoints a, b, c."""
    save_checkpoint(path, model, {'keypoints': list(NAMES)})
    return path


def two_subject_scene(tmp_path, T=12):
    """What a live two-subject run needs: write_two_subjects' recording (camera_info) in
    tmp_path / 'rec', its ground-truth stamps, X (T, 2, 3, 3), a trained blob detector
    checkpoint and a blobs skeleton YAML (keypoints a, b, c; one bone) ->
    (folder, stamps, X, model, skeleton)."""
    import yaml
    folder, _, X = write_two_subjects(tmp_path / 'rec', T=T, camera_info=True)
    stamps = np.load(folder / 'ground_truth.npz')['stamps'].tolist()
    model = blob_checkpoint(train_blob_net(steps=400, sigma=(1.2, 4.0)), tmp_path / 'b.pt')
    skeleton = tmp_path / 'blobs.yaml'
    skeleton.write_text(yaml.safe_dump({'name': 'blobs', 'keypoints': list(NAMES),
                                        'bones': [[NAMES[0], NAMES[1]]]}))
    return folder, stamps, X, model, skeleton

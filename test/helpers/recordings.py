"""Small recordings and checkpoints for command tests (written with the package's writers)."""
import numpy as np
import torch

from helpers.scenes import ring_rig
from monet_ros.io import BagWriter
from monet_ros.models import build_model, save_checkpoint
from monet_ros.skeleton import load_skeleton

T0 = 1_000_000_000_000_000_000
PERIOD = 33_000_000


def noise_recording(path, cameras=4, frames=6, width=320, height=240, seed=0,
                    compressed=False):
    """A rosbag2 folder: `cameras` Image + CameraInfo topics, /tf_static, noise images
    (compressed: JPEG CompressedImage on /<cam>/image_raw/compressed instead).
    Returns (rig, stamps)."""
    K = np.array([[300.0, 0, width / 2 - 0.5], [0, 300.0, height / 2 - 0.5], [0, 0, 1]])
    rig = [c.replace(width=width, height=height, K=K) for c in ring_rig(cameras)]
    rng = np.random.default_rng(seed)
    stamps = [T0 + i * PERIOD for i in range(frames)]
    with BagWriter(path) as writer:
        writer.write_tf_static(T0, rig)
        for stamp in stamps:
            for cam in rig:
                image = rng.integers(0, 255, (height, width, 3), dtype=np.uint8)
                if compressed:
                    writer.write_compressed_image(f'/{cam.name}/image_raw/compressed', stamp,
                                                  image, f'{cam.name}_optical')
                else:
                    writer.write_image(f'/{cam.name}/image_raw', stamp, image,
                                       f'{cam.name}_optical')
                writer.write_camera_info(f'/{cam.name}/camera_info', stamp, cam,
                                         f'{cam.name}_optical')
    return rig, stamps


def small_checkpoint(path, seed=0, input_size=(128, 96)):
    torch.manual_seed(seed)
    model = build_model('small', 14, input_size=input_size)
    save_checkpoint(path, model, {'keypoints': list(load_skeleton('human14').keypoints)})
    return path


def detector_recording(folder, compressed=False):
    """What a detector node test starts from: a 2-camera 320 x 240 one-frame noise_recording
    at folder/rec (compressed: JPEG on /<cam>/image_raw/compressed only), a small_checkpoint
    at folder/model.pt, and the detector's parameters that use them (rig read from the
    recording, device cpu). Returns (rig, params)."""
    rig, _ = noise_recording(folder / 'rec', cameras=2, frames=1, compressed=compressed)
    model = small_checkpoint(folder / 'model.pt')
    return rig, dict(rig=str(folder / 'rec'), model=str(model), device='cpu')

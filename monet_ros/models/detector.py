"""Inference API: crop every camera's image, one batched forward pass, heatmaps + K_heat.

Input normalisation (the same for training and inference): images are uint8 RGB; the
network takes float RGB in [0, 1] (x / 255) and normalises with fixed mean/std inside its
forward (monet_ros.models.layers.Normalize), so no caller ever normalises differently.
"""
import copy

import numpy as np
import torch

from monet_ros.models.checkpoint import load_checkpoint
from monet_ros.models.crop import crop_images, fit_boxes_to_aspect, full_frame_boxes
from monet_ros.models.layers import fuse_for_inference


def images_to_tensor(images, device='cpu'):
    """(N, H, W, 3) uint8 RGB (numpy or torch) -> (N, 3, H, W) float32 in [0, 1] on device.

    The one conversion used by the detector and the trainer; the uint8 array is moved to the
    device before the conversion (4x less to copy to a GPU).
    """
    tensor = torch.as_tensor(np.ascontiguousarray(images) if isinstance(images, np.ndarray)
                             else images)
    if tensor.dtype != torch.uint8 or tensor.ndim != 4 or tensor.shape[-1] != 3:
        raise ValueError(f'images must be (N, H, W, 3) uint8 RGB, got {tuple(tensor.shape)} '
                         f'{tensor.dtype}')
    return tensor.to(device).permute(0, 3, 1, 2).float().div_(255.0)


class Detector:
    """Heatmaps for the synchronized images of several cameras in one forward pass.

    model: a detector from build_model / load_checkpoint (it is copied, put in eval mode,
    BatchNorm folded into the convolutions, so the caller's model is never changed).
    metadata: its checkpoint metadata (at least 'keypoints'). device: None = CUDA when
    available, else CPU.
    """

    def __init__(self, model, metadata, device=None, fuse=True):
        keypoints = list(metadata.get('keypoints', []))
        if len(keypoints) != model.num_keypoints:
            raise ValueError(f'Detector: metadata.keypoints has {len(keypoints)} names but the '
                             f'model has {model.num_keypoints} channels')
        architecture = metadata.get('architecture', model.architecture)
        if architecture != model.architecture:
            raise ValueError(f'Detector: metadata.architecture is {architecture!r} but the '
                             f'model is {model.architecture!r}')
        if device is None:
            device = 'cuda' if torch.cuda.is_available() else 'cpu'
        self.device = torch.device(device)
        self.model = copy.deepcopy(model).eval().to(self.device)
        if fuse:
            fuse_for_inference(self.model)
        self.metadata = dict(metadata)
        self.keypoints = keypoints
        self.input_size = tuple(model.input_size)       # (H, W)
        self.heatmap_size = tuple(model.heatmap_size)   # (h, w)

    @classmethod
    def from_checkpoint(cls, path, device=None, architecture=None, num_keypoints=None):
        """Detector of a checkpoint file (CheckpointError names the file and field)."""
        model, metadata = load_checkpoint(path, architecture=architecture,
                                          num_keypoints=num_keypoints)
        return cls(model, metadata, device=device)

    def boxes_for(self, cameras, boxes=None, keep_aspect=True):
        """The crop boxes predict uses: (N, 4) edge coordinates.

        boxes None -> each full frame, padded (centred) to the network's aspect ratio;
        given boxes are grown about their centres to that aspect when keep_aspect.
        """
        aspect = self.input_size[1] / self.input_size[0]
        if boxes is None:
            return full_frame_boxes([(c.width, c.height) for c in cameras], aspect)
        boxes = np.asarray(boxes, dtype=np.float64)
        if boxes.shape != (len(cameras), 4):
            raise ValueError(f'Detector: boxes must be (N, 4) = ({len(cameras)}, 4), got '
                             f'{boxes.shape}')
        return fit_boxes_to_aspect(boxes, aspect) if keep_aspect else boxes

    def predict(self, images, cameras, boxes=None, keep_aspect=True):
        """Heatmaps of N synchronized views.

        images: (N, H, W, 3) uint8 RGB (or a sequence of (H_i, W_i, 3) for mixed sizes), one
        per camera; cameras: list of N Camera (image size must match); boxes: (N, 4) pixel-edge
        boxes or None (full frames); see boxes_for.
        -> heatmaps (N, C, h, w) float32 numpy, heat_cameras: list of N Camera, the virtual
        cameras of the heatmaps, cam.crop(box, (w, h)) (K_heat = S K, heatmap pixels).
        """
        if len(images) != len(cameras):
            raise ValueError(f'Detector: {len(images)} images but {len(cameras)} cameras')
        for image, camera in zip(images, cameras):
            shape = np.shape(image)
            if len(shape) != 3 or shape[2] != 3 or np.asarray(image).dtype != np.uint8:
                raise ValueError(f'Detector: image of camera {camera.name!r} must be (H, W, 3) '
                                 f'uint8 RGB, got {shape} {np.asarray(image).dtype}')
            if shape[:2] != (camera.height, camera.width):
                raise ValueError(f'Detector: image of camera {camera.name!r} is '
                                 f'{shape[1]}x{shape[0]} but the camera is '
                                 f'{camera.width}x{camera.height}')
        boxes = self.boxes_for(cameras, boxes, keep_aspect)
        h_in, w_in = self.input_size
        crops = crop_images(images, boxes, (w_in, h_in))
        with torch.inference_mode():
            heatmaps = self.model(images_to_tensor(crops, self.device))[-1]
        h, w = self.heatmap_size
        heat_cameras = [camera.crop(box, (w, h)) for camera, box in zip(cameras, boxes)]
        return heatmaps.float().cpu().numpy(), heat_cameras

"""Inference API: crop every camera's image, one batched forward pass, heatmaps + K_heat.

Input normalisation (the same for training and inference): images are uint8 RGB; the
network takes float RGB in [0, 1] (x / 255) and normalises with fixed mean/std inside its
forward (monet_ros.models.layers.Normalize), so no caller ever normalises differently.
"""
import copy

import numpy as np
import torch

from monet_ros.cores import ViewThreads
from monet_ros.models.checkpoint import load_checkpoint
from monet_ros.models.crop import crop_images, fit_boxes_to_aspect, full_frame_boxes
from monet_ros.models.layers import fuse_for_inference
from monet_ros.models.onnx_backend import (
    BACKEND_CHOICES,
    OnnxRunner,
    export_onnx,
    import_onnxruntime,
    onnx_runner_for,
)
from monet_ros.timing import StageTimer

PRECISIONS = ('auto', 'float32', 'bfloat16', 'int8')
# int8 is an inference precision only (ONNX Runtime static quantisation: models.quantize)
TRAINING_PRECISIONS = ('auto', 'float32', 'bfloat16')


def bfloat16_feature(device):
    """What makes bfloat16 native on `device`, as text ('AMX', 'AVX512-BF16', both joined by
    ' and ', or 'CUDA bfloat16 (<GPU name>)'), or None where it would be emulated (slower
    than float32): oneDNN's fast paths need AVX512-BF16 or AMX on a CPU."""
    device = torch.device(device)
    if device.type == 'cuda':
        return (f'CUDA bfloat16 ({torch.cuda.get_device_name(device)})'
                if torch.cuda.is_bf16_supported() else None)
    if device.type != 'cpu':
        return None
    # torch.cpu's probes of the CPU flags (cpuinfo); absent from a torch build -> False
    probes = (('_is_amx_tile_supported', 'AMX'), ('_is_avx512_bf16_supported', 'AVX512-BF16'))
    found = [text for name, text in probes if getattr(torch.cpu, name, lambda: False)()]
    return ' and '.join(found) or None


def bfloat16_native(device):
    """True when `device` runs bfloat16 convolutions natively: a CUDA GPU that supports
    them, or a CPU with AVX512-BF16 or AMX (bfloat16_feature)."""
    return bfloat16_feature(device) is not None


def check_precision(precision, backend, device):
    """Raises ValueError (naming precision) unless `precision` is one of PRECISIONS that
    `backend` runs well on `device` (bfloat16: torch backend, bfloat16_native device; int8:
    backend onnxruntime on a CPU with VNNI or AMX-INT8, models.quantize.check_int8_cpu;
    auto always runs: resolve_precision)."""
    if precision not in PRECISIONS:
        raise ValueError(f'precision must be one of {PRECISIONS}, got {precision!r}')
    if precision == 'int8':
        from monet_ros.models.quantize import check_int8_cpu
        if backend != 'onnxruntime':
            raise ValueError(f'precision int8 needs backend onnxruntime (ONNX Runtime static '
                             f'quantisation), got {backend!r}')
        if torch.device(device).type != 'cpu':
            raise ValueError(f'precision int8 runs on the CPU, not on {torch.device(device)}')
        check_int8_cpu()
    if precision == 'bfloat16':
        if backend != 'torch':
            raise ValueError(f'precision bfloat16 needs backend torch, got {backend!r}')
        if not bfloat16_native(device):
            raise ValueError(f'precision bfloat16 needs a CPU with AVX512-BF16 or AMX, or a '
                             f'CUDA GPU with bfloat16; {torch.device(device)} has neither (it '
                             f'would be slower than float32; precision auto picks float32 '
                             f'there)')


def resolve_backend(backend, precision='auto', device='cpu', native_bfloat16=None):
    """(backend run, one line saying why, '' when given) of a backend of BACKEND_CHOICES for
    `precision` (PRECISIONS, before resolve_precision) on `device`. auto -> torch on a GPU
    and for bfloat16 (asked for, or auto where native: native_bfloat16, None = probed with
    bfloat16_feature), onnxruntime for int8 and float32 on a CPU (precision float32, or auto
    without native bfloat16): the same network exported to ONNX ran 1.2-1.45x torch's
    keypoints3d/s end to end on an AVX2 CPU at 8 and 4 cameras (bench/results/pipeline.md)
    and its bare forward ~2x torch's float32 on both CPUs measured; torch where the
    onnxruntime package is missing (said). Raises ValueError naming backend for an unknown
    one."""
    if backend not in BACKEND_CHOICES:
        raise ValueError(f'backend must be one of {BACKEND_CHOICES}, got {backend!r}')
    if backend != 'auto':
        return backend, ''
    device = torch.device(device)
    if device.type != 'cpu':
        return 'torch', f'backend auto: torch (device {device})'
    if precision == 'bfloat16':
        return 'torch', 'backend auto: torch (bfloat16 runs on torch)'
    if precision == 'auto':
        if native_bfloat16 is None:
            native_bfloat16 = bfloat16_native(device)
        if native_bfloat16:
            return 'torch', 'backend auto: torch (bfloat16 is native on this CPU)'
    try:
        import_onnxruntime()                 # only whether it is there (and importable)
    except ImportError:
        return 'torch', ('backend auto: torch (the onnxruntime package is not installed; '
                         'it runs float32 faster on a CPU: pip install -r requirements.txt)')
    why = 'int8 runs on it' if precision == 'int8' else (
        'float32 on a CPU: faster than torch, bench/results/pipeline.md')
    return 'onnxruntime', f'backend auto: onnxruntime ({why})'


def resolve_precision(precision, backend='torch', device='cpu', checkpoint=None):
    """(precision run, one line saying why) for a precision of PRECISIONS (check_precision
    first: ValueError naming precision). auto -> with backend torch: bfloat16 where it runs
    natively on `device` (bfloat16_feature names the CPU feature or GPU found), else
    float32; with another backend: float32. auto never picks int8: measured slower than
    ONNX Runtime float32 and than torch bfloat16 on an AMX CPU (bench/detector_budget.py,
    bench/results/pipeline.md: bare forward 1.9 against 1.2 and 0.46 ms per image); int8
    runs when asked for. float32 / bfloat16 / int8 are kept as given. `checkpoint` is
    accepted for callers that pass it and unused."""
    check_precision(precision, backend, device)
    if precision != 'auto':
        return precision, f'precision {precision}'
    device = torch.device(device)
    if backend == 'onnxruntime' and device.type == 'cpu':
        return 'float32', ('precision auto: float32 (backend onnxruntime; int8 only when '
                           'asked for: measured slower here, bench/results/pipeline.md)')
    if backend != 'torch':
        return 'float32', f'precision auto: float32 (backend {backend} runs float32)'
    feature = bfloat16_feature(device)
    if feature is not None:
        return 'bfloat16', f'precision auto: bfloat16 ({device.type} has {feature}: native)'
    what = ('the GPU has no native bfloat16' if device.type == 'cuda' else
            'the CPU has neither AVX512-BF16 nor AMX, so bfloat16 would be emulated')
    return 'float32', f'precision auto: float32 ({what})'


def resolve_inference(precision, backend, device='cpu', checkpoint=None):
    """(precision run, backend run, one line saying both and why) of the detector's
    `precision` (PRECISIONS) and `backend` (BACKEND_CHOICES) on `device`: with backend auto
    the precision is resolved first as torch would run it (int8 as onnxruntime: the only
    backend that runs it), then the backend for that precision (resolve_backend), and the
    pair is checked (check_precision); a given backend as resolve_precision. Raises
    ValueError naming backend or precision. One rule for Detector and the commands' line
    (commands.common.precision_note)."""
    if backend not in BACKEND_CHOICES:
        raise ValueError(f'backend must be one of {BACKEND_CHOICES}, got {backend!r}')
    if backend != 'auto':
        chosen, note = resolve_precision(precision, backend, device, checkpoint)
        return chosen, backend, note
    chosen, note = resolve_precision(precision, 'onnxruntime' if precision == 'int8'
                                     else 'torch', device, checkpoint)
    backend, backend_note = resolve_backend('auto', chosen, device)
    check_precision(chosen, backend, device)
    return chosen, backend, f'{note}; {backend_note}'


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
    available, else CPU. backend: 'torch', 'onnxruntime' (the same network exported to
    ONNX, see monet_ros.models.onnx_backend; exported in memory here, or cached beside the
    checkpoint by from_checkpoint) or 'auto' (resolve_inference: `backend` is then the one
    chosen, its line the end of precision_note). threads: CPU threads of the onnxruntime
    session
    (0 = its default; torch's are process-wide: torch.set_num_threads) and of the per-view
    work of an instant (view_threads, a cores.ViewThreads: the crops here, the JPEG
    decodes of io.jpeg_scale.decode_views; 0 = the cores the process may use).
    precision: 'float32', or 'bfloat16' (torch backend only: the network runs under
    torch.autocast in bfloat16, 2-3x faster on CPUs with AVX512-BF16 / AMX; heatmaps are
    returned as float32 and differ from float32 inference by ~1e-2 of their peak), or
    'int8' (backend onnxruntime, CPU with VNNI / AMX-INT8: the network quantised by ONNX
    Runtime, models.quantize, calibrated on the crops the run makes: `int8_crops` is the
    crops key, 'full' (full-frame crops, what predict makes without boxes: the default)
    or a tracked key (monet_ros.int8_calibration.crops_key: the tracked rule's crops
    around the subject); it names the cached quant, so a quant of one crop mode is never
    used for the other. `calibration`: a recording (full-frame crops only), a cached
    quant of this checkpoint and crops key, crops (N, H, W, 3) uint8 of that mode, or a
    function detector -> crops that makes them with a float32 Detector of the same network
    (int8_calibration's tracked calibration), called only without a cached quant; needed
    unless the checkpoint has a cached quant of these crops, and checked even then:
    models.quantize.check_calibration; `int8_note` is then the one line saying what it
    calibrated on and which quant it wrote, or which cached quant it uses), or
    'auto' (bfloat16 with torch where native, else float32; never int8: resolve_precision;
    `precision` is then the one chosen and `precision_note` the line saying why).
    The torch backend keeps the network and its input channels-last (NHWC), the layout
    oneDNN's bfloat16 convolutions take (for float32 within noise of NCHW on CPU, results
    equal to ~1e-6).
    Raises ValueError (naming backend / precision) for a value it cannot run.
    """

    def __init__(self, model, metadata, device=None, fuse=True, backend='torch', threads=0,
                 checkpoint=None, precision='float32', calibration=None, int8_crops='full'):
        keypoints = list(metadata.get('keypoints', []))
        if len(keypoints) != model.num_keypoints:
            raise ValueError(f'Detector: metadata.keypoints has {len(keypoints)} names but the '
                             f'model has {model.num_keypoints} channels')
        architecture = metadata.get('architecture', model.architecture)
        if architecture != model.architecture:
            raise ValueError(f'Detector: metadata.architecture is {architecture!r} but the '
                             f'model is {model.architecture!r}')
        if backend not in BACKEND_CHOICES:
            raise ValueError(f'Detector: backend must be one of {BACKEND_CHOICES}, got '
                             f'{backend!r}')
        if device is None:
            device = 'cuda' if torch.cuda.is_available() else 'cpu'
        self.device = torch.device(device)
        # auto -> the precision / backend run here; precision_note: the line saying why
        self.precision, backend, self.precision_note = resolve_inference(
            precision, backend, self.device, checkpoint)
        self.model = copy.deepcopy(model).eval().to(self.device)
        if fuse:
            fuse_for_inference(self.model)
        if backend == 'torch':
            self.model.to(memory_format=torch.channels_last)
        self.metadata = dict(metadata)
        self.keypoints = keypoints
        self.input_size = tuple(model.input_size)       # (H, W)
        self.heatmap_size = tuple(model.heatmap_size)   # (h, w)
        self.backend = backend
        self.runner = None
        self.int8_note = None    # precision int8: the line saying which quant it runs
        if backend == 'onnxruntime' and self.precision == 'int8':
            from monet_ros.models.quantize import int8_onnx_for
            cpu_model = copy.deepcopy(self.model).cpu()
            if callable(calibration):        # crops made by float32 with the run's crop rule
                make = calibration

                def calibration():              # called once, if at all
                    return make(Detector(cpu_model, metadata, device='cpu', fuse=False,
                                         threads=threads))
                # the recording it reads: checked, named in int8_note
                calibration.recording = getattr(make, 'recording', None)
            network, self.int8_note = int8_onnx_for(cpu_model, checkpoint, calibration,
                                                    crops=int8_crops)
            self.runner = OnnxRunner(network, self.device, threads)
        elif backend == 'onnxruntime':
            cpu_model = copy.deepcopy(self.model).cpu()
            self.runner = (onnx_runner_for(cpu_model, checkpoint, self.device, threads)
                           if checkpoint is not None else
                           OnnxRunner(export_onnx(cpu_model), self.device, threads))
        self._input = None  # pre-allocated network input, grown with the batch size
        self.view_threads = ViewThreads(threads)   # crops (and decodes) of the views
        self.timer = StageTimer()  # 'crop' and 'forward' wall time of predict

    def input_buffer(self, n):
        """The (n, 3, H, W) float32 network-input tensor (pre-allocated, reused): contiguous
        for onnxruntime, channels-last for torch (then filling it from (n, H, W, 3) crops
        is a plain copy)."""
        if self._input is None or self._input.shape[0] < n:
            h, w = self.input_size
            device = 'cpu' if self.backend == 'onnxruntime' else self.device
            memory_format = (torch.contiguous_format if self.backend == 'onnxruntime' else
                             torch.channels_last)
            self._input = torch.empty((n, 3, h, w), dtype=torch.float32, device=device,
                                      memory_format=memory_format)
        return self._input[:n]

    @classmethod
    def from_checkpoint(cls, path, device=None, architecture=None, num_keypoints=None,
                        backend='torch', threads=0, precision='float32', calibration=None,
                        int8_crops='full'):
        """Detector of a checkpoint file (CheckpointError names the file and field); with
        backend 'onnxruntime' the export (and with precision int8 the quant, keyed also by
        int8_crops) is cached beside it, keyed by its sha256."""
        model, metadata = load_checkpoint(path, architecture=architecture,
                                          num_keypoints=num_keypoints)
        return cls(model, metadata, device=device, backend=backend, threads=threads,
                   checkpoint=path, precision=precision, calibration=calibration,
                   int8_crops=int8_crops)

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

    def predict(self, images, cameras, boxes=None, keep_aspect=True, encodings=None):
        """Heatmaps of N synchronized views.

        images: (N, H, W, 3) uint8 RGB (or a sequence of (H_i, W_i, 3) for mixed sizes), one
        per camera; cameras: list of N Camera (image size must match); boxes: (N, 4) pixel-edge
        boxes or None (full frames); see boxes_for. encodings: None (all rgb8) or, per image,
        the channel layout it is in ('rgb8', 'bgr8', 'rgba8', 'bgra8', 'mono8' with (H, W, 4)
        or (H, W, 1) arrays as raw message buffers): each crop is converted to RGB, never the
        full frame.
        -> heatmaps (N, C, h, w) float32 numpy, heat_cameras: list of N Camera, the virtual
        cameras of the heatmaps, cam.crop(box, (w, h)) (K_heat = S K, heatmap pixels).
        """
        if len(images) != len(cameras):
            raise ValueError(f'Detector: {len(images)} images but {len(cameras)} cameras')
        encodings = ['rgb8'] * len(images) if encodings is None else list(encodings)
        if len(encodings) != len(images):
            raise ValueError(f'Detector: {len(encodings)} encodings for {len(images)} images')
        for image, camera, encoding in zip(images, cameras, encodings):
            shape = np.shape(image)
            channels = {'rgba8': 4, 'bgra8': 4, 'mono8': 1}.get(encoding, 3)
            if len(shape) != 3 or shape[2] != channels or np.asarray(image).dtype != np.uint8:
                raise ValueError(f'Detector: image of camera {camera.name!r} must be (H, W, '
                                 f'{channels}) uint8 {encoding}, got {shape} '
                                 f'{np.asarray(image).dtype}')
            if shape[:2] != (camera.height, camera.width):
                raise ValueError(f'Detector: image of camera {camera.name!r} is '
                                 f'{shape[1]}x{shape[0]} but the camera is '
                                 f'{camera.width}x{camera.height}')
        boxes = self.boxes_for(cameras, boxes, keep_aspect)
        h_in, w_in = self.input_size
        with self.timer('crop'):
            # one batch of crops; each in the message's own layout, then only the (small)
            # crop converted to RGB
            crops = crop_images(images, boxes, (w_in, h_in), layouts=encodings,
                                threads=self.view_threads)
        with self.timer('forward'):
            heatmaps = self.forward(crops)
        h, w = self.heatmap_size
        heat_cameras = [camera.crop(box, (w, h)) for camera, box in zip(cameras, boxes)]
        return heatmaps, heat_cameras

    def forward(self, crops):
        """(N, H, W, 3) uint8 RGB network-input crops -> (N, C, h, w) float32 numpy heatmaps,
        through the chosen backend (the same conversion as images_to_tensor, into the
        pre-allocated input tensor).

        The array's memory is channel-interleaved ((N, h, w, C) contiguous, seen as (N, C,
        h, w)): the torch network's own channels-last output, and the layout of a heatmap
        message (32FC<C>), so io.heatmaps_to_image_msg copies it only into the message
        (a contiguous (N, C, h, w) result cost a copy here and a transposing one there)."""
        buffer = self.input_buffer(len(crops))
        with torch.inference_mode():
            source = torch.from_numpy(np.ascontiguousarray(crops)).to(buffer.device)
            buffer.copy_(source.permute(0, 3, 1, 2)).div_(255.0)
            if self.runner is not None:
                heatmaps = self.runner(buffer.numpy())
                return np.ascontiguousarray(heatmaps.transpose(0, 2, 3, 1)).transpose(0, 3, 1, 2)
            with torch.autocast(self.device.type, dtype=torch.bfloat16,
                                enabled=self.precision == 'bfloat16'):
                heatmaps = self.model(buffer)[-1]
            # a no-op for the channels-last output of a CPU network
            heatmaps = heatmaps.float().permute(0, 2, 3, 1).contiguous()
        return heatmaps.cpu().numpy().transpose(0, 3, 1, 2)

"""ONNX Runtime inference of a detector network (optional `backend: onnxruntime`).

The network of a checkpoint is exported once with torch.onnx.export (TorchScript exporter,
dynamo=False, dynamic batch) to `<checkpoint stem>.<sha256[:16]>.onnx` beside the
checkpoint, written atomically; the name is keyed by the checkpoint's sha256, so new weights
get a new export and an export never belongs to other weights. The graph takes the same
input as the torch network, (N, 3, H, W) float32 RGB in [0, 1] (normalisation is inside),
and gives the last stage's heatmaps (N, C, h, w) float32.
"""
import io
import os
from pathlib import Path
import warnings

import numpy as np
import torch

from monet_ros.atomic import atomic_write, sha256_file

BACKENDS = ('torch', 'onnxruntime')
# what the detector node, `monet process` and `monet pipeline` take: auto picks one of
# BACKENDS (models.detector.resolve_backend)
BACKEND_CHOICES = ('auto',) + BACKENDS
OPSET = 17


class OnnxBackendError(ValueError):
    """ONNX Runtime is not installed, or the export / session could not be made (a
    ValueError, so commands and nodes report it in one line)."""


def onnx_path_for(checkpoint, sha256):
    """Where the export of a checkpoint with this sha256 is cached (beside it)."""
    checkpoint = Path(checkpoint)
    return checkpoint.with_name(f'{checkpoint.stem}.{sha256[:16]}.onnx')


class _LastStage(torch.nn.Module):
    def __init__(self, model):
        super().__init__()
        self.model = model

    def forward(self, x):
        return self.model(x)[-1]


def export_onnx(model):
    """The eval-mode CPU `model` (a detector network) as ONNX bytes.

    Input 'images' (N, 3, H, W) float32 with N dynamic; output 'heatmaps' (N, C, h, w).
    Raises OnnxBackendError when torch cannot export it."""
    h, w = model.input_size
    dummy = torch.zeros(1, 3, h, w)
    buffer = io.BytesIO()
    try:
        with torch.inference_mode(False), torch.no_grad(), warnings.catch_warnings():
            warnings.simplefilter('ignore', DeprecationWarning)  # the TorchScript exporter
            torch.onnx.export(_LastStage(model).eval(), (dummy,), buffer, dynamo=False,
                              input_names=['images'], output_names=['heatmaps'],
                              dynamic_axes={'images': {0: 'batch'}, 'heatmaps': {0: 'batch'}},
                              opset_version=OPSET)
    except Exception as error:  # noqa: BLE001 - the exporter raises many kinds
        raise OnnxBackendError(f'ONNX export of the {model.architecture} network failed '
                               f'({type(error).__name__}: {error})') from None
    return buffer.getvalue()


def import_deferred(name):
    """importlib.import_module(name) with a stop signal deferred to the end of the import
    (stop_signals.stop_signals_deferred): a Ctrl-C / SIGTERM that lands while a C extension
    initialises can come out of the import as an ImportError (onnxruntime's: ImportError(
    'import numpy failed')), and the stop would be lost. For the lazy imports of
    onnxruntime and onnx. Raises ImportError where the module is not installed (or
    broken)."""
    from importlib import import_module

    from monet_ros.stop_signals import stop_signals_deferred
    with stop_signals_deferred():
        return import_module(name)


def import_onnxruntime():
    """The onnxruntime module (import_deferred). Raises ImportError where it is missing."""
    return import_deferred('onnxruntime')


def _onnxruntime():
    try:
        onnxruntime = import_onnxruntime()
    except ImportError:
        raise OnnxBackendError("backend 'onnxruntime' needs the onnxruntime package "
                               '(pip install -r requirements.txt)') from None
    return onnxruntime


def spinning():
    """Whether ONNX Runtime's intra-op threads spin while they wait (its default): not
    where OpenMP waits passively (OMP_WAIT_POLICY=PASSIVE, which the nodes and `monet
    pipeline` set unless the user did: threads spinning on shared cores starve the
    publisher, fusion and decode threads, as torch's did), so both backends follow the
    one policy."""
    return os.environ.get('OMP_WAIT_POLICY', '').strip().upper() != 'PASSIVE'


class OnnxRunner:
    """An ONNX Runtime session of an exported detector network.

    path: the .onnx file (or its bytes); device: 'cpu' or 'cuda[:i]' (CUDA needs
    onnxruntime-gpu, else OnnxBackendError); threads: intra-op CPU threads (0 = ONNX
    Runtime's default). Calling it with (N, 3, H, W) float32 numpy returns (N, C, h, w)
    float32 numpy."""

    def __init__(self, path, device='cpu', threads=0):
        ort = _onnxruntime()
        options = ort.SessionOptions()
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        if threads:
            options.intra_op_num_threads = int(threads)
            options.inter_op_num_threads = 1
        if not spinning():
            options.add_session_config_entry('session.intra_op.allow_spinning', '0')
        device = torch.device(device)
        if device.type == 'cuda':
            if 'CUDAExecutionProvider' not in ort.get_available_providers():
                raise OnnxBackendError('device cuda with backend onnxruntime needs '
                                       'onnxruntime-gpu (CUDAExecutionProvider not available)')
            providers = [('CUDAExecutionProvider', {'device_id': device.index or 0}),
                         'CPUExecutionProvider']
        else:
            providers = ['CPUExecutionProvider']
        try:
            source = path if isinstance(path, bytes) else str(path)
            self.session = ort.InferenceSession(source, options, providers=providers)
        except Exception as error:  # noqa: BLE001 - onnxruntime raises its own kinds
            name = 'the exported network' if isinstance(path, bytes) else path
            raise OnnxBackendError(f'{name}: ONNX Runtime cannot load it ({error})') from None
        self.path = None if isinstance(path, bytes) else Path(path)

    def __call__(self, images):
        images = np.ascontiguousarray(images, dtype=np.float32)
        return self.session.run(['heatmaps'], {'images': images})[0]


def onnx_runner_for(model, checkpoint, device='cpu', threads=0, sha256=None):
    """OnnxRunner of `model` (loaded from `checkpoint`), exporting it beside the checkpoint
    first unless that export exists (keyed by the checkpoint's sha256). Where that folder
    is not writable the export is used from memory (and made again at the next start)."""
    sha256 = sha256 or sha256_file(checkpoint)
    path = onnx_path_for(checkpoint, sha256)
    if not path.is_file():
        data = export_onnx(model)
        try:
            with atomic_write(path) as stream:
                stream.write(data)
        except OSError:
            return OnnxRunner(data, device=device, threads=threads)
    return OnnxRunner(path, device=device, threads=threads)

"""Topic and namespace names shared by the nodes.

Outputs and inter-node topics are node-relative (`keypoints3d`, `skeleton`, `model`,
`<camera>/heatmaps`, `<camera>/camera_info`, `<camera>/debug_image`) and every node starts
in the namespace `monet`, so the defaults are `/monet/...` while `-r __ns:=/rig1` (or a
launch file's PushRosNamespace / namespace=) moves a whole rig. Camera driver topics
(`/<camera>/image_raw`), `/diagnostics`, `/tf_static` and `/clock` stay absolute.
"""
DEFAULT_NAMESPACE = 'monet'

KEYPOINTS3D = 'keypoints3d'
KEYPOINTS3D_RAW = 'keypoints3d_raw'   # the unfiltered keypoints while the filter is on
SKELETON = 'skeleton'
RIG_MARKERS = 'rig_markers'
MODEL = 'model'
HEATMAPS = '{camera}/heatmaps'
HEATMAP_CAMERA_INFO = '{camera}/camera_info'
DEBUG_IMAGE = '{camera}/debug_image'
DEBUG_CAMERA_INFO = '{camera}/debug_image/camera_info'
# Several subjects (`subjects` N >= 2): the {camera} of the heatmap and camera_info topics
# becomes each crop slot's name, <camera>/crop<k>: k < N the crops around subjects, k = N the
# full frame (docs/subjects.md "Live").
CROP_SLOT = '{camera}/crop{slot}'
DIAGNOSTICS = '/diagnostics'
TF_STATIC = '/tf_static'
PLAYED_FRAMES = 'played_frames'   # the player's [stamp, wall time] per frame


def crop_slots(camera, subjects, discovery=1):
    """The N + D crop slot names (CROP_SLOT) of a camera with `subjects` N >= 2: slots
    0..N-1 the subjects' crops, N..N+D-1 its D discovery maps (the whole frame, or its
    tiles: subjects.detection.discovery_slots)."""
    return [CROP_SLOT.format(camera=camera, slot=k) for k in range(subjects + discovery)]


def heatmap_sources(camera, subjects, discovery=1):
    """What takes the place of {camera} in the heatmap and camera_info topics (HEATMAPS,
    HEATMAP_CAMERA_INFO) of one camera: [camera] with `subjects` 1, its N + D crop slots
    (crop_slots) with N >= 2. `camera` may itself be a template ('{camera}')."""
    return [camera] if subjects <= 1 else crop_slots(camera, subjects, discovery)


def node_namespace(kwargs):
    """`kwargs` of a Node constructor with the default namespace filled in (an explicit
    namespace=..., or `__ns` on the command line, still wins)."""
    kwargs = dict(kwargs)
    kwargs.setdefault('namespace', DEFAULT_NAMESPACE)
    return kwargs

"""One crop rule live and offline: `monet pipeline --lockstep` (real nodes over DDS) and
`monet process` give the same 3D for the same recording and model, frame by frame."""
import sys

from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
from helpers.ros import NodeProcess, RosHarness
import numpy as np
from sensor_msgs.msg import PointCloud2
import torch

from monet_ros.cli import main as monet
from monet_ros.io import cloud_to_keypoints3d, header_stamp_ns, open_bag
from monet_ros.learning.config import TrainConfig
from monet_ros.learning.trainer import Trainer, TrainingData


def blob_model(recording, out):
    """A small net trained briefly on the moving blobs: decisive peaks, so the tracked crops
    follow the subject (a random network's flat maps would make argmax ties)."""
    torch.set_num_threads(1)
    config = TrainConfig(mode='supervised', steps=120, architecture='small', input_size=48,
                         width=16, lr=3e-3, eval_fraction=0.0, box_source='labels',
                         device='cpu', checkpoint_every=1000)
    trainer = Trainer(config, TrainingData(recording, config, (48, 48), (12, 12)), out)
    trainer.run(progress=False)
    return out / 'model.pt'


def test_process_and_lockstep_pipeline_agree_within_a_millimetre(ros_env, tmp_path):
    rec = blob_recording(num_views=4, T=12, C=3, labelled=tuple(range(12)))
    write_blob_folder(rec, tmp_path / 'rec', camera_info=True)
    model = blob_model(rec, tmp_path / 'train')
    (tmp_path / 'skeleton.yaml').write_text('name: blobs\nkeypoints: [k0, k1, k2]\n'
                                            'bones: [[k0, k1], [k1, k2]]\n')
    bag, rig = tmp_path / 'rec' / 'recording', tmp_path / 'rec' / 'rig.yaml'
    assert monet(['process', str(bag), '--rig', str(rig), '--model', str(model), '--out',
                  str(tmp_path / 'out'), '--quiet']) == 0
    offline = {m.stamp_ns: cloud_to_keypoints3d(m.msg, units='m')['X'] for m in
               open_bag(tmp_path / 'out').messages(['/monet/keypoints3d'])}
    stamps = [int(s) for s in rec.stamps]
    assert sorted(offline) == stamps
    tracked = [np.isfinite(X).all(axis=1).sum() >= 3 for X in offline.values()]
    assert sum(tracked[:-1]) >= 6, 'the tracked rule was hardly exercised'
    argv = [sys.executable, '-m', 'monet_ros.cli', 'pipeline', '--bag', str(bag), '--rig',
            str(rig), '--model', str(model), '--skeleton', str(tmp_path / 'skeleton.yaml'),
            '--lockstep', '--start-delay', '2.0', '--quiet']
    with RosHarness(ros_env) as ros:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, 100)
        with NodeProcess('pipeline', ros_env, argv=argv) as proc:
            ros.spin_until(lambda: len(clouds) >= len(stamps), timeout=180, process=None)
            assert proc.wait(timeout=90) == 0, proc.output()
    live = {header_stamp_ns(c): cloud_to_keypoints3d(c, units='m')['X'] for c in clouds}
    assert sorted(live) == stamps, proc.output()
    for stamp in stamps:
        a, b = offline[stamp], live[stamp]
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=f'stamp {stamp}')
        diff = np.abs(a - b)[np.isfinite(a)]
        assert diff.size == 0 or diff.max() <= 1e-3, (stamp, diff.max())
    # and the 3D is the blobs' (the crops followed the subject)
    errors = np.linalg.norm(np.stack([offline[s] for s in stamps]) - rec.gt3d, axis=-1)
    assert np.nanmedian(errors) < 0.05, np.nanmedian(errors)

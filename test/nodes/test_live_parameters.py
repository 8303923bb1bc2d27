"""Every declared parameter of every node, set to extreme finite values (and inf, NaN) and
to its range's ends on the running executable through the rcl_interfaces services (what
`ros2 param set` calls, from another participant on the domain): the node keeps running and
answering, a refusal names the parameter, a refused value leaves the old one, and (fusion)
the node still fuses correctly once its parameters are set back (issue 37: filter_noise_mm
1e200 killed the fusion node with an OverflowError in the parameter callback). At start a
value whose derived numbers overflow exits 2 with one line naming the parameter."""
from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
from helpers.fusion_frames import Frame, publishers, run_frames
from helpers.recordings import noise_recording, small_checkpoint
from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import ring_rig
import numpy as np
import pytest
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters, SetParameters
from sensor_msgs.msg import PointCloud2

from monet_ros.geometry import save_rig
from monet_ros.io import cloud_to_keypoints3d
from monet_ros.models import build_model, save_checkpoint
from monet_ros.nodes.fusion import LIVE
from monet_ros.nodes.qos import STREAM_OUT

FLOAT_MAX = 1.7976931348623157e308
DOUBLES = (1e200, -1e200, FLOAT_MAX, -FLOAT_MAX, 5e-324, 1e-200, 0.0, float('inf'), float('nan'))
INTEGERS = (2 ** 63 - 1, -2 ** 63, 0)


def int_value(value):
    return ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value)


def double_value(value):
    return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)


def plain(value):
    """A ParameterValue's Python value (numbers and bools; None otherwise)."""
    return {ParameterType.PARAMETER_BOOL: value.bool_value,
            ParameterType.PARAMETER_INTEGER: value.integer_value,
            ParameterType.PARAMETER_DOUBLE: value.double_value}.get(value.type)


def trials(descriptor):
    """ParameterValues to try on one numeric parameter: its declared range's ends, huge and
    tiny finite values, inf and NaN (and a huge double on an integer parameter)."""
    if descriptor.type == ParameterType.PARAMETER_DOUBLE:
        ends = [v for r in descriptor.floating_point_range for v in (r.from_value, r.to_value)]
        return [double_value(v) for v in (*ends, *DOUBLES)]
    ends = [v for r in descriptor.integer_range for v in (r.from_value, r.to_value)]
    return [int_value(v) for v in (*ends, *INTEGERS)] + [double_value(1e200)]


def storm(ros, process, service):
    """Set every numeric parameter of the node at `service` to each of its trials, one
    SetParameters request each. Returns (descriptors {name: descriptor}, original values
    {name: ParameterValue}, expected values {name: python value} after the storm,
    refusals [(name, value, reason)])."""
    names = ros.call(ListParameters, f'{service}/list_parameters',
                     ListParameters.Request(), process).result.names
    described = ros.call(DescribeParameters, f'{service}/describe_parameters',
                         DescribeParameters.Request(names=names), process).descriptors
    descriptors = {d.name: d for d in described}
    original = dict(zip(names, ros.call(GetParameters, f'{service}/get_parameters',
                                        GetParameters.Request(names=names), process).values))
    expected = {name: plain(value) for name, value in original.items()}
    refusals = []
    numeric = [d for d in described if d.type in (ParameterType.PARAMETER_DOUBLE,
                                                  ParameterType.PARAMETER_INTEGER)]
    assert numeric, names
    for descriptor in numeric:
        for value in trials(descriptor):
            request = SetParameters.Request(parameters=[Parameter(name=descriptor.name,
                                                                  value=value)])
            result = ros.call(SetParameters, f'{service}/set_parameters', request,
                              process).results[0]
            assert process.running(), process.output()
            if result.successful:
                expected[descriptor.name] = plain(value)
            else:
                refusals.append((descriptor.name, plain(value), result.reason))
    return descriptors, original, expected, refusals


def check_after_storm(ros, process, service, descriptors, expected, refusals):
    """The node still answers; every parameter holds the last accepted value; every
    refusal named its parameter; a read-only parameter was never changed."""
    names = sorted(descriptors)
    values = ros.call(GetParameters, f'{service}/get_parameters',
                      GetParameters.Request(names=names), process).values
    got = {name: plain(value) for name, value in zip(names, values)}
    for name in names:
        if expected[name] is not None:
            assert got[name] == expected[name], (name, got[name], expected[name])
    for name, value, reason in refusals:
        assert name in reason, (name, value, reason)
    assert process.running(), process.output()


def test_fusion_survives_every_extreme_value_and_still_fuses(ros_env, tmp_path):
    rig = ring_rig(4)
    save_rig(tmp_path / 'rig.yaml', rig, frame_id='world')
    params = dict(rig=str(tmp_path / 'rig.yaml'), timeout_s=2.0, input_reliability='reliable',
                  filter=True)
    service = '/monet/fusion'
    rng = np.random.default_rng(37)
    X = rng.uniform([-0.3, -0.3, 0.6], [0.3, 0.3, 1.5], size=(14, 3))
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        descriptors, original, expected, refusals = storm(ros, node, service)
        check_after_storm(ros, node, service, descriptors, expected, refusals)
        # the value of the report is refused with its reason, live
        reported = [r for r in refusals if r[0] == 'filter_noise_mm' and r[1] == 1e200]
        assert reported and reported[0][2].startswith(
            "parameter 'filter_noise_mm': 1e+200 gives a measurement variance of inf"), reported
        # set back to the start values (every one accepted), the node fuses as before
        back = ros.call(SetParameters, f'{service}/set_parameters', SetParameters.Request(
            parameters=[Parameter(name=n, value=original[n]) for n in LIVE]), node).results
        assert all(r.successful for r in back), [r.reason for r in back]
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, STREAM_OUT)
        pubs = publishers(ros, [c.name for c in rig])
        for heat_pub, info_pub in pubs.values():
            ros.wait_for_subscribers(heat_pub, timeout=60, process=node)
            ros.wait_for_subscribers(info_pub, timeout=60, process=node)
        frame = Frame(rig, X, 0, rng, noise=0.0)
        got = run_frames(ros, node, pubs, [frame], clouds)[frame.stamp]
        assert node.stop() == 0, node.output()
    assert 'Traceback' not in node.output()
    assert set(LIVE) <= {n for n, d in descriptors.items() if not d.read_only}
    fused = cloud_to_keypoints3d(got, units='m')['X']
    assert np.abs(fused - X).max() < 1e-3      # the first filtered frame is the measurement


def survives_storm(ros_env, name, params):
    """Start node `name`, storm its parameters, check it after; returns the refusals."""
    service = f'/monet/{name}'
    with RosHarness(ros_env) as ros, NodeProcess(name, ros_env, params) as node:
        descriptors, _, expected, refusals = storm(ros, node, service)
        check_after_storm(ros, node, service, descriptors, expected, refusals)
        assert node.stop() == 0, node.output()
    assert 'Traceback' not in node.output()
    return refusals


def test_detector_survives_every_extreme_value(ros_env, tmp_path):
    save_rig(tmp_path / 'rig.yaml', ring_rig(2))
    model = small_checkpoint(tmp_path / 'model.pt')
    params = dict(rig=str(tmp_path / 'rig.yaml'), model=str(model), device='cpu', threads=1)
    refusals = survives_storm(ros_env, 'detector', params)
    assert any(n == 'track_timeout_s' and v == 1e200 for n, v, _ in refusals), refusals


def test_player_survives_every_extreme_value(ros_env, tmp_path):
    noise_recording(tmp_path / 'bag', cameras=2, frames=3, width=32, height=24)
    params = dict(bag=str(tmp_path / 'bag'), wait_for_subscribers=0, start_delay_s=0.0)
    survives_storm(ros_env, 'player', params)


def test_learner_survives_every_extreme_value(ros_env, tmp_path):
    rec = blob_recording(num_views=4, T=12, C=3, labelled=(2, 9), label_views=(0, 1))
    folder = write_blob_folder(rec, tmp_path / 'data')
    save_checkpoint(tmp_path / 'init.pt', build_model('small', 3, input_size=[48, 48],
                                                      width=16), {'keypoints': ['k0', 'k1', 'k2']})
    params = dict(bags=[str(folder)], out=str(tmp_path / 'run'), model=str(tmp_path / 'init.pt'),
                  steps=1, checkpoint_every=1, batch_labelled=2, batch_pseudo=2,
                  batch_unlabeled=1, views_per_instant=3, eval_fraction=0.25, device='cpu',
                  threads=1, validate_instants=2)
    survives_storm(ros_env, 'learner', params)


@pytest.mark.parametrize('node_name, param, value', [
    ('fusion', 'filter_noise_mm', 1e200),
    ('detector', 'track_timeout_s', 1e200),
    ('player', 'start_delay_s', 1e200),
])
def test_a_value_that_overflows_at_start_exits_2_naming_it(ros_env, tmp_path, node_name, param,
                                                            value):
    save_rig(tmp_path / 'rig.yaml', ring_rig(2))
    base = dict(fusion=dict(rig=str(tmp_path / 'rig.yaml')),
                detector=dict(rig=str(tmp_path / 'rig.yaml'), model='unused.pt', device='cpu'),
                player=dict(bag=str(tmp_path / 'unused')))[node_name]
    with NodeProcess(node_name, ros_env, {**base, param: value}) as node:
        assert node.wait(timeout=120) == 2, node.output()
    lines = [line for line in node.stderr_path.read_text().splitlines() if line.strip()]
    assert len(lines) == 1, node.output()
    assert lines[0].startswith(f"{node_name}: error: parameter '{param}': 1e+200 "), lines

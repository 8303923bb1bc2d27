"""The fusion executable with a rig in mm (an anipose TOML that states no unit, the
`rig_units` parameter saying mm): keypoints3d in mm, the live filter's mm / m/s^2 settings
converted (nothing gated on a still subject; before, a mm joint was gated nearly every
frame), /diagnostics stating the unit; the filter's numbers checked in mm, at start and
live (a noise usable in metres whose covariance overflows in mm is refused naming it)."""
import re

from diagnostic_msgs.msg import DiagnosticArray
from helpers.fusion_frames import Frame, fusion_statuses, publishers, run_frames
from helpers.ros import NodeProcess, RosHarness
from helpers.scenes import ring_rig
import numpy as np
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from sensor_msgs.msg import PointCloud2

from monet_ros.geometry import save_anipose_toml, save_rig
from monet_ros.geometry.units import rescale
from monet_ros.io import cloud_to_keypoints3d, header_stamp_ns
from monet_ros.nodes.qos import STREAM_OUT
from monet_ros.temporal.live import LiveFilter, LiveFilterConfig


def test_fusion_in_mm_filters_as_in_metres(ros_env, tmp_path):
    rig = rescale(ring_rig(4), 'mm')
    path = tmp_path / 'calibration.toml'
    save_anipose_toml(path, rig)
    path.write_text(re.sub(r'(?m)^units = .*\n', '', path.read_text()))   # anipose's form
    rng = np.random.default_rng(5)
    X = rng.uniform([-300, -300, 600], [300, 300, 1500], size=(14, 3))       # mm
    frames = [Frame(rig, X, i, rng, noise=0.4) for i in range(8)]
    # every frame fused whole, however loaded the machine: no view timeout that a slow
    # process can reach, no stale skip (max_queue_ms 0); run_frames resends until fused
    params = dict(rig=str(path), rig_units='mm', filter=True, timeout_s=60.0,
                  max_queue_ms=0.0, input_reliability='reliable', diagnostics_period_s=0.2)
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, STREAM_OUT)
        raw = ros.collect('/monet/keypoints3d_raw', PointCloud2, STREAM_OUT)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        pubs = publishers(ros, [c.name for c in rig])
        for heat_pub, info_pub in pubs.values():
            ros.wait_for_subscribers(heat_pub, timeout=60, process=node)
            ros.wait_for_subscribers(info_pub, timeout=60, process=node)
        run_frames(ros, node, pubs, frames, clouds)
        stamps = [f.stamp for f in frames]

        def counted():
            status = fusion_statuses(diagnostics).get('monet fusion')
            values = {kv.key: kv.value for kv in status.values} if status else {}
            # a frame resent before its cloud came back may be counted twice
            return values if int(values.get('frames', 0)) >= len(frames) else None
        assert ros.spin_until(lambda: counted() is not None and set(stamps) <= {
            header_stamp_ns(c) for c in raw}, timeout=30, process=node), node.output()
        values = counted()
        assert node.stop() == 0, node.output()
    assert values['units'] == 'mm' and values['filter_gated'] == '0', values
    filtered = {header_stamp_ns(c): cloud_to_keypoints3d(c) for c in clouds}
    unfiltered = {header_stamp_ns(c): cloud_to_keypoints3d(c) for c in raw}
    # the raw keypoints are the subject in mm (heatmap noise: a few mm)
    for stamp in stamps:
        assert np.nanmax(np.abs(unfiltered[stamp]['X'] - X)) < 30.0
    # the node's filter is LiveFilter in mm, which equals the metre filter on X / 1000
    in_mm = LiveFilter(LiveFilterConfig(filter=True), 'mm')
    in_m = LiveFilter(LiveFilterConfig(filter=True))
    for stamp in stamps:
        measured = unfiltered[stamp]['X'].astype(np.float64)
        expected, _ = in_mm.update(stamp, measured)
        metres, _ = in_m.update(stamp, measured / 1000.0)
        np.testing.assert_allclose(filtered[stamp]['X'], expected, atol=1e-2)
        np.testing.assert_allclose(expected / 1000.0, metres, atol=1e-9)
    assert in_mm.gated == in_m.gated == 0


def test_the_filter_is_checked_in_the_rig_unit_at_start_and_live(ros_env, tmp_path):
    # 1e146 mm: a restart covariance of 2e286 m^2 / 1e-18 s^2 in metres, inf in mm
    path = tmp_path / 'rig.yaml'
    save_rig(path, rescale(ring_rig(2), 'mm'))
    params = dict(rig=str(path), filter=True)
    with NodeProcess('fusion', ros_env, {**params, 'filter_noise_mm': 1e146}) as node:
        assert node.wait(timeout=120) == 2, node.output()
    lines = [line for line in node.stderr_path.read_text().splitlines() if line.strip()]
    assert lines == ["fusion: error: parameter 'filter_noise_mm': 1e+146 mm gives a "
                     'non-finite restart covariance in mm'], node.output()
    with RosHarness(ros_env) as ros, NodeProcess('fusion', ros_env, params) as node:
        def set_noise(value):
            request = SetParameters.Request(parameters=[Parameter(
                name='filter_noise_mm', value=ParameterValue(
                    type=ParameterType.PARAMETER_DOUBLE, double_value=value))])
            return ros.call(SetParameters, '/monet/fusion/set_parameters', request,
                            node).results[0]
        refused = set_noise(1e146)
        accepted = set_noise(1e5)
        assert node.stop() == 0, node.output()
    assert not refused.successful and refused.reason == (
        "parameter 'filter_noise_mm': 1e+146 mm gives a non-finite restart covariance in mm")
    assert accepted.successful, accepted.reason

"""CallbackGuard (run_node wraps every node's callbacks in it): an exception in a
subscription callback costs only that message - counted per topic and kind, logged once,
reported on /diagnostics - and the node goes on handling the next messages. Real rclpy
nodes over DDS, in this process."""
from diagnostic_msgs.msg import DiagnosticArray
from helpers.ros import RosHarness
from rclpy.node import Node
from std_msgs.msg import String

from monet_ros.nodes.runner import CallbackGuard


def test_exceptions_are_counted_per_topic_and_the_node_goes_on(ros_env):
    with RosHarness(ros_env) as ros:
        node = Node('guarded', context=ros.context)
        handled = []

        def on_message(msg):
            if msg.data.startswith('bad'):
                raise ValueError(f'cannot use {msg.data!r}')
            if msg.data.startswith('worse'):
                raise KeyError(msg.data)
            handled.append(msg.data)

        node.create_subscription(String, '/input', on_message, 10)
        guard = CallbackGuard(node)
        ros.executor.add_node(node)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        pub = ros.publisher('/input', String)
        ros.wait_for_subscribers(pub)
        sent = ['ok1', 'bad1', 'ok2', 'worse1', 'bad2', 'ok3']
        for text in sent:
            pub.publish(String(data=text))
            ros.spin_for(0.05)
        assert ros.spin_until(lambda: len(handled) == 3 and sum(guard.errors.values()) == 3)
        assert handled == ['ok1', 'ok2', 'ok3']
        assert guard.errors == {('/input', 'ValueError'): 2, ('/input', 'KeyError'): 1}

        def reported():      # the newest report (one may have gone out after 1 or 2 errors)
            for msg in reversed(diagnostics):
                for status in msg.status:
                    if status.hardware_id == '/input':
                        return {kv.key: kv.value for kv in status.values}
            return None
        assert ros.spin_until(lambda: (reported() or {}).get('errors') == '3', timeout=60)
        assert 'bad2' in reported()['last_error']
        ros.executor.remove_node(node)
        node.destroy_node()


def test_bad_messages_are_logged_once_per_kind(ros_env):
    from monet_ros.nodes.runner import log_bad_once
    with RosHarness(ros_env) as ros:
        node = Node('logger', context=ros.context)
        size = 'image is 320x240 but the camera is 640x480'
        assert log_bad_once(node, '/cam0/image_raw', ValueError(size), 1)
        assert not log_bad_once(node, '/cam0/image_raw', ValueError(size.replace('320', '32')), 2)
        assert log_bad_once(node, '/cam0/image_raw', ValueError('no camera_info yet'), 3)
        assert log_bad_once(node, '/cam1/image_raw', ValueError(size), 1)   # another source
        node.destroy_node()

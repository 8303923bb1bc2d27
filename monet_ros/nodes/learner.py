"""learner node: fine-tunes the detector from recorded bags and announces better models.

Parameters: monet_ros.learning.online.LearnerConfig (the TrainConfig fields + bags, rig,
labels, model, out, ...), see config/learner.yaml. Training (OnlineLearner.step) runs in a
background thread; the executor thread serves the services and timers:

  ~/save_checkpoint  std_srvs/Trigger   write, validate (and maybe announce) a checkpoint now
  ~/pause, ~/resume  std_srvs/Trigger   stop / continue training between steps
  /monet/model       std_msgs/String    JSON {path, step, sha256, metrics}, transient-local:
                                        every checkpoint_every steps, when its publish_metric
                                        (default: mean error on the held-out validation
                                        labels; reprojection error when there are none) is
                                        not worse than the last announced one's
  /diagnostics       DiagnosticArray    step, steps/s, loss terms, last validation, state,
                                        the criterion and its announced value

The criterion and the validation split are the core's (OnlineLearner, should_publish): the
same for `monet pipeline --learn` and any offline caller.
"""
import sys
import threading

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from std_msgs.msg import String
from std_srvs.srv import Trigger

from monet_ros.error_text import error_line
from monet_ros.learning.config import LOSS_TERMS
from monet_ros.learning.online import LearnerConfig, OnlineLearner
from monet_ros.nodes.names import DIAGNOSTICS, MODEL, node_namespace
from monet_ros.nodes.params import declare_config
from monet_ros.nodes.qos import LATCHED, STREAM_OUT
from monet_ros.nodes.runner import run_node


class LearnerNode(Node):
    def __init__(self, overrides=None, node_name='learner', start=True, **kwargs):
        super().__init__(node_name, **node_namespace(kwargs))
        self.config = declare_config(self, LearnerConfig, overrides)
        self.pub_model = self.create_publisher(String, MODEL, LATCHED)
        self.pub_diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS, STREAM_OUT)
        self.learner = OnlineLearner(self.config, log=self.get_logger().info)
        self.lock = threading.Lock()          # one trainer call at a time
        self.running = threading.Event()      # set = training, clear = paused
        self.stopping = threading.Event()
        self.error = None
        self.last_terms = {}
        self.announced = 0
        self.listeners = []                   # callables(CheckpointResult), e.g. pipeline
        if self.learner.published is not None:
            self.announce(self.learner.published)       # a restart re-announces
        self.create_service(Trigger, '~/save_checkpoint', self.on_save)
        self.create_service(Trigger, '~/pause', self.on_pause)
        self.create_service(Trigger, '~/resume', self.on_resume)
        self.create_timer(1.0, self.publish_diagnostics)
        self.thread = threading.Thread(target=self.train_loop, name='learner', daemon=True)
        if start:
            self.running.set()
        self.thread.start()

    # ------------------------------------------------------------------ training
    def train_loop(self):
        try:
            while not self.stopping.is_set():
                if not self.running.wait(timeout=0.2) or self.stopping.is_set():
                    continue
                with self.lock:
                    if self.learner.finished:
                        self.running.clear()
                        self.get_logger().info(f'reached steps={self.config.steps}; idle')
                        continue
                    self.last_terms = self.learner.step()
                    result = self.learner.checkpoint_due()
                if result is not None:
                    self.report(result)
        except Exception as error:  # noqa: BLE001 - keep the node up to say what happened
            self.error = f'{type(error).__name__}: {error_line(error)}'
            self.running.clear()
            self.get_logger().error(f'training stopped: {self.error}')

    def report(self, result):
        verdict = 'announced' if result.published else 'not announced'
        self.get_logger().info(f'checkpoint {result.path} step {result.step}: {verdict} '
                               f'({result.reason})')
        if result.published:
            self.announce(result)
        for listener in self.listeners:
            listener(result)

    def announce(self, result):
        self.pub_model.publish(String(data=result.announcement()))
        self.announced += 1

    # ------------------------------------------------------------------ services
    def on_save(self, request, response):
        try:
            with self.lock:
                result = self.learner.save()
        except Exception as error:  # noqa: BLE001 - answered, not fatal
            response.success, response.message = False, f'{type(error).__name__}: {error}'
            return response
        self.report(result)
        response.success = True
        response.message = result.announcement() if result.published else \
            f'{result.path} (step {result.step}, not announced: {result.reason})'
        return response

    def on_pause(self, request, response):
        was = self.running.is_set()
        self.running.clear()
        with self.lock:                        # returns once the current step has ended
            step = self.learner.step_count
        response.success = True
        response.message = f'paused at step {step}' + ('' if was else ' (already paused)')
        return response

    def on_resume(self, request, response):
        if self.error is not None:
            response.success, response.message = False, f'training failed: {self.error}'
        elif self.learner.finished:
            response.success = False
            response.message = f'reached steps={self.config.steps}'
        else:
            self.running.set()
            response.success, response.message = True, f'training from step ' \
                f'{self.learner.step_count}'
        return response

    # ------------------------------------------------------------------ diagnostics
    def publish_diagnostics(self):
        learner = self.learner
        last = learner.last_result
        values = {'step': learner.step_count, 'steps_per_s': f'{learner.steps_per_s:.3f}',
                  'state': 'error' if self.error else 'finished' if learner.finished else
                  ('training' if self.running.is_set() else 'paused'),
                  'checkpoints': learner.checkpoints, 'announced': self.announced,
                  'announced_step': learner.published.step if learner.published else '',
                  'publish_metric': learner.metric, 'announced_value_px': learner.reference_px,
                  'announced_reprojection_px': learner.published.metrics.get('reprojection_px')
                  if learner.published else ''}
        values.update({f'loss_{k}': f'{v:.6g}' for k, v in self.last_terms.items()
                       if k in ('loss', 'lr', *LOSS_TERMS)})
        if last is not None:
            values.update({f'last_{k}': v for k, v in last.metrics.items()
                           if not k.startswith('loss_')})
            values['last_checkpoint'] = last.path
        level = DiagnosticStatus.ERROR if self.error else DiagnosticStatus.OK
        message = self.error or f"{values['state']} at step {learner.step_count}, " \
            f'{learner.steps_per_s:.2f} steps/s'
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status.append(DiagnosticStatus(
            level=level, name='monet learner', hardware_id=self.get_name(), message=message,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()]))
        self.pub_diag.publish(msg)

    def destroy_node(self):
        self.stopping.set()
        if self.thread.is_alive() and self.thread is not threading.current_thread():
            self.thread.join(timeout=10.0)
        super().destroy_node()


def main(args=None):
    return run_node(LearnerNode, 'learner', args)


if __name__ == '__main__':
    sys.exit(main())

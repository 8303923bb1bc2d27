"""Settings of the offline 3D filters (`monet process --filter`, `monet triangulate
--filter`), in physical units. Defaults were chosen by measurement with bench/filters.py on
its synthetic set (human14 subject, 8-camera ring, 1 px noise, 10% gross outliers, 5%
dropped views, 30 frames/s); the figures are in README.md (3D filters).
"""
from dataclasses import dataclass
from types import SimpleNamespace

from monet_ros.config import setting, validate_config
from monet_ros.geometry.units import from_m, from_mm
from monet_ros.temporal.cv_kalman import V0, model_numbers

METHODS = ('none', 'kalman', 'optim')
LOSSES = ('soft_l1', 'huber', 'cauchy', 'linear')


@dataclass(frozen=True)
class FilterConfig:
    """Which filter and its parameters (validated on construction, their Kalman numbers
    in a rig's unit by in_units; errors name the field).

    method: 'none' (frame-by-frame robust triangulation as fused), 'kalman' (per-joint
    constant-velocity Kalman filter + Rauch-Tung-Striebel smoother with Mahalanobis
    gating, temporal.kalman) or 'optim' (spatiotemporal least squares over the whole
    recording: robust reprojection error + smoothness + bone lengths, temporal.optim,
    started from the Kalman result)."""
    method: str = setting('none', 'offline 3D filter', choices=METHODS)
    max_gap_s: float = setting(
        0.25, 'longest run of missing frames (s) bridged by the filter; longer gaps stay '
        'empty', minimum=0.0)
    measurement_noise_mm: float = setting(
        15.0, 'Kalman: standard deviation of a triangulated point (mm)', minimum=0.0,
        exclusive_minimum=True)
    acceleration_m_s2: float = setting(
        20.0, 'standard deviation of joint acceleration (m/s^2): Kalman process noise and '
        'the smoothness scale of optim', minimum=0.0, exclusive_minimum=True)
    gate_sigma: float = setting(
        4.0, 'Kalman: Mahalanobis distance (sigmas, 3D) beyond which a point is rejected',
        minimum=0.0, exclusive_minimum=True)
    reprojection_px: float = setting(
        4.0, 'reprojection error scale (px): the robust loss of optim discounts a view '
        'beyond it; the Kalman measurement noise of a point grows by 1 + (its mean '
        'reprojection error / this)^2', minimum=0.0, exclusive_minimum=True)
    loss: str = setting('cauchy', 'optim: robust loss of scipy.optimize.least_squares',
                        choices=LOSSES)
    bone_mm: float = setting(
        10.0, 'optim: standard deviation of a bone length about its median (mm)',
        minimum=0.0, exclusive_minimum=True)
    confidence_threshold: float = setting(
        0.1, 'optim: 2D detection score below which a view is left out', minimum=0.0)
    threshold_px: float = setting(
        15.0, 'reprojection error (px) above which a view does not count in the filtered '
        "points' error / ncams", minimum=0.0, exclusive_minimum=True)
    max_iterations: int = setting(50, 'optim: most least-squares iterations', minimum=1)

    def __post_init__(self):
        validate_config(self)

    def in_units(self, units):
        """The physical settings in a rig's length unit ('m', 'cm', 'mm'; the one place
        they are converted), checked there: noise (measurement_noise_mm), acceleration
        (acceleration_m_s2, units/s^2), bone (bone_mm), v0 (cv_kalman.V0, units/s),
        step (optim's projection-derivative step, 10 um), and the Kalman model's r2
        (units^2), q ((units/s^2)^2) and gate2 (cv_kalman.model_numbers: the variances,
        the gate and the covariance over a max_gap_s step in this unit). Raises ConfigError
        naming the field whose number cannot be used in this unit (e.g.
        measurement_noise_mm 1e155: its square in mm^2 overflows), ValueError for an
        unknown unit."""
        physical = SimpleNamespace(noise=from_mm(self.measurement_noise_mm, units),
                                   acceleration=from_m(self.acceleration_m_s2, units),
                                   bone=from_mm(self.bone_mm, units), v0=from_m(V0, units),
                                   step=from_mm(0.01, units))
        physical.r2, physical.q, physical.gate2 = model_numbers(
            self, units, ('measurement_noise_mm', physical.noise),
            ('acceleration_m_s2', physical.acceleration), 'gate_sigma', 'max_gap_s',
            physical.v0)
        return physical

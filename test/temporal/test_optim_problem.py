"""The optimisation's analytic sparse Jacobian and robust losses against finite
differences (scipy's approx_derivative), on a small problem with lens distortion."""
import numpy as np
import pytest
from scipy.optimize._numdiff import approx_derivative

from monet_ros.synth import RigConfig, make_rig
from monet_ros.temporal import FilterConfig
from monet_ros.temporal.optim import _robust, build_problem


def test_sparse_jacobian_matches_finite_differences():
    rng = np.random.default_rng(0)
    cameras = make_rig(RigConfig(num_cameras=3, distortion=(-0.1, 0.03, 0.001, -0.001, 0.0)),
                       seed=1)
    T, C = 7, 3
    stamps = np.cumsum(rng.uniform(0.02, 0.05, T) * 1e9).astype(np.int64)   # uneven times
    X = np.array([0.0, 0.0, 0.9]) + rng.normal(0, 0.2, (T, C, 3))
    points = np.stack([np.stack([c.project(X[t]) for c in cameras]) for t in range(T)])
    points += rng.normal(0, 3.0, points.shape)
    score = rng.uniform(0.2, 1.0, (T, 3, C))
    points[2, 1, 0] = np.nan                                     # a missing view
    keep = np.ones((T, C), bool)
    keep[4, 2] = False                                           # a joint not solved for
    problem = build_problem(X + rng.normal(0, 0.01, X.shape), keep, points, score, cameras,
                            stamps, [(0, 1), (1, 2)], [0.3, np.nan],
                            FilterConfig(method='optim'))
    x = problem.x0
    J = problem.jacobian(x).toarray()
    numeric = approx_derivative(problem.residuals, x, method='3-point', rel_step=1e-7)
    assert J.shape == numeric.shape == (len(problem.residuals(x)), 3 * (T * C - 1))
    np.testing.assert_allclose(J, numeric, rtol=1e-4, atol=1e-4 * np.abs(numeric).max())
    # one reprojection pair per finite detection of a kept joint, first in the residuals
    assert problem.n_reproj == 2 * (T * 3 * C - 1 - 3)


@pytest.mark.parametrize('name', ['cauchy', 'soft_l1', 'huber', 'linear'])
def test_robust_loss_derivatives(name):
    z = np.array([0.01, 0.5, 0.99, 1.5, 4.0, 100.0])
    rho, d1, d2 = _robust(name, z)
    h = 1e-6
    np.testing.assert_allclose(d1, (_robust(name, z + h)[0] - _robust(name, z - h)[0]) / (2 * h),
                               rtol=1e-5)
    np.testing.assert_allclose(d2, (_robust(name, z + h)[1] - _robust(name, z - h)[1]) / (2 * h),
                               rtol=1e-4, atol=1e-9)
    np.testing.assert_allclose(_robust(name, np.array([1e-12]))[0], 1e-12, rtol=1e-5)

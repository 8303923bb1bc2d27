"""temporal.cv_kalman (the step shared by the live filter and the offline smoother)
against the matrix form of the Kalman filter, joint by joint."""
import numpy as np

from monet_ros.temporal import cv_kalman


def test_predict_gate_update_equal_the_matrix_form():
    rng = np.random.default_rng(0)
    J, dt, q = 5, 0.04, 400.0
    p, v = rng.normal(size=(J, 3)), rng.normal(size=(J, 3))
    A = rng.normal(size=(J, 2, 2)) * 0.1
    M = A @ A.transpose(0, 2, 1) + 1e-4 * np.eye(2)        # (J, 2, 2) covariances
    P = np.stack([M[:, 0, 0], M[:, 0, 1], M[:, 1, 1]])
    X = p + rng.normal(scale=0.05, size=(J, 3))
    X[3] = np.nan                                          # no measurement
    r2 = rng.uniform(1e-4, 1e-3, J)
    accept = np.array([True, False, True, True, True])
    p1, P1 = cv_kalman.predict(p, v, P, dt, q)
    y, S, d2, measured = cv_kalman.innovation(p1, P1, X, r2)
    p2, v2, P2 = cv_kalman.update(p1, v, P1, y, S, accept & measured)
    F = np.array([[1.0, dt], [0.0, 1.0]])
    Q = q * np.array([[dt ** 4 / 4, dt ** 3 / 2], [dt ** 3 / 2, dt ** 2]])
    H = np.array([[1.0, 0.0]])
    np.testing.assert_array_equal(measured, [True, True, True, False, True])
    for j in range(J):
        x = F @ np.stack([p[j], v[j]])                     # (2, 3): one column per axis
        Pj = F @ M[j] @ F.T + Q
        np.testing.assert_allclose(cv_kalman.as_matrices(P1)[j], Pj, rtol=1e-12)
        if not measured[j]:
            assert y[j].tolist() == [0.0] * 3
            continue
        s = (H @ Pj @ H.T)[0, 0] + r2[j]
        np.testing.assert_allclose(S[j], s, rtol=1e-12)
        np.testing.assert_allclose(d2[j], ((X[j] - x[0]) ** 2).sum() / s, rtol=1e-12)
        if accept[j]:
            K = Pj @ H.T / s                               # (2, 1)
            x = x + K @ (X[j] - x[0])[None]
            Pj = (np.eye(2) - K @ H) @ Pj
        np.testing.assert_allclose(np.stack([p2[j], v2[j]]), x, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(cv_kalman.as_matrices(P2)[j], Pj, rtol=1e-10, atol=1e-18)


def test_start_sets_the_measurement_and_the_velocity_prior():
    p, v, P = np.ones((3, 3)), np.ones((3, 3)), np.ones((3, 3))
    X = np.arange(9.0).reshape(3, 3)
    which = np.array([False, True, True])
    cv_kalman.start(p, v, P, X, which, np.array([1e-4, 2e-4, 3e-4]), v0=2.0)
    np.testing.assert_array_equal(p, [[1, 1, 1], X[1], X[2]])
    np.testing.assert_array_equal(v, [[1, 1, 1], [0, 0, 0], [0, 0, 0]])
    np.testing.assert_array_equal(P.T, [[1, 1, 1], [2e-4, 0, 4], [3e-4, 0, 4]])

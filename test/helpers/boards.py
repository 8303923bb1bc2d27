"""Honest renderings of a calibration board seen by a known camera (for calibration tests).

The board image is OpenCV's own (CharucoBoard.generateImage, or a drawn checkerboard). A
pinhole view of the board plane is exactly a homography, H = K [r1 r2 t] A^-1 (A: board
units -> board-image pixels); every (supersampled) output pixel is traced back through the
camera's inverse distortion (Camera.undistort_normalized) and H^-1 to the board art, which
is sampled there (cv2.remap) and box-filtered down (cv2.INTER_AREA).
"""
import cv2
import numpy as np


def board_image(board, pixels_per_square):
    """uint8 image of the board, pixels_per_square per square; pixel centres on integers."""
    p = int(pixels_per_square)
    if board.type == 'charuco':
        return board.opencv_board().generateImage((board.board_x * p, board.board_y * p),
                                                  marginSize=0, borderBits=1)
    columns, rows = board.corner_grid          # inner corners: one more square per side
    squares = np.indices((rows + 1, columns + 1)).sum(axis=0) % 2
    image = np.kron(squares, np.ones((p, p))).astype(np.uint8) * 255
    return np.pad(image, p, constant_values=255)   # white frame around the squares


def board_to_image(board, pixels_per_square):
    """A (3, 3): board-plane (X, Y, 1) in board units -> board-image pixels."""
    s = pixels_per_square / board.square_length
    # checkerboard: a one-square white frame, then corner 0 one square further in
    offset = (2.0 * pixels_per_square if board.type == 'checkerboard' else 0.0) - 0.5
    return np.array([[s, 0.0, offset], [0.0, s, offset], [0.0, 0.0, 1.0]])


_RAYS = {}   # (camera id, supersample) -> normalised ideal rays of the output samples


def _rays(camera, supersample):
    """(H s, W s, 3) ideal normalised rays (x, y, 1) of a camera's supersampled pixel grid:
    sample (us, vs) is at pixel ((us + 0.5) / s - 0.5, ...), undistorted by the camera's
    model (cached per camera)."""
    key = (id(camera), supersample)
    if key not in _RAYS or _RAYS[key][0] is not camera:
        s = supersample
        u, v = np.meshgrid((np.arange(camera.width * s) + 0.5) / s - 0.5,
                           (np.arange(camera.height * s) + 0.5) / s - 0.5)
        uv = np.stack([u.ravel(), v.ravel()], 1)
        xy = camera.pixels_to_normalized(uv)
        if camera.has_distortion:
            xy = camera.undistort_normalized(xy)
        rays = np.concatenate([xy, np.ones((len(xy), 1))], 1)
        _RAYS.clear()
        _RAYS[key] = (camera, rays.reshape(camera.height * s, camera.width * s, 3))
    return _RAYS[key][1]


def render_view(board, camera, T_cb, pixels_per_square=60, background=150, supersample=3,
                blur_sigma=0.5, noise=1.0, rng=None):
    """(H, W) uint8 image of the board at pose T_cb (board -> camera, 4x4) in `camera`
    (a monet_ros.geometry.Camera, with its distortion), on a grey background.

    Each of s x s samples per pixel takes its viewing ray (the camera's inverse distortion),
    meets the board plane (the homography of the plane, inverted) and reads the board art
    there (bilinear); the samples are averaged (cv2.INTER_AREA: box-filtered, no
    aliasing), then a slight blur and seeded sensor noise are added."""
    W, H = camera.width, camera.height
    art = board_image(board, pixels_per_square).astype(np.float32)
    A = board_to_image(board, pixels_per_square)
    # ideal normalised ray -> board-image pixel: A [r1 r2 t]^-1
    to_art = A @ np.linalg.inv(T_cb[:3, [0, 1, 3]])
    rays = _rays(camera, supersample)
    p = rays @ to_art.T
    with np.errstate(divide='ignore', invalid='ignore'):
        mx = (p[..., 0] / p[..., 2]).astype(np.float32)
        my = (p[..., 1] / p[..., 2]).astype(np.float32)
    behind = ~(p[..., 2] > 0)           # rays that meet the plane behind the camera
    mx[behind], my[behind] = -1e6, -1e6
    fine = cv2.remap(art, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=float(background))
    image = cv2.resize(fine, (W, H), interpolation=cv2.INTER_AREA)
    if blur_sigma:
        image = cv2.GaussianBlur(image, (0, 0), blur_sigma)
    if noise:
        rng = rng or np.random.default_rng(0)
        image = image + rng.normal(0.0, noise, image.shape)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def projected_corners(board, camera, T_cb):
    """(N, 2) true pixels of the board's corners at pose T_cb (the camera's own model)."""
    X = board.object_points @ T_cb[:3, :3].T + T_cb[:3, 3]
    return camera.replace(R=np.eye(3), t=np.zeros(3)).project(X)


def board_poses_facing_up(count, centre, square_length, board, rng, tilt_deg=25.0,
                          spread=0.25):
    """(count, 4, 4) board -> world poses: the board near `centre`, its face up (world z
    up; board z points into the board, so down) tilted up to tilt_deg in random directions,
    turned about the vertical, shifted up to `spread` (world units)."""
    columns, rows = board.corner_grid
    middle = np.array([(columns + 1) / 2.0, (rows + 1) / 2.0, 0.0]) * square_length
    poses = []
    for _ in range(count):
        yaw = rng.uniform(-np.pi, np.pi)
        tilt_axis = rng.uniform(-np.pi, np.pi)
        tilt = np.radians(rng.uniform(5.0, tilt_deg))
        face_down = np.diag([1.0, -1.0, -1.0])            # board z -> world -z
        R = (cv2.Rodrigues(np.array([np.cos(tilt_axis), np.sin(tilt_axis), 0.0]) * tilt)[0]
             @ cv2.Rodrigues(np.array([0.0, 0.0, yaw]))[0] @ face_down)
        t = np.asarray(centre) + rng.uniform(-spread, spread, 3) * [1, 1, 0.3] - R @ middle
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, t
        poses.append(T)
    return np.stack(poses)

"""Calibration boards: the board's geometry, finding it in an image, and drawing it.

A board is a chessboard or a ChArUco board with `cols` x `rows` INNER corners (the corners where
four squares meet), i.e. (cols + 1) x (rows + 1) squares of `square_mm`. Board frame (mm):
origin at the board's outer top-left corner, x along the columns, y along the rows, z = x × y
(into the board); inner corner (i, j) sits at ((i + 1)·s, (j + 1)·s, 0) and has id j·cols + i —
OpenCV's ChArUco convention, used for plain chessboards too. A plain chessboard whose inner
corner counts are one odd and one even (9x6: 10x7 squares) has one black and one white outer
corner, and `cv2.findChessboardCornersSB` orders its corners consistently from any view (id 0
next to the white outer corner, as `board_texture` draws it); with cols + rows even the board
looks the same turned by 180 degrees and the order is ambiguous (`is_symmetric`).

`render_board_view` draws the board as a camera with OpenCV distortion sees it (inverse mapping:
each pixel's ray, from `cv2.undistortPointsIter`, hits the board plane): the test and demo
renderer behind the calibration tests, consistent with `cv2.projectPoints`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.vision.rig import Camera

# ChArUco markers: the 4x4 dictionaries share their first markers, so 4X4_250 also finds boards
# printed with DICT_4X4_50 / _100.
DEFAULT_DICTIONARY = "DICT_4X4_250"
MIN_CHARUCO_CORNERS = 6
MAX_CORNERS_PER_SIDE = 100  # a board with more is not printable, nor detectable at camera resolution


@dataclass(frozen=True)
class Board:
    """A calibration board: `cols` x `rows` inner corners, squares of `square_mm` mm. ChArUco
    boards also have markers of `marker_mm` (default 0.7 · square) from `dictionary`."""

    cols: int
    rows: int
    square_mm: float
    charuco: bool = False
    marker_mm: float = 0.0
    dictionary: str = DEFAULT_DICTIONARY

    def __post_init__(self) -> None:
        if not (2 <= self.cols <= MAX_CORNERS_PER_SIDE and 2 <= self.rows <= MAX_CORNERS_PER_SIDE):
            raise InputError(f"board: needs 2..{MAX_CORNERS_PER_SIDE} inner corners per side, "
                             f"got {self.cols}x{self.rows}")
        if not 0 < self.square_mm <= 1000:
            raise InputError(f"board: square size must be within 0..1000 mm, got {self.square_mm}")
        if self.charuco:
            if self.marker_mm == 0.0:
                object.__setattr__(self, "marker_mm", 0.7 * self.square_mm)
            if not 0 < self.marker_mm < self.square_mm:
                raise InputError(f"board: marker size must be in (0, square), got {self.marker_mm} mm")
            if not hasattr(cv2.aruco, self.dictionary):
                raise InputError(f"board: unknown ArUco dictionary '{self.dictionary}'")
            n_markers = (self.cols + 1) * (self.rows + 1) // 2
            size = int(self.dictionary.rsplit("_", 1)[-1]) if self.dictionary.rsplit("_", 1)[-1].isdigit() else None
            if size is not None and n_markers > size:
                raise InputError(f"board: a {self.cols}x{self.rows} ChArUco board needs {n_markers} markers, "
                                 f"more than {self.dictionary} has ({size})")

    @classmethod
    def parse(cls, text: str, square_mm: float, charuco: bool = False, marker_mm: float = 0.0,
              dictionary: str = DEFAULT_DICTIONARY) -> Board:
        """'9x6' (inner corners, COLSxROWS) -> Board."""
        m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
        if not m:
            raise InputError(f"--board '{text}': expected COLSxROWS inner corners, e.g. 9x6")
        return cls(int(m.group(1)), int(m.group(2)), float(square_mm), charuco, float(marker_mm), dictionary)

    @property
    def is_symmetric(self) -> bool:
        """A plain chessboard that looks the same turned by 180 degrees (cols + rows even): its
        corner order is ambiguous between views. ChArUco boards never are."""
        return not self.charuco and (self.cols + self.rows) % 2 == 0

    @property
    def n_corners(self) -> int:
        return self.cols * self.rows

    @property
    def size_mm(self) -> tuple[float, float]:
        """Outer size (width, height) of the squares area, mm."""
        return (self.cols + 1) * self.square_mm, (self.rows + 1) * self.square_mm

    def object_points(self) -> np.ndarray:
        """(cols·rows, 3) inner-corner positions in the board frame (mm), in id order."""
        i, j = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        P = np.zeros((self.n_corners, 3))
        P[:, 0] = (i.ravel() + 1) * self.square_mm
        P[:, 1] = (j.ravel() + 1) * self.square_mm
        return P

    def cv_charuco(self) -> cv2.aruco.CharucoBoard:
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.cols + 1, self.rows + 1), self.square_mm, self.marker_mm, d)


@dataclass(frozen=True)
class BoardDetection:
    """Inner corners found in one image: `ids` (n,) index `Board.object_points()`;
    `image_points` (n, 2) px, sub-pixel."""

    ids: np.ndarray
    image_points: np.ndarray

    def __len__(self) -> int:
        return int(self.ids.size)


def _gray(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image


def detect_board(image: np.ndarray, board: Board) -> BoardDetection | None:
    """Find the board's inner corners in an image (BGR or grey).

    Chessboard: `cv2.findChessboardCornersSB` (robust, corner order consistent between views
    on boards with cols + rows odd), refined by `cv2.cornerSubPix` in a window a quarter of the
    corner spacing wide; all corners or nothing. The classic `findChessboardCorners` is not used as a fallback: it is slower
    when the board is absent and its order flips with the view. Symmetric boards keep a
    180-degree ambiguity (see `match_order`). ChArUco: the aruco
    module's `CharucoDetector`; any subset of >= 6 non-collinear corners, ids unambiguous.
    Returns None when the board is not found.
    """
    gray = _gray(image)
    if board.charuco:
        cb = board.cv_charuco()
        corners, ids, _, _ = cv2.aruco.CharucoDetector(cb).detectBoard(gray)
        if ids is None or len(ids) < MIN_CHARUCO_CORNERS:
            return None
        if cb.checkCharucoCornersCollinear(ids):
            return None
        ids = ids.ravel().astype(int)
        order = np.argsort(ids)
        return BoardDetection(ids[order], corners.reshape(-1, 2)[order].astype(np.float64))
    size = (board.cols, board.rows)
    ok, corners = cv2.findChessboardCornersSB(gray, size, flags=cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok:
        return None
    # SB's own sub-pixel estimate is biased on tilted boards (0.5 % in focal length on the
    # rendered test views); cornerSubPix in a window inside one square removes it (0.06 %).
    grid = corners.reshape(board.rows, board.cols, 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=-1).min(),
                  np.linalg.norm(np.diff(grid, axis=1), axis=-1).min())
    w = int(np.clip(spacing / 4, 2, 10))
    corners = cv2.cornerSubPix(gray, corners.astype(np.float32), (w, w), (-1, -1),
                               (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4))
    return BoardDetection(np.arange(board.n_corners), corners.reshape(-1, 2).astype(np.float64))


def reversed_order(det: BoardDetection, board: Board) -> BoardDetection:
    """The same chessboard corners with the 180-degree-rotated id assignment (id k -> N-1-k)."""
    ids = board.n_corners - 1 - det.ids
    order = np.argsort(ids)
    return BoardDetection(ids[order], det.image_points[order])


def match_order(reference: BoardDetection, other: BoardDetection, board: Board) -> BoardDetection:
    """Resolve a plain chessboard's 180-degree order ambiguity between two views of the same
    board pose (the left and right image of a stereo pair): returns `other` with its ids
    reversed when its first->last corner direction opposes the reference's. ChArUco ids are
    unambiguous and come back unchanged."""
    if board.charuco or len(reference) != board.n_corners or len(other) != board.n_corners:
        return other
    d_ref = reference.image_points[-1] - reference.image_points[0]
    d_oth = other.image_points[-1] - other.image_points[0]
    return reversed_order(other, board) if float(d_ref @ d_oth) < 0 else other


def common_corners(a: BoardDetection, b: BoardDetection) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Corners seen in both detections: (ids, points_a (n,2), points_b (n,2))."""
    ids, ia, ib = np.intersect1d(a.ids, b.ids, return_indices=True)
    return ids, a.image_points[ia], b.image_points[ib]


# ----------------------------------------------------------------------------- drawing


def board_texture(board: Board, px_per_mm: float, margin_squares: float = 1.0) -> tuple[np.ndarray, float]:
    """The printable board image (grey uint8) at `px_per_mm`, with a white margin of
    `margin_squares` squares. Returns (image, margin_mm): texture pixel (c, r) centre is at
    board-frame ((c + 0.5) / px_per_mm - margin_mm, (r + 0.5) / px_per_mm - margin_mm)."""
    w_mm, h_mm = board.size_mm
    margin_mm = margin_squares * board.square_mm
    sq_px = board.square_mm * px_per_mm
    W, H = round(w_mm * px_per_mm), round(h_mm * px_per_mm)
    if board.charuco:
        inner = board.cv_charuco().generateImage((W, H), marginSize=0, borderBits=1)
    else:
        c, r = np.meshgrid(np.arange(W), np.arange(H))
        inner = np.where(((c // sq_px).astype(int) + (r // sq_px).astype(int)) % 2 == 0, 255, 0).astype(np.uint8)
    m = round(margin_mm * px_per_mm)
    return cv2.copyMakeBorder(inner, m, m, m, m, cv2.BORDER_CONSTANT, value=255), m / px_per_mm


class PlaneRenderer:
    """Renders a flat textured plane (a board, a marker) seen by one camera with distortion, at
    known poses. Plane frame (mm): texture pixel (c, r) centre at ((c + 0.5) / px_per_mm -
    margin_mm, (r + 0.5) / px_per_mm - margin_mm, 0). The camera's pixel rays are computed once
    (supersampled `ss` x `ss` per pixel, then area-averaged)."""

    def __init__(self, texture: np.ndarray, px_per_mm: float, margin_mm: float, cam: Camera, ss: int = 2) -> None:
        self.texture, self.px_per_mm, self.margin_mm = texture, px_per_mm, margin_mm
        self.cam, self.ss = cam, ss
        w, h = cam.size
        # hi-res pixel u' sits at low-res coordinate (u' - (ss-1)/2) / ss
        u, v = np.meshgrid((np.arange(w * ss) - (ss - 1) / 2) / ss, (np.arange(h * ss) - (ss - 1) / 2) / ss)
        uv = np.stack([u.ravel(), v.ravel()], axis=-1).reshape(-1, 1, 2)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 60, 1e-10)
        xy = cv2.undistortPointsIter(uv, cam.K, cam.dist, None, None, crit).reshape(h * ss, w * ss, 2)
        self.rays = np.concatenate([xy, np.ones((h * ss, w * ss, 1))], axis=-1)  # (H, W, 3), z = 1

    def render(self, R_cam_plane: np.ndarray, t_cam_plane: np.ndarray, background: int = 110,
               rng: np.random.Generator | None = None, noise_sigma: float = 0.0,
               base: np.ndarray | None = None) -> np.ndarray:
        """BGR image of the plane at pose X_cam = R · X_plane + t (mm): over `base` (a BGR image
        of the camera's size, for several planes in one view) or over grey `background`;
        optional Gaussian pixel noise (grey levels)."""
        n = R_cam_plane[:, 2]
        denom = self.rays @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            s = float(n @ t_cam_plane) / denom
            X = self.rays * s[..., None] - t_cam_plane
            B = X @ R_cam_plane  # plane coords: R^T (X - t)
        bad = ~(s > 0)
        mx = ((B[..., 0] + self.margin_mm) * self.px_per_mm - 0.5).astype(np.float32)
        my = ((B[..., 1] + self.margin_mm) * self.px_per_mm - 0.5).astype(np.float32)
        mx[bad], my[bad] = -1e6, -1e6
        hi = cv2.remap(self.texture, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                       borderValue=background)
        w, h = self.cam.size
        img = cv2.resize(hi, (w, h), interpolation=cv2.INTER_AREA).astype(np.float64)
        if base is not None:
            th, tw = self.texture.shape[:2]
            inside = ((mx >= -0.5) & (my >= -0.5) & (mx <= tw - 0.5) & (my <= th - 0.5)).astype(np.float32)
            alpha = cv2.resize(inside, (w, h), interpolation=cv2.INTER_AREA).astype(np.float64)
            grey = cv2.cvtColor(base, cv2.COLOR_BGR2GRAY).astype(np.float64)
            img = alpha * img + (1 - alpha) * grey
        if noise_sigma > 0:
            img += (rng or np.random.default_rng(0)).normal(0.0, noise_sigma, img.shape)
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)


class BoardRenderer(PlaneRenderer):
    """A calibration board (`board_texture`) in the board frame of the module docstring."""

    def __init__(self, board: Board, cam: Camera, px_per_mm: float = 8.0, ss: int = 2) -> None:
        self.board = board
        texture, margin_mm = board_texture(board, px_per_mm)
        super().__init__(texture, px_per_mm, margin_mm, cam, ss)


class MarkerRenderer(PlaneRenderer):
    """One ArUco marker of `side_mm` with a white quiet zone, in the marker frame of
    `marker_object_points`."""

    def __init__(self, dictionary: str, marker_id: int, side_mm: float, cam: Camera,
                 px_per_mm: float = 8.0, ss: int = 2) -> None:
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
        side_px = round(side_mm * px_per_mm)
        img = cv2.aruco.generateImageMarker(d, marker_id, side_px)
        m = round(0.25 * side_mm * px_per_mm)
        super().__init__(cv2.copyMakeBorder(img, m, m, m, m, cv2.BORDER_CONSTANT, value=255),
                         px_per_mm, m / px_per_mm, cam, ss)


# ----------------------------------------------------------------------------- single markers


def marker_object_points(side_mm: float) -> np.ndarray:
    """(4, 3) corners of a square marker in ArUco's detection order (top-left, top-right,
    bottom-right, bottom-left as printed) in the marker frame: origin at the top-left corner,
    x along the top edge, y down the left edge, z = x × y (into the marker), mm."""
    s = float(side_mm)
    return np.array([[0.0, 0.0, 0.0], [s, 0.0, 0.0], [s, s, 0.0], [0.0, s, 0.0]])


def detect_markers(image: np.ndarray, dictionary: str = DEFAULT_DICTIONARY) -> dict[int, np.ndarray]:
    """ArUco markers in an image: {id: (4, 2) corners, px, sub-pixel} (cv2.aruco.ArucoDetector
    with sub-pixel corner refinement)."""
    if not hasattr(cv2.aruco, dictionary):
        raise InputError(f"unknown ArUco dictionary '{dictionary}'")
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)), params)
    corners, ids, _ = det.detectMarkers(_gray(image))
    if ids is None:
        return {}
    return {int(i): c.reshape(4, 2).astype(np.float64) for i, c in zip(ids.ravel(), corners)}


def draw_detection(image: np.ndarray, det: BoardDetection | None, board: Board) -> np.ndarray:
    """A copy of `image` with the found corners drawn (for previews)."""
    out = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if det is None:
        return out
    if not board.charuco and len(det) == board.n_corners:
        cv2.drawChessboardCorners(out, (board.cols, board.rows),
                                  det.image_points.reshape(-1, 1, 2).astype(np.float32), True)
    else:
        cv2.aruco.drawDetectedCornersCharuco(out, det.image_points.reshape(-1, 1, 2).astype(np.float32),
                                             det.ids.reshape(-1, 1).astype(np.int32))
    return out

"""Synthetic stereo views of a photo's target floating on water (issue 2, item 7).

This module renders from camera poses it is GIVEN (DESIGN.md): it never knows about the arm.
The arm simulator (sim/world.py) and the scene generators (sim/scenes.py, sim/harbour.py) hand it poses.

Frames and units
  * World frame: mm, z up; the water surface is the plane z = 0 (waves only tilt its normal for
    shading — geometry stays flat, as a floating target rides the swell with it).
  * Camera frames: OpenCV (x right, y down, z forward). `T_world_cam` is a 4x4 with
    X_world = T_world_cam · X_cam.
  * A floater's model frame is the photo-model frame of DESIGN.md: a photo pixel (u, v) sits at
    ((u - ox)/alpha, (v - oy)/alpha, 0) mm, z into the photo. A creature lying face-up on the
    water therefore has its model z pointing down into the water: see `lying_on_water`.

API
  Water, Floater, Foam, Scene            value objects of a scene
  CameraEffects                          per-camera image effects (blur, gain, white balance,
                                         sensor noise, JPEG/MJPG chroma loss)
  render_view(scene, cam, T_world_cam, t, rng, effects) -> BGR uint8
  render_stereo(scene, rig, T_world_left, t, rng, effects) -> (left, right)
  StereoRenderer(rig).render(scene, T_world_left, t, rng, effects)   same, rays cached (video)
  lying_on_water(position_world, heading) -> T_world_model of a creature lying face-up
  Water, calm_water                      the water's look (sim/water.py); the scene generator: sim/scenes.py

Rendering: every pixel of the (distorted) image is undistorted to a ray (cv2.undistortPointsIter, so the
camera's lens distortion is honoured exactly), the ray is intersected with the water plane and with each
floater's surface (plane, or a gently bent sheet solved by fixed-point iteration), and the photo is sampled
there with premultiplied-alpha bilinear lookup from a photo prefiltered to the on-screen footprint
(anti-aliased edges, no backdrop fringe). The per-pixel passes run as numba kernels (renderer_kernel.py);
sim/water.py's `_shade_water` is the water pass's numpy reference."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from photoservo.errors import InputError
from photoservo.geometry import axis_rotation
from photoservo.geometry import make_pose as make_transform  # one builder for vision/
from photoservo.sim.water import Water, _ripple_slopes, _sample_wrapped, _shade_water, _texture, calm_water
from photoservo.vision.photo_model import PhotoModel
from photoservo.vision.rig import Camera, Rig


# ----------------------------------------------------------------------------- scene objects


@dataclass(frozen=True)
class Floater:
    """A flat textured object on the water: the masked part of `photo` (BGR uint8) scaled by
    1/alpha (px/mm) and placed by T_world_model (4x4, model frame of DESIGN.md -> world).
    bend_mm: the ends of the model's x axis are lifted this far out of the model plane (towards
    -z_model, i.e. out of the water for a creature lying face-up): z_model = -bend·(2x/width)²."""

    photo: np.ndarray
    mask: np.ndarray
    origin_px: tuple[float, float]
    alpha: float
    T_world_model: np.ndarray
    bend_mm: float = 0.0


@dataclass(frozen=True)
class Foam:
    """Foam patches floating on the water (world xy, mm): rows (x, y, radius_mm). Foam is white
    and carries no hue; it covers water and floaters alike."""

    patches: np.ndarray
    seed: int = 0


@dataclass(frozen=True)
class Scene:
    """What the cameras look at: water, an optional target, look-alike distractors, foam."""

    water: Water
    target: Floater | None = None
    distractors: tuple[Floater, ...] = ()
    foam: Foam | None = None


@dataclass(frozen=True)
class CameraEffects:
    """Per-camera image effects applied after rendering, in this order: Gaussian blur (sigma
    px), gain (brightness multiplier), white balance (B, G, R gains), sensor noise (sigma in
    8-bit DN), then a JPEG round trip at `jpeg_quality` with 4:2:0 chroma (0 = off), as MJPG
    cameras deliver."""

    blur_sigma: float = 0.0
    gain: float = 1.0
    white_balance: tuple[float, float, float] = (1.0, 1.0, 1.0)
    noise_sigma: float = 0.0
    jpeg_quality: int = 0


def lying_on_water(position_world: np.ndarray, heading: float) -> np.ndarray:
    """T_world_model of a creature lying face-up on the water at `position_world` (mm), its model
    x axis at `heading` (rad, about world z from world x). The model z axis points down."""
    R = axis_rotation(2, heading) @ np.diag([1.0, -1.0, -1.0])
    return make_transform(R, np.asarray(position_world, float))


def stereo_transform(rig: Rig) -> np.ndarray:
    """T_right_left (4x4): X_right = R · X_left + T."""
    return make_transform(rig.R, rig.T)


def floater_from_model(photo: np.ndarray, model: PhotoModel, alpha: float, T_world_model: np.ndarray,
                       bend_mm: float = 0.0) -> Floater:
    """A Floater of a photo's target as its photo-model cut it out (mask, origin)."""
    if not alpha > 0:
        raise InputError(f"alpha {alpha!r}: must be a positive px/mm ratio")
    return Floater(photo=photo, mask=model.mask, origin_px=model.origin_px, alpha=float(alpha),
                   T_world_model=np.asarray(T_world_model, float), bend_mm=float(bend_mm))


# ----------------------------------------------------------------------------- rendering


def pixel_rays(cam: Camera) -> np.ndarray:
    """(H, W, 3) rays (x, y, 1) in the camera frame through every pixel centre of the distorted
    image: the inverse of `project_points` (10 fixed-point undistortion iterations: ~1e-9 px for mild distortion)."""
    W, H = cam.size
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    pts = np.stack([u, v], -1).reshape(-1, 1, 2)
    if np.any(cam.dist):
        crit = (cv2.TERM_CRITERIA_COUNT, 10, 0.0)  # ~1e-9 px for mild distortion; EPS checks cost 3x
        xy = cv2.undistortPointsIter(pts, cam.K, cam.dist, None, None, crit).reshape(H, W, 2)
    else:
        xy = np.stack([(u - cam.K[0, 2]) / cam.K[0, 0], (v - cam.K[1, 2]) / cam.K[1, 1]], -1)
    return np.concatenate([xy, np.ones((H, W, 1))], axis=-1)


def _footprint(u: np.ndarray, v: np.ndarray, valid: np.ndarray) -> float:
    """Median photo pixels per image pixel over `valid` (from the map's finite differences; the
    fast path's is renderer_kernel.footprint_values)."""
    if u.shape[0] < 2 or u.shape[1] < 2:
        return 1.0
    du = np.hypot(np.diff(u, axis=1)[:-1], np.diff(v, axis=1)[:-1])
    dv = np.hypot(np.diff(u, axis=0)[:, :-1], np.diff(v, axis=0)[:, :-1])
    m = valid[:-1, :-1] & valid[1:, :-1] & valid[:-1, 1:]
    if not m.any():
        return 1.0
    return float(np.median(np.maximum(du[m], dv[m])))


def _window(cam: Camera, T_cam_world: np.ndarray, Xw: np.ndarray, margin: int = 4) -> tuple[slice, slice] | None:
    """Image window (rows, cols) holding the projection of world points Xw (the corners of a box
    around an object); the full image when a corner is behind the camera; None if off-image."""
    from photoservo.vision.rig import project_points

    Xc = Xw @ T_cam_world[:3, :3].T + T_cam_world[:3, 3]
    W, H = cam.size
    if np.any(Xc[:, 2] <= 1e-3):
        return slice(0, H), slice(0, W)
    uv = project_points(Xc, cam)
    # distortion can fold far-off-axis points back in: only trust corners near the image
    if not np.all(np.isfinite(uv)) or np.any(np.abs(Xc[:, :2] / Xc[:, 2:3]) > 2.0):
        return slice(0, H), slice(0, W)
    x0, y0 = np.floor(uv.min(0)).astype(int) - margin
    x1, y1 = np.ceil(uv.max(0)).astype(int) + margin + 1
    x0, y0, x1, y1 = max(0, x0), max(0, y0), min(W, x1), min(H, y1)
    if x0 >= x1 or y0 >= y1:
        return None
    return slice(y0, y1), slice(x0, x1)


def _floater_box(f: Floater) -> np.ndarray:
    """World corners of a box around a floater (its mask's rectangle, bend included)."""
    x, y, w, h = cv2.boundingRect(f.mask)
    xs = (np.array([x - 1, x + w]) - f.origin_px[0]) / f.alpha
    ys = (np.array([y - 1, y + h]) - f.origin_px[1]) / f.alpha
    zs = np.array([0.0, -abs(f.bend_mm) - 1.0, abs(f.bend_mm) + 1.0])
    P = np.array([[a, b, c] for a in xs for b in ys for c in zs])
    return P @ f.T_world_model[:3, :3].T + f.T_world_model[:3, 3]


def _photo_layers(photo: np.ndarray, mask: np.ndarray, size: tuple[int, int] | None) -> tuple[np.ndarray, np.ndarray]:
    """(premultiplied colour, coverage) float32 of a floater's photo: the mask softened into an
    anti-aliased coverage, the photo premultiplied by it, both shrunk to `size` (w, h;
    cv2.INTER_AREA: the prefilter to the on-screen footprint) unless size is None."""
    a = cv2.GaussianBlur(mask.astype(np.float32) / 255.0, (0, 0), 0.7)  # soft, anti-aliased edge
    premult = photo.astype(np.float32) * a[..., None]
    if size is not None:
        premult = cv2.resize(premult, size, interpolation=cv2.INTER_AREA)
        a = cv2.resize(a, size, interpolation=cv2.INTER_AREA)
    return premult, a


class _ByIdentity:
    """A cache key that hashes and compares by object identity; it holds the object, so the id
    stays unique while the key is cached."""

    __slots__ = ("obj",)

    def __init__(self, obj: object) -> None:
        self.obj = obj

    def __hash__(self) -> int:
        return id(self.obj)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _ByIdentity) and other.obj is self.obj


@functools.lru_cache(maxsize=16)
def _photo_layers_cached(photo: _ByIdentity, mask: _ByIdentity, size: tuple[int, int] | None) -> tuple[np.ndarray, np.ndarray]:
    """`_photo_layers` memoised by the photo and mask OBJECTS (render_view's fast path: the
    simulator renders the same photo every frame; the photo must not change in place)."""
    premult, a = _photo_layers(photo.obj, mask.obj, size)
    premult.flags.writeable = a.flags.writeable = False
    return premult, a


def _floater_layer(f: Floater, C: np.ndarray, d: np.ndarray, fast: bool = False
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(premultiplied colour h x w x 3 float32, coverage h x w float32, valid h x w bool: a hit
    in front) of one floater seen from camera centre C (world) along rays d (world, h x w x 3):
    `_lay_floater` lays it over the image. fast: the map from image to photo and its footprint
    by the compiled kernels (renderer_kernel.py), and the prefiltered photo of an earlier frame
    at the same on-screen size (`_photo_layers_cached`): equal to the exact layer up to float
    rounding."""
    u, v, valid, fp = _photo_map(f, C, d, fast)
    H, W = f.mask.shape
    size = None
    if fp > 1.2:  # prefilter the photo to the on-screen footprint (anti-aliasing)
        k = 1.0 / fp
        size = (max(2, round(W * k)), max(2, round(H * k)))
        sx, sy = size[0] / W, size[1] / H
        u, v = (u + 0.5) * sx - 0.5, (v + 0.5) * sy - 0.5
    premult, a = (_photo_layers_cached(_ByIdentity(f.photo), _ByIdentity(f.mask), size) if fast
                  else _photo_layers(f.photo, f.mask, size))
    mu, mv = u.astype(np.float32), v.astype(np.float32)
    cov = cv2.remap(a, mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    col = cv2.remap(premult, mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return col.reshape(*cov.shape, 3), cov, valid


def _lay_floater(img: np.ndarray, win: tuple[slice, slice], layer: tuple[np.ndarray, np.ndarray, np.ndarray],
                 shade: np.ndarray, fast: bool) -> None:
    """Lay a `_floater_layer` over img[win] (float32 BGR, in place): its coverage (clipped to
    0..1) over its un-premultiplied colour, shaded by the swell like the water (`shade`, full
    image). fast: in one compiled pass (renderer_kernel.composite_floater, the same float32
    arithmetic)."""
    if fast:
        from photoservo.sim import renderer_kernel as sk

        sk.composite_floater(img, win[0].start, win[1].start, *layer, shade)
        return
    col, cov, valid = layer
    cov = np.where(valid, cov, np.float32(0))
    col = np.where(cov[..., None] > 1e-4, col / np.maximum(cov, np.float32(1e-4))[..., None], np.float32(0))
    cov = np.clip(cov, 0, 1)
    col = col * (0.95 + 0.12 * (shade[win] - 1.0))[..., None]
    img[win] = img[win] * (1 - cov[..., None]) + col * cov[..., None]


def _photo_map(f: Floater, C: np.ndarray, d: np.ndarray, fast: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(u, v, valid, footprint): the photo pixel (u, v) where each ray d (world, h x w x 3) from
    camera centre C (world, mm) meets the floater's surface (-1e4 where it does not, in front:
    valid False), and the median photo px per image px there (`_footprint`). fast: the
    compiled kernels; else numpy (the reference)."""
    Tm = np.linalg.inv(f.T_world_model)
    o = Tm[:3, :3] @ C + Tm[:3, 3]
    H, W = f.mask.shape
    half_w = 0.5 * cv2.boundingRect(f.mask)[2] / f.alpha if f.bend_mm != 0.0 else 1.0
    if fast:
        from photoservo.sim import renderer_kernel as sk

        u, v = np.empty(d.shape[:2]), np.empty(d.shape[:2])
        valid, near = np.empty(d.shape[:2], np.bool_), np.empty(d.shape[:2], np.bool_)
        sk.floater_hits(d, np.ascontiguousarray(Tm[:3, :3]), o, float(f.alpha), float(f.origin_px[0]),
                        float(f.origin_px[1]), float(W), float(H), float(f.bend_mm), half_w, u, v, valid, near)
        out = np.empty(max(0, d.shape[0] - 1) * max(0, d.shape[1] - 1))
        n = sk.footprint_values(u, v, near, out)
        return u, v, valid, float(np.median(out[:n])) if n else 1.0
    dm = d.astype(np.float64) @ Tm[:3, :3].T
    dz = dm[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(np.abs(dz) > 1e-12, -o[2] / dz, np.nan)
        for _ in range(8 if f.bend_mm != 0.0 else 0):  # fixed point: z(x(s)) on the bent sheet z = -b (x / half_w)^2
            xm = o[0] + s * dm[..., 0]
            zt = -f.bend_mm * (xm / half_w) ** 2
            s = (zt - o[2]) / dz
    valid = np.isfinite(s) & (s > 0)
    u = np.where(valid, (o[0] + s * dm[..., 0]) * f.alpha + f.origin_px[0], -1e4)
    v = np.where(valid, (o[1] + s * dm[..., 1]) * f.alpha + f.origin_px[1], -1e4)
    near = valid & (u > -2) & (v > -2) & (u < W + 1) & (v < H + 1)
    return u, v, valid, _footprint(u, v, near)


def _foam_layer(foam: Foam, P: np.ndarray) -> np.ndarray:
    """Foam coverage (0..1) at world water points P (H, W, 2): ragged blobs around each patch."""
    tex = _texture(foam.seed + 3, 128, 3.0)
    ragged = _sample_wrapped(tex, P[..., 0], P[..., 1], 1.5)
    cov = np.zeros(P.shape[:2], np.float32)
    for x, y, r in np.asarray(foam.patches, float).reshape(-1, 3):
        dist = np.hypot(P[..., 0] - np.float32(x), P[..., 1] - np.float32(y)) / np.float32(r)
        cov = np.maximum(cov, np.clip((1.0 - dist + 0.35 * ragged) * 4, 0, 1))
    return cov


NOISE_TILE_PAD = 64  # the pre-drawn noise tile is this many px larger than the image each way


@functools.lru_cache(maxsize=4)
def _noise_tile(height: int, width: int, sigma: float) -> np.ndarray:
    """Gaussian noise of std `sigma` (float32, (height + pad) x (width + pad) x 3), drawn once
    per image size from a fixed seed; memoised, read-only. `_apply_effects(noise_tile=True)`
    adds or subtracts a window of it at a random offset: per-pixel independent noise for ~1 %
    of the cost of drawing it afresh."""
    pad = NOISE_TILE_PAD
    tile = np.random.default_rng([height, width, 17]).standard_normal((height + pad, width + pad, 3),
                                                                       dtype=np.float32)
    tile *= np.float32(sigma)
    tile.flags.writeable = False
    return tile


def _apply_effects(img: np.ndarray, fx: CameraEffects, rng: np.random.Generator,
                   noise_tile: bool = False) -> np.ndarray:
    """CameraEffects on a float32 BGR image. noise_tile: the sensor noise is a window of
    `_noise_tile` at an offset drawn from `rng` (with a random sign) instead of fresh draws."""
    if fx.blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), fx.blur_sigma)
    gains = fx.gain * np.asarray(fx.white_balance, np.float32)
    if np.any(gains != 1):  # (a product with 1.0 would only cost time)
        img = img * gains
    if noise_tile:  # cv2 rounds and saturates to uint8 in the same pass (numpy's rint/clip: ~10x slower)
        if fx.noise_sigma > 0:
            H, W = img.shape[:2]
            oy, ox, sign = rng.integers(0, NOISE_TILE_PAD, 3)
            noise = _noise_tile(H, W, float(fx.noise_sigma))[oy:oy + H, ox:ox + W, :img.shape[2]]
            out = (cv2.add if sign % 2 else cv2.subtract)(img, noise, dtype=cv2.CV_8U)
        else:
            out = cv2.add(img, (0.0, 0.0, 0.0, 0.0), dtype=cv2.CV_8U)
    else:
        if fx.noise_sigma > 0:
            img = img + rng.normal(0, fx.noise_sigma, img.shape).astype(np.float32)
        out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if fx.jpeg_quality > 0:
        _, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(fx.jpeg_quality),
                                            cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420])
        out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    return out


def coarse_rays(rays: np.ndarray, stride: int) -> np.ndarray:
    """Camera-frame rays (ceil(H/stride), ceil(W/stride), 3) through the centres of the
    stride x stride pixel blocks of `rays` (H, W, 3; block means, cv2.INTER_AREA): the grid that
    cv2.resize (INTER_LINEAR) maps back onto the full image in render_view's fast path."""
    H, W = rays.shape[:2]
    return cv2.resize(np.ascontiguousarray(rays, np.float64), (-(-W // stride), -(-H // stride)),
                      interpolation=cv2.INTER_AREA)


def _world_rays(rays: np.ndarray, R: np.ndarray, compiled: bool = False) -> np.ndarray:
    """Unit world rays (h, w, 3 float32) of camera-frame rays (h, w, 3) for camera rotation R
    (compiled: renderer_kernel.window_rays, the same rays in one pass)."""
    if compiled:
        from photoservo.sim.renderer_kernel import window_rays
        return window_rays(rays, R)
    d = (rays @ R.T).astype(np.float32)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)  # not in place: numpy's broadcast /= is ~5x slower


def _water_hits(rays: np.ndarray, R: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(d, P, water) for camera-frame rays (h, w, 3) of a camera at rotation R, centre C
    (camera -> world, mm): unit world rays d (float32), their hits P (h, w, 2, world xy mm) on
    the water plane z = 0 and whether they hit it (rays at or above the horizon: P = C)."""
    d = _world_rays(rays, R)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(d[..., 2] < -1e-9, np.float32(-C[2]) / d[..., 2], np.float32(np.nan))
    water = np.isfinite(s) & (s > 0)
    P = C[:2].astype(np.float32) + np.where(water, s, np.float32(0))[..., None] * d[..., :2]
    return d, P, water


def _water_pass(w: Water, rays: np.ndarray, R: np.ndarray, C: np.ndarray, t: float, compiled: bool
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(image, shade, water points P, water mask, world rays d) of the water seen along `rays`
    from a camera at R, C (world, mm) at time t: the numba kernel or the numpy reference."""
    if compiled:
        from photoservo.sim import renderer_kernel as sk

        dx, dy = _ripple_slopes(w.seed)
        return sk.shade_water(rays, R, C, w.waves, t, w.ripple, dx, dy, _texture(w.seed + 1, 128, 4.0), w.mottle,
                              w.sun_dir, w.colour_bgr, w.sky_bgr, w.glint)
    d, P, water = _water_hits(rays, R, C)
    img, shade = _shade_water(w, P, d, t)
    return np.where(water[..., None], img, np.asarray(w.sky_bgr, np.float32)), shade, P, water, d


def render_view(scene: Scene, cam: Camera, T_world_cam: np.ndarray, t: float = 0.0,
                rng: np.random.Generator | None = None, effects: CameraEffects | None = None,
                rays: np.ndarray | None = None, compiled: bool = True, water_stride: int = 1,
                water_rays: np.ndarray | None = None) -> np.ndarray:
    """What camera `cam` at pose T_world_cam (4x4, camera -> world, mm) sees of `scene` at time
    t (s): BGR uint8 of cam.size, lens distortion included. `rng` drives the sensor noise (a
    fixed default seed when None, so renders are reproducible). `rays`: `pixel_rays(cam)`,
    precomputed when rendering many frames of one camera (see `StereoRenderer`). `compiled`:
    the water pass by the numba kernel (renderer_kernel.py, ~10x faster) or by the numpy
    reference `_shade_water` (identical model; textures sampled without OpenCV's 1/32-texel
    weight quantisation, so the two differ by well under 1 DN on average).

    water_stride > 1 is the fast path for live simulation (~7x less CPU at 4, benchmarks/render_speed.py): the
    water is shaded on a grid of one ray per stride x stride block (`coarse_rays(rays, stride)`, or `water_rays`
    when precomputed) and upsampled bilinearly, so waves, mottle and glints keep their look but not their finest
    detail; floaters and foam are still drawn at full resolution (full-resolution rays only inside their image
    windows, by the compiled kernels), and the sensor noise is a window of a pre-drawn noise tile at a random
    offset. Same rng state -> same image. water_stride = 1 is the exact render."""
    if int(water_stride) != water_stride or water_stride < 1:
        raise InputError(f"water_stride {water_stride!r}: must be a positive integer")
    water_stride = int(water_stride)
    T = np.asarray(T_world_cam, float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InputError("T_world_cam: expected a finite 4x4 transform")
    rng = np.random.default_rng(0) if rng is None else rng
    R, C = T[:3, :3], T[:3, 3]
    rays = pixel_rays(cam) if rays is None else rays
    fast = water_stride > 1
    rays_w = rays if not fast else coarse_rays(rays, water_stride) if water_rays is None else water_rays
    img, shade, P, water, d = _water_pass(scene.water, rays_w, R, C, t, compiled)
    if fast:  # back to full resolution; per-pixel rays and hits only inside object windows
        size = (rays.shape[1], rays.shape[0])
        # glints are far brighter than white: clipped first, they blend out instead of blocky squares
        img = cv2.resize(np.minimum(img, np.float32(255)), size, interpolation=cv2.INTER_LINEAR)
        shade = cv2.resize(shade, size, interpolation=cv2.INTER_LINEAR)

    def hits(win: tuple[slice, slice]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return _water_hits(rays[win], R, C) if fast else (d[win], P[win], water[win])

    T_cam_world = np.linalg.inv(T)
    for f in (*scene.distractors, *(() if scene.target is None else (scene.target,))):
        win = _window(cam, T_cam_world, _floater_box(f))
        if win is not None:
            _lay_floater(img, win, _floater_layer(f, C, _world_rays(rays[win], R, True) if fast else d[win], fast),
                         shade, fast)
    if scene.foam is not None and len(scene.foam.patches):
        for patch in np.asarray(scene.foam.patches, float).reshape(-1, 3):
            x, y, r = patch
            box = np.array([[x + a * 1.5 * r, y + b * 1.5 * r, 0.0] for a in (-1, 1) for b in (-1, 1)])
            win = _window(cam, T_cam_world, box)
            if win is None:
                continue
            _, P_win, water_win = hits(win)
            cov = _foam_layer(Foam(patch[None], scene.foam.seed), P_win) * water_win
            img[win] = img[win] * (1 - cov[..., None]) + np.float32(238) * cov[..., None]
    return _apply_effects(img.astype(np.float32, copy=False), effects or CameraEffects(), rng, noise_tile=fast)


def render_stereo(scene: Scene, rig: Rig, T_world_left: np.ndarray, t: float = 0.0,
                  rng: np.random.Generator | None = None,
                  effects: tuple[CameraEffects, CameraEffects] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Both views of a stereo rig whose left camera is at T_world_left (4x4, mm); the right
    camera follows from the rig's extrinsics (X_right = R · X_left + T)."""
    return StereoRenderer(rig).render(scene, T_world_left, t, rng, effects)


class StereoRenderer:
    """`render_stereo` for many frames of one rig: the per-pixel rays are computed once.

    >>> from photoservo.sim.scenes import synthetic_rig
    >>> r = StereoRenderer(synthetic_rig())
    >>> T_world_left = make_transform(np.diag([1.0, -1.0, -1.0]), [0.0, 0.0, 1000.0])  # 1 m up, looking down
    >>> left, right = r.render(Scene(water=calm_water(0)), T_world_left, 0.0, water_stride=4)
    >>> left.shape, right.dtype
    ((480, 640, 3), dtype('uint8'))
    """

    def __init__(self, rig: Rig) -> None:
        self.rig = rig
        self.rays_left = pixel_rays(rig.left)
        self.rays_right = pixel_rays(rig.right)
        self.T_left_right = np.linalg.inv(stereo_transform(rig))
        self._water_rays: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def water_rays(self, stride: int) -> tuple[np.ndarray, np.ndarray]:
        """(left, right) `coarse_rays` for render_view's fast path at `stride`, computed once."""
        if stride not in self._water_rays:
            self._water_rays[stride] = (coarse_rays(self.rays_left, stride), coarse_rays(self.rays_right, stride))
        return self._water_rays[stride]

    def render(self, scene: Scene, T_world_left: np.ndarray, t: float = 0.0,
               rng: np.random.Generator | None = None,
               effects: tuple[CameraEffects, CameraEffects] | None = None,
               water_stride: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """(left, right) BGR images with the left camera at T_world_left (4x4, mm) at time t (s).
        water_stride > 1: render_view's fast path (coarse water, full-resolution floaters)."""
        rng = np.random.default_rng(0) if rng is None else rng
        T_world_right = np.asarray(T_world_left, float) @ self.T_left_right
        fl, fr = effects if effects is not None else (None, None)
        wl, wr = self.water_rays(water_stride) if water_stride > 1 else (None, None)
        return (render_view(scene, self.rig.left, T_world_left, t, rng, fl, self.rays_left,
                            water_stride=water_stride, water_rays=wl),
                render_view(scene, self.rig.right, T_world_right, t, rng, fr, self.rays_right,
                            water_stride=water_stride, water_rays=wr))

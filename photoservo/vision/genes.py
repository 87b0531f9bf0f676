"""The GA's genes (method step 4): the 7 genes of a pose and their decoding into (R, t, alpha) for
one rig and photo-model (`GeneSpace`), the search volume as a gene box and windows around a pose.

Genes. The paper's 7 genes are (x, y, z, three orientation parameters, alpha). By default
(`[estimator] genes = "image"`) the same 7 degrees of freedom are coded so that the search box
is the rig's field of view and the fitness landscape is nearly separable:

    g = (u, v, q, psi, tilt_x, tilt_y, ln s)

    u, v    px   where the model origin projects in the LEFT image (pinhole, no distortion)
    q       1/m  inverse depth, q = 1000 / z          (uniform in q = uniform in disparity)
    psi     rad  heading, tilt_x, tilt_y rad: tilt rotation vector (see `geometry.py`)
    ln s         s = fx / (alpha z): image px per photo px at a frontal pose

    t = z · K^-1 (u, v, 1),   alpha = fx / (s z),   R = R_tilt(tilt_x, tilt_y) · Rz(psi)

One image fixes (u, v, s) and the heading; the second camera fixes q through parallax — and with
it alpha: a big far model and a small near one agree in one camera, not in two (method step 3).
`genes = "cartesian"` is the paper's literal coding (x, y, z, psi, tilt_x, tilt_y, ln alpha).

Default search volume: the left image (u, v) with the origin also inside the right image, depth
z_min..z_max, any heading, tilt <= tilt_max, alpha_min..alpha_max and an apparent size of at
least `min_apparent_px`; candidates outside it score -inf.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from photoservo.geometry import heading_tilt_from_rotation, rotation_from_heading_tilt
from photoservo.vision.ga import Region
from photoservo.vision.photo_model import PhotoModel
from photoservo.vision.rig import Rig

if TYPE_CHECKING:
    from photoservo.vision.estimator import EstimatorParams


@dataclass(frozen=True)
class GeneSpace:
    """Decodes genes (P, 7) into poses for one rig and photo-model (module docstring)."""

    kind: Literal["image", "cartesian"]
    rig: Rig
    model: PhotoModel
    params: EstimatorParams

    @property
    def fx(self) -> float:
        return float(self.rig.left.K[0, 0])

    def decode(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Genes (P, 7) -> (R (P,3,3), t (P,3) mm, alpha (P,) px/mm, valid (P,) bool).
        Tilt beyond tilt_max is clamped onto it; `valid` is False outside the search volume:
        depth or alpha out of range, model origin outside either image (pinhole), apparent size
        below min_apparent_px. Compiled (`genes_kernel.decode_genes`: the tracker decodes its
        population a few times a generation); `decode_reference` is the numpy version."""
        from photoservo.vision.genes_kernel import decode_genes

        g = np.ascontiguousarray(g, dtype=np.float64)
        if g.ndim == 1:
            g = g[None]
        P = len(g)
        R, t, alpha, valid = np.empty((P, 3, 3)), np.empty((P, 3)), np.empty(P), np.empty(P, np.bool_)
        decode_genes(g, self.kind == "image", math.radians(self.params.tilt_max_deg), *self._decode_constants,
                     R, t, alpha, valid)
        return R, t, alpha, valid

    @functools.cached_property
    def _decode_constants(self) -> tuple[np.ndarray, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """`decode_genes`'s rig and volume arguments: K, fx, limits, rig R and T, cams."""
        p, rig = self.params, self.rig
        limits = np.array([p.z_min_mm, p.z_max_mm, p.alpha_min, p.alpha_max,
                           self.fx * max(self.model.size_px) / p.min_apparent_px])
        cams = np.array([[c.K[0, 0], c.K[1, 1], c.K[0, 2], c.K[1, 2], c.width, c.height]
                         for c in (rig.left, rig.right)], dtype=np.float64)
        return (np.ascontiguousarray(rig.left.K, np.float64), self.fx, limits,
                np.ascontiguousarray(rig.R, np.float64), np.ascontiguousarray(rig.T, np.float64).reshape(3), cams)

    def decode_reference(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """`decode` in numpy (the reference the compiled kernel is tested against)."""
        g = np.asarray(g, dtype=np.float64)
        if g.ndim == 1:
            g = g[None]
        p, K, rig = self.params, self.rig.left.K, self.rig
        tmax = math.radians(p.tilt_max_deg)
        tx, ty = g[:, 4], g[:, 5]
        th2 = tx * tx + ty * ty
        if np.any(th2 > tmax * tmax):
            shrink = np.minimum(1.0, tmax / np.sqrt(np.maximum(th2, 1e-24)))
            tx, ty = tx * shrink, ty * shrink
        R = rotation_from_heading_tilt(g[:, 3], tx, ty)
        t = np.empty((len(g), 3))
        if self.kind == "image":
            z = 1000.0 / g[:, 2]
            t[:, 0] = (g[:, 0] - K[0, 2]) * (z / K[0, 0])
            t[:, 1] = (g[:, 1] - K[1, 2]) * (z / K[1, 1])
            t[:, 2] = z
            alpha = self.fx / (np.exp(g[:, 6]) * z)
        else:
            t[:] = g[:, :3]
            z = t[:, 2]
            alpha = np.exp(g[:, 6])
        valid = (z >= p.z_min_mm * 0.999) & (z <= p.z_max_mm * 1.001)
        valid &= (alpha >= p.alpha_min * 0.999) & (alpha <= p.alpha_max * 1.001)
        # apparent size (longest side of the target in the image at a frontal pose)
        valid &= alpha * z <= self.fx * max(self.model.size_px) / p.min_apparent_px
        # the model origin must be seen by both cameras
        with np.errstate(divide="ignore", invalid="ignore"):
            for cam, X in ((rig.left, t), (rig.right, t @ rig.R.T + rig.T)):
                w = 1.0 / X[:, 2]
                uc = X[:, 0] * w * cam.K[0, 0] + cam.K[0, 2]
                vc = X[:, 1] * w * cam.K[1, 1] + cam.K[1, 2]
                valid &= (w > 0) & (uc >= -0.5) & (uc <= cam.width - 0.5) & (vc >= -0.5) & (vc <= cam.height - 0.5)
        return R, t, alpha, valid

    def encode(self, R: np.ndarray, t: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        """Poses -> genes (P, 7), the inverse of `decode` (tilt not clamped)."""
        R = np.asarray(R, dtype=np.float64).reshape(-1, 3, 3)
        t = np.asarray(t, dtype=np.float64).reshape(-1, 3)
        alpha = np.asarray(alpha, dtype=np.float64).reshape(-1)
        psi, tx, ty = heading_tilt_from_rotation(R)
        if self.kind == "image":
            K = self.rig.left.K
            z = t[:, 2]
            u = K[0, 0] * t[:, 0] / z + K[0, 2]
            v = K[1, 1] * t[:, 1] / z + K[1, 2]
            return np.column_stack([u, v, 1000.0 / z, psi, tx, ty, np.log(self.fx / (alpha * z))])
        return np.column_stack([t, psi, tx, ty, np.log(alpha)])

    def full_region(self) -> Region:
        """The default search volume as a gene box (module docstring)."""
        p, cam = self.params, self.rig.left
        tmax = math.radians(p.tilt_max_deg)
        if self.kind == "image":
            # apparent scale s = fx / (alpha z): from the smallest apparent size to the largest s
            # any (alpha, z) of the volume allows, capped at 3x the image width
            longest = max(self.model.size_px)
            s_lo = p.min_apparent_px / longest
            s_hi = min(self.fx / (p.alpha_min * p.z_min_mm), 3.0 * cam.width / longest)
            s_lo = max(s_lo, self.fx / (p.alpha_max * p.z_max_mm))
            lo = [-0.5, -0.5, 1000.0 / p.z_max_mm, -math.pi, -tmax, -tmax, math.log(s_lo)]
            hi = [cam.width - 0.5, cam.height - 0.5, 1000.0 / p.z_min_mm, math.pi, tmax, tmax,
                  math.log(max(s_hi, s_lo * 1.01))]
        else:
            half_w = p.z_max_mm * max(cam.K[0, 2] + 0.5, cam.width - cam.K[0, 2]) / cam.K[0, 0]
            half_h = p.z_max_mm * max(cam.K[1, 2] + 0.5, cam.height - cam.K[1, 2]) / cam.K[1, 1]
            lo = [-half_w, -half_h, p.z_min_mm, -math.pi, -tmax, -tmax, math.log(p.alpha_min)]
            hi = [half_w, half_h, p.z_max_mm, math.pi, tmax, tmax, math.log(p.alpha_max)]
        return Region.box(lo, hi, [False, False, False, True, False, False, False])

    def window(self, R: np.ndarray, t: np.ndarray, alpha: float, position_mm: float,
               heading_deg: float, tilt_deg: float, alpha_frac: float) -> Region:
        """A gene box around one pose: position +- position_mm (converted to image px and inverse
        depth for the image coding), heading +- heading_deg (>= 180: any), tilt +- tilt_deg,
        alpha within a factor (1 +- alpha_frac). Clipped to the full volume."""
        g0 = self.encode(R, t, alpha)[0]
        full = self.full_region()
        z = float(np.asarray(t).reshape(3)[2])
        tw = math.radians(tilt_deg)
        la = math.log1p(alpha_frac)
        if self.kind == "image":
            du = self.rig.left.K[0, 0] * position_mm / z
            dv = self.rig.left.K[1, 1] * position_mm / z
            dq = 1000.0 / max(z - position_mm, 1e-3) - 1000.0 / z
            half = np.array([du, dv, dq, 0.0, tw, tw, la])
        else:
            half = np.array([position_mm, position_mm, position_mm, 0.0, tw, tw, la])
        lo, hi = g0 - half, g0 + half
        periodic = np.zeros(7, bool)
        if heading_deg >= 180:
            lo[3], hi[3], periodic[3] = -math.pi, math.pi, True
        else:
            lo[3], hi[3] = g0[3] - math.radians(heading_deg), g0[3] + math.radians(heading_deg)
        keep = ~periodic
        keep[3] = False
        lo[keep] = np.maximum(lo[keep], full.lo[keep])
        hi[keep] = np.minimum(hi[keep], full.hi[keep])
        hi = np.maximum(hi, lo + 1e-9)
        return Region.box(lo, hi, periodic)

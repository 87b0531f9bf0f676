"""Seeding the acquisition's GA islands (method step 4, our addition): where in the stereo pair
the photo's creature may be, before any pose is scored.

The target's hues (the model's `target_hues`) are segmented in both images; blobs are paired
along the epipolar lines and triangulated, which gives the model origin's pixel (u, v) and inverse
depth q, the apparent scale s from the blob area and two heading hypotheses from the blob's
principal axis (`seed_genes`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

from photoservo.vision.fitness import StereoHue
from photoservo.vision.ga import Region
from photoservo.vision.genes import GeneSpace
from photoservo.vision.parts import FOAM
from photoservo.vision.photo_model import PhotoModel, target_hue_lut
from photoservo.vision.rig import Rig

if TYPE_CHECKING:
    from photoservo.vision.estimator import EstimatorParams


@dataclass(frozen=True)
class Blob:
    """A connected region of target hue in one image: centroid (u, v) px, area px, major-axis
    angle (rad, image x toward y), elongation (major / minor axis) and the central second
    moments per unit area `mu` = (mu20, mu02, mu11) px^2 (what `union` adds up)."""

    centroid: np.ndarray
    area: float
    angle: float
    elongation: float
    mu: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def half_length(self) -> float:
        """Half the major axis of the blob's equivalent ellipse (px)."""
        return 2.0 * math.sqrt(max(0.5 * (self.mu[0] + self.mu[1]
                                          + math.hypot(self.mu[0] - self.mu[1], 2 * self.mu[2])), 0.0))


def _shape(c: np.ndarray, a: float, mu20: float, mu02: float, mu11: float) -> Blob:
    """A Blob from its centroid, area and central second moments per unit area."""
    angle = 0.5 * math.atan2(2 * mu11, mu20 - mu02)
    d = math.sqrt(max(0.0, 4 * mu11 * mu11 + (mu20 - mu02) ** 2))
    l1, l2 = (mu20 + mu02 + d) / 2, (mu20 + mu02 - d) / 2
    return Blob(centroid=c, area=a, angle=angle, elongation=math.sqrt(l1 / max(l2, 1e-9)), mu=(mu20, mu02, mu11))


def _moments_shape(m: dict) -> Blob:
    a = m["m00"]
    return _shape(np.array([m["m10"] / a, m["m01"] / a]), a, m["mu20"] / a, m["mu02"] / a, m["mu11"] / a)


def union(blobs: list[Blob]) -> Blob:
    """The blob of several pieces taken together (area, centroid and second moments of the union:
    the parallel-axis theorem), e.g. a creature cut in two by a foam band."""
    a = np.array([b.area for b in blobs])
    c = np.array([b.centroid for b in blobs])
    A = float(a.sum())
    cc = (a[:, None] * c).sum(axis=0) / A
    d = c - cc
    mu = np.array([b.mu for b in blobs])
    mu20 = float((a * (mu[:, 0] + d[:, 0] ** 2)).sum() / A)
    mu02 = float((a * (mu[:, 1] + d[:, 1] ** 2)).sum() / A)
    mu11 = float((a * (mu[:, 2] + d[:, 0] * d[:, 1])).sum() / A)
    return _shape(cc, A, mu20, mu02, mu11)


def target_mask(hue: np.ndarray, target_hues: np.ndarray, dense_px: int = 7, stray_max: float = 0.0025,
                above_water_sd: float = 0.0) -> np.ndarray:
    """The target-hue pixels of a hue image that seed from (uint8, 255). A region of target hue
    is where a pixel's `dense_px` square neighbourhood is at least half target hue. Water whose
    hue lies at the edge of the target's tolerance, under sensor noise, holds target-hue pixels
    scattered everywhere (a third of them, say) that form no region; closed and merged, they
    would join the creature into one blob the size of the image: when more than `stray_max` of
    the pixels farther than `dense_px` from every region have target hue, the mask is the regions
    alone. Otherwise (clean water: 0-0.05 % on the two generators, speckled harbour water
    0.5-28 %) it is every target-hue pixel, so the creature's thin arms, fins and rim keep their
    part of its area and moments. Water with target hue in 40 % of its pixels holds half-full
    neighbourhoods all over (harbour 1038: a tenth of them), regions that merge with the creature
    and pull its blob's centroid off: with `above_water_sd` > 0 a region's neighbourhood must also
    hold that many binomial standard deviations more target hue than the frame's median one, the
    water's (the creature covers less than half the frame; a full neighbourhood always counts)."""
    on = cv2.LUT(hue, target_hue_lut(target_hues).astype(np.uint8))
    count = cv2.boxFilter(on, -1, (dense_px, dense_px), normalize=False)
    n = dense_px * dense_px
    region = on & (count >= (n + 1) // 2).astype(np.uint8)
    near = cv2.dilate(region, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * dense_px + 1,) * 2))
    away = on.size - np.count_nonzero(near)
    stray = np.count_nonzero(on & (1 - near))
    if stray <= stray_max * max(away, 1):
        return on * np.uint8(255)
    if above_water_sd > 0:
        r = float(np.median(count)) / n
        region &= (count >= min(n, math.ceil(n * r + above_water_sd * math.sqrt(n * r * (1.0 - r))))).astype(np.uint8)
    return region * np.uint8(255)


# a seeding region on water speckled with target hue stands this many binomial standard deviations above the
# water's own density of target hue (`target_mask`): at 4, about 1 in 30000 of the water's neighbourhoods
ABOVE_WATER_SD = 4.0


def target_blobs(hue: np.ndarray, target_hues: np.ndarray, min_px: int, max_blobs: int = 12,
                 merge_px: int = 9) -> list[Blob]:
    """Blobs of the model's target hues in a hue image (largest first): regions of target hue
    (`target_mask`, standing `ABOVE_WATER_SD` above the water's; pixels scattered in it do not
    count). Pieces closer than about `merge_px` (a creature cut up by foam, glints or its own
    markings) count as one blob; its area and moments are those of the target-hue pixels only."""
    mask = cv2.morphologyEx(target_mask(hue, target_hues, above_water_sd=ABOVE_WATER_SD), cv2.MORPH_CLOSE,
                            cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
    grouped = cv2.dilate(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (merge_px, merge_px)))
    _, labels, stats, _ = cv2.connectedComponentsWithStats(grouped, connectivity=8)
    labels[mask == 0] = 0
    area = np.bincount(labels.ravel(), minlength=len(stats)).astype(float)
    order = [i for i in np.argsort(-area, kind="stable") if i > 0 and area[i] >= min_px]
    blobs = []
    for i in order[:max_blobs]:
        x, y, w, h = stats[i, :4]
        b = _moments_shape(cv2.moments((labels[y:y + h, x:x + w] == i).astype(np.uint8), binaryImage=True))
        blobs.append(Blob(b.centroid + (x, y), b.area, b.angle, b.elongation, b.mu))
    return blobs


@dataclass(frozen=True)
class BlobPair:
    """A left and a right blob matched along the epipolar line, triangulated: origin guess in
    the left camera frame (mm), the left blob, the epipolar residual (px)."""

    position_mm: np.ndarray
    left: Blob
    right: Blob
    residual_px: float


def match_blobs(left: list[Blob], right: list[Blob], rig: Rig, params: EstimatorParams) -> list[BlobPair]:
    """Pair blobs whose centroids lie on each other's epipolar lines (within epipolar_tol_px plus
    a share of the blob size), whose triangulated depth is in the search volume and whose areas
    agree within 2.5x; each left blob takes its best right blob. Largest first."""
    if not left or not right:
        return []
    def norm(blobs: list[Blob], cam) -> np.ndarray:
        pts = np.array([b.centroid for b in blobs], np.float64).reshape(-1, 1, 2)
        return cv2.undistortPoints(pts, cam.K, cam.dist).reshape(-1, 2)
    nl, nr = norm(left, rig.left), norm(right, rig.right)
    R, T = rig.R, rig.T
    tx = np.array([[0, -T[2], T[1]], [T[2], 0, -T[0]], [-T[1], T[0], 0]])
    E = tx @ R  # x_r^T E x_l = 0
    f = float(rig.right.K[0, 0])
    pairs = []
    for i, bl in enumerate(left):
        xl = np.array([nl[i, 0], nl[i, 1], 1.0])
        line = E @ xl
        best = None
        for j, br in enumerate(right):
            if not (1 / 2.5 <= br.area / bl.area <= 2.5):
                continue
            xr = np.array([nr[j, 0], nr[j, 1], 1.0])
            err = abs(line @ xr) / max(math.hypot(line[0], line[1]), 1e-12) * f
            if err > params.epipolar_tol_px + 0.15 * math.sqrt(min(bl.area, br.area)):
                continue
            # depth along the left ray: least squares of  z_l R xl + T = z_r xr
            A = np.column_stack([R @ xl, -xr])
            (zl, zr), *_ = np.linalg.lstsq(A, -T, rcond=None)
            if not (params.z_min_mm <= zl <= params.z_max_mm) or zr <= 0:
                continue
            if best is None or err < best[0]:
                best = (err, zl * xl, br)
        if best is not None:
            pairs.append(BlobPair(position_mm=best[1], left=bl, right=best[2], residual_px=best[0]))
    return pairs


def stereo_blobs(hue_left: np.ndarray, hue_right: np.ndarray, model: PhotoModel,
                 params: EstimatorParams) -> tuple[list[Blob], list[Blob]]:
    """The model's target-hue blobs of the left and the right hue image (`target_blobs`,
    min_blob_px), largest first."""
    return (target_blobs(hue_left, model.target_hues, params.min_blob_px),
            target_blobs(hue_right, model.target_hues, params.min_blob_px))


def blob_pairs(hue_left: np.ndarray, hue_right: np.ndarray, model: PhotoModel, rig: Rig,
               params: EstimatorParams) -> list[BlobPair]:
    """The model's target-hue blobs of both hue images (`stereo_blobs`) paired along the epipolar
    lines (`match_blobs`)."""
    return match_blobs(*stereo_blobs(hue_left, hue_right, model, params), rig, params)


def near_groups(blobs: list[Blob], reach: float) -> list[list[Blob]]:
    """Blobs of ONE image that lie near each other: connected components of "the gap between two
    centroids is at most `reach` times the sum of their half-lengths", two or more members each."""
    near = np.array([[float(np.linalg.norm(a.centroid - b.centroid)) <= reach * (a.half_length + b.half_length)
                      for b in blobs] for a in blobs], dtype=bool).reshape(len(blobs), len(blobs))
    return [[blobs[k] for k in c] for c in components(near)]


def components(near: np.ndarray) -> list[list[int]]:
    """Connected components of two or more members of a symmetric "near" relation (n x n bool; n
    is a handful of blobs), in order of their first member."""
    n = len(near)
    label = list(range(n))
    for i in range(n):
        for j in range(n):
            if near[i, j] and label[j] != label[i]:
                old, new = max(label[i], label[j]), min(label[i], label[j])
                label = [new if x == old else x for x in label]
    return [[k for k in range(n) if label[k] == g] for g in sorted(set(label)) if label.count(g) > 1]


def split_pairs(left: list[Blob], right: list[Blob], pairs: list[BlobPair], rig: Rig,
                params: EstimatorParams) -> list[BlobPair]:
    """A creature in pieces in one image and not in the other (foam, a glint or a wave crest seen
    differently by the two cameras, or a gap one camera's blob merging closes): no piece matches
    a blob of the other image alone, so `match_blobs` pairs nothing and `group_pairs` has nothing
    to group. Here each image's groups of near pieces (`near_groups`, `group_reach`) of which no
    piece found a partner in `pairs` are taken together (`union`) and matched with the other
    image's single blobs. (Where a piece did pair, its island grows from it, and taking it with
    an unpaired neighbour - a glint-cut leg, a fleck of foam - only adds a worse-seeded island.)
    Largest first."""
    out = []
    for mine, other, flip in ((left, right, False), (right, left, True)):
        matched = [bp.right if flip else bp.left for bp in pairs]
        for group in near_groups(mine, params.group_reach):
            if any(any(b.area == m.area and np.array_equal(b.centroid, m.centroid) for m in matched) for b in group):
                continue  # a piece paired on its own: its island (and `group_pairs`) grow from it
            u = [union(group)]
            out += match_blobs(other, u, rig, params) if flip else match_blobs(u, other, rig, params)
    return sorted(out, key=lambda bp: -bp.left.area)


# two pieces of one image lie on either side of foam when at least this share of the pixels off the target's
# hues on the line between their centroids are foam (`parts.foam_marked`): across a band over the creature
# they are (renderer held-out 2: 0.53-1.00 off a foam band's pale, hued edge), across water none are (0.00)
FOAM_GAP_SHARE = 0.5


def foam_gap(a: Blob, b: Blob, marked: np.ndarray, target_hues: np.ndarray) -> bool:
    """Whether the gap between two blobs of one image is foam: of the pixels on the line between
    their centroids in `marked` (a hue image with foam marked `parts.FOAM`), those off the
    target's hues are foam in at least `FOAM_GAP_SHARE` (and some are: touching pieces are one blob)."""
    n = int(math.ceil(float(np.linalg.norm(b.centroid - a.centroid)))) + 1
    h, w = marked.shape
    xs = np.clip(np.rint(np.linspace(a.centroid[0], b.centroid[0], n)).astype(int), 0, w - 1)
    ys = np.clip(np.rint(np.linspace(a.centroid[1], b.centroid[1], n)).astype(int), 0, h - 1)
    line = marked[ys, xs]
    off = line[~target_hue_lut(target_hues)[line]]
    return bool(len(off)) and float(np.mean(off == FOAM)) >= FOAM_GAP_SHARE


def bridged_pairs(left: list[Blob], right: list[Blob], pairs: list[BlobPair], foam: StereoHue,
                  target_hues: np.ndarray, rig: Rig, params: EstimatorParams) -> list[BlobPair]:
    """A creature cut by a foam band whose pieces pair unevenly: the large piece pairs on its own,
    a piece across the band does not (the two images cut it differently: areas more than 2.5x
    apart, or the other image's pieces merged), so `group_pairs` has no second pair to group and
    `split_pairs` skips the group (a piece paired). Its island then takes scale and heading from
    the large piece alone: half a crab cut across its long side is long the other way, a quarter
    turn off (renderer held-out 2 1202, 1220, 1256). Here each image's near pieces (`group_reach`)
    whose gaps are foam (`foam_gap`; `foam`: the pair's hue frame with foam marked) form groups;
    a group of which some pieces paired on their own and some did not is taken together (`union`)
    and matched with what the other image holds whole: its own such groups taken together and
    its blobs in no group. Pieces near each other across water (two creatures, a creature beside
    a look-alike) are not joined. Pairs already in `pairs` or `group_pairs` are left out. Largest
    first."""
    def same(a: Blob, b: Blob) -> bool:
        return a.area == b.area and np.array_equal(a.centroid, b.centroid)

    def groups_of(blobs: list[Blob], marked: np.ndarray) -> list[list[Blob]]:
        n = len(blobs)
        near = np.zeros((n, n), bool)
        for i in range(n):
            for j in range(i + 1, n):
                a, b = blobs[i], blobs[j]
                near[i, j] = near[j, i] = (
                    float(np.linalg.norm(a.centroid - b.centroid)) <= params.group_reach * (a.half_length + b.half_length)
                    and foam_gap(a, b, marked, target_hues))
        return [[blobs[k] for k in c] for c in components(near)]

    sides = []
    for blobs, marked, paired in ((left, foam.left, [bp.left for bp in pairs]),
                                  (right, foam.right, [bp.right for bp in pairs])):
        groups = groups_of(blobs, marked)
        own = [[any(same(b, m) for m in paired) for b in g] for g in groups]
        uneven = [union(g) for g, o in zip(groups, own) if any(o) and not all(o)]
        whole = [union(g) for g in groups] + [b for b in blobs if not any(same(b, m) for g in groups for m in g)]
        sides.append((uneven, whole))
    (uneven_l, whole_l), (uneven_r, whole_r) = sides
    out = ((match_blobs(uneven_l, whole_r, rig, params) if uneven_l and whole_r else [])
           + (match_blobs(whole_l, uneven_r, rig, params) if whole_l and uneven_r else []))
    kept: list[BlobPair] = []
    known = pairs + group_pairs(pairs, params)
    for bp in out:
        if not any(same(bp.left, h.left) and same(bp.right, h.right) for h in known + kept):
            kept.append(bp)
    return sorted(kept, key=lambda bp: -bp.left.area)


def group_pairs(pairs: list[BlobPair], params: EstimatorParams) -> list[BlobPair]:
    """Stereo-consistent groups of nearby blob pairs, each as one pair of `union` blobs: the
    pieces of one creature that foam, a glint or a wave crest cut apart. Two pairs are near when
    their triangulated depths agree within `window_depth` and, in both images, the gap between
    their centroids is at most `group_reach` times the sum of their half-lengths. Groups of two
    or more (connected components of "near"), largest total area first; the position is the
    area-weighted mean of the members'."""
    n = len(pairs)
    near = np.eye(n, dtype=bool)
    for i in range(n):
        for j in range(i + 1, n):
            a, b = pairs[i], pairs[j]
            za, zb = float(a.position_mm[2]), float(b.position_mm[2])
            ok = abs(za - zb) <= params.window_depth * min(za, zb)
            for ba, bb in ((a.left, b.left), (a.right, b.right)):
                reach = params.group_reach * (ba.half_length + bb.half_length)
                ok &= float(np.linalg.norm(ba.centroid - bb.centroid)) <= reach
            near[i, j] = near[j, i] = ok
    groups = []
    for members in ([pairs[k] for k in c] for c in components(near)):
        w = np.array([m.left.area for m in members])
        pos = (w[:, None] * np.array([m.position_mm for m in members])).sum(axis=0) / w.sum()
        groups.append(BlobPair(position_mm=pos, left=union([m.left for m in members]),
                               right=union([m.right for m in members]),
                               residual_px=max(m.residual_px for m in members)))
    return sorted(groups, key=lambda gp: -gp.left.area)


@dataclass(frozen=True)
class ModelShape:
    """Area (photo px), centroid offset from the model origin (px) and principal axis of the
    photo-model's target mask — what a blob is compared with."""

    area: float
    centroid_uv: np.ndarray
    angle: float
    elongation: float

    @staticmethod
    def of(model: PhotoModel) -> ModelShape:
        b = _moments_shape(cv2.moments((np.asarray(model.mask) > 0).astype(np.uint8), binaryImage=True))
        return ModelShape(area=b.area, centroid_uv=b.centroid - np.asarray(model.origin_px), angle=b.angle,
                          elongation=b.elongation)


def seed_genes(pair: BlobPair, shape: ModelShape, space: GeneSpace, rng: np.random.Generator,
               n: int) -> tuple[np.ndarray, Region]:
    """Seed individuals (n, 7) and the island's window for one blob pair (image coding).

    Apparent scale s from the blob area (s^2 = area_blob / area_model; a tilt shrinks the blob,
    so the window reaches further up than down), headings psi from the difference of principal
    axes (two hypotheses, 180 deg apart; random when either shape is nearly round), origin = blob
    centroid minus the rotated, scaled centroid offset of the photo mask.

    The blob may be a piece of the creature (foam, a glint or a wave crest over the rest): the
    window reaches `window_grow` above the blob's ln s, and wide enough in (u, v) for a model that
    large to hold the piece anywhere inside it; a third of the seeds are such grown models, each
    placed with the piece at a random point of its photo mask."""
    p = space.params
    full = space.full_region()
    K = space.rig.left.K
    X = pair.position_mm
    z = float(X[2])
    s0 = math.sqrt(pair.left.area / shape.area)
    ls0 = math.log(s0)
    q0 = 1000.0 / z
    if pair.left.elongation > 1.25 and shape.elongation > 1.25:
        base = pair.left.angle - shape.angle
        psis = np.array([base, base + math.pi])
    else:
        psis = rng.uniform(-math.pi, math.pi, 2)
    cu = K[0, 0] * X[0] / z + K[0, 2]
    cv = K[1, 1] * X[1] / z + K[1, 2]
    r_img = math.sqrt(pair.left.area / math.pi)
    ls_hi = ls0 + max(p.window_scale, p.window_grow)
    half_uv = max(4.0 + 0.35 * r_img + s0 * np.abs(shape.centroid_uv).max(),
                  0.5 * math.exp(ls_hi) * max(space.model.size_px))
    lo = np.array([cu - half_uv, cv - half_uv, q0 * (1 - p.window_depth), 0, 0, 0, ls0 - 0.5 * p.window_scale])
    hi = np.array([cu + half_uv, cv + half_uv, q0 * (1 + p.window_depth), 0, 0, 0, ls_hi])
    lo[3:6], hi[3:6] = full.lo[3:6], full.hi[3:6]
    lo = np.maximum(lo, full.lo)
    hi = np.minimum(hi, full.hi)
    hi = np.maximum(hi, lo + 1e-6)
    region = Region.box(lo, hi, full.periodic)
    seeds = region.sample(rng, n)
    k = np.arange(n)
    psi = psis[k % 2] + rng.normal(0, 0.15, n)
    off = np.stack([np.cos(psi) * shape.centroid_uv[0] - np.sin(psi) * shape.centroid_uv[1],
                    np.sin(psi) * shape.centroid_uv[0] + np.cos(psi) * shape.centroid_uv[1]], 1) * s0
    seeds[:, 0] = cu - off[:, 0] + rng.normal(0, 1.0, n)
    seeds[:, 1] = cv - off[:, 1] + rng.normal(0, 1.0, n)
    seeds[:, 2] = q0 * (1 + rng.normal(0, 0.02, n))
    seeds[:, 3] = psi
    tilt = rng.uniform(0, 1, n) ** 0.5 * math.radians(min(p.tilt_max_deg, 35.0))
    phi = rng.uniform(-math.pi, math.pi, n)
    tilt[: max(1, n // 4)] = 0.0
    seeds[:, 4], seeds[:, 5] = tilt * np.cos(phi), tilt * np.sin(phi)
    # the blob may be a fragment of the creature (foam, glints): scales up to x1.5 are as likely
    seeds[:, 6] = ls0 + rng.uniform(-0.1, 0.4, n)
    if p.window_grow > 0:  # a third grown from the piece
        g = k[k % 3 == 2]
        seeds[g] = _grown(seeds[g], space.model, (cu, cv), ls0 + rng.uniform(0.2, p.window_grow, len(g)), rng)
    return region.repair(seeds), region


def _grown(seeds: np.ndarray, model: PhotoModel, piece_uv: tuple[float, float], ls: np.ndarray,
           rng: np.random.Generator) -> np.ndarray:
    """Seeds (image coding, headings as given) made into larger models (ln s = `ls`) that hold
    the piece's centroid `piece_uv` (left image px) at a random point of the photo's mask."""
    seeds = seeds.copy()
    ys, xs = np.nonzero(model.mask)
    pick = rng.integers(len(xs), size=len(seeds))
    at = np.column_stack([xs[pick], ys[pick]]) - np.asarray(model.origin_px)  # photo px from the origin
    c, s = np.cos(seeds[:, 3]), np.sin(seeds[:, 3])
    e = np.exp(ls)
    seeds[:, 0] = piece_uv[0] - e * (c * at[:, 0] - s * at[:, 1])
    seeds[:, 1] = piece_uv[1] - e * (s * at[:, 0] + c * at[:, 1])
    seeds[:, 6] = ls
    return seeds

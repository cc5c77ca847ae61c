"""A shape cue for smooth, low-texture marks (arches, roundels, script on a plain ground), where keypoints find no
consistent fit: the silhouette of a mark's main colour region.

* :func:`shape_template`: a reference's largest region of its dominant saturated hue (one of :data:`HUE_BINS` bins,
  with its two neighbours), cut to its bounding box and resized to :data:`SIDE` x :data:`SIDE`.
* :func:`scene_regions`: every connected region of every hue bin of a scene, normalised the same way.
* :func:`shape_scores`: the intersection over union of each template with the best region of its hue whose aspect
  ratio is within :data:`ASPECT_TOLERANCE` of its own (a normalised silhouette ignores scale and position, not
  rotation: marks are photographed upright far more often than not).
* :func:`calibrate_shapes`: a template's threshold is the best score it reaches on photos without its brand (its
  chance level on this gallery); it is kept only when its silhouette is not a plain blob (at most
  :data:`MAX_FILL` of its box: a filled rectangle or disc matches any sign) and when it finds its own brand on
  another photo by more than :data:`MARGIN` above that threshold.
* :func:`decide_shape`: the brand whose kept template clears its threshold by the largest margin, above
  :data:`MARGIN`.

The settings were chosen on the leave-one-photo-out protocol of the logo benchmark (docs/notes/logo.md).
Functions take arrays and never touch the disk.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

#: side of a normalised silhouette, pixels
SIDE = 48
#: hue bins of OpenCV's 0-180 hue; a template's hue is its bin and the two next to it (60 degrees in all)
HUE_BINS = 18
#: a pixel is chromatic when its HSV saturation and value reach these (0-255)
MIN_SATURATION, MIN_VALUE = 80, 70
#: a reference with fewer chromatic pixels than this share of its box gives no template (black or grey marks)
MIN_CHROMATIC = 0.15
#: a template's region must cover at least this share of the reference's box
MIN_TEMPLATE_SHARE = 0.05
#: scene regions smaller than this many pixels, or narrower than MIN_REGION_SIDE, are not compared
MIN_REGION_PIXELS, MIN_REGION_SIDE = 60, 10
#: a region's aspect ratio (width / height) must be within this factor of the template's
ASPECT_TOLERANCE = 1.6
#: a template whose silhouette fills more of its box than this is not kept (plain blobs match any sign)
MAX_FILL = 0.5
#: how far a score must clear the template's chance level, in intersection over union
MARGIN = 0.1


@dataclass(frozen=True)
class ShapeTemplate:
    """A mark's silhouette: ``brand``, ``name`` (the reference's), ``source`` (the photo it was cut from, or None:
    a photo that must not calibrate or test it), its hue bin, the (SIDE, SIDE) bool ``mask`` and the aspect ratio
    (width / height) of its box."""

    brand: str
    name: str
    source: str | None
    hue_bin: int
    mask: np.ndarray
    aspect: float

    @property
    def fill(self) -> float:
        """Share of its box that the silhouette covers."""
        return float(self.mask.mean())


#: a scene's regions: hue bin -> list of (normalised (SIDE, SIDE) bool mask, aspect ratio, (x, y, w, h) box)
Regions = dict[int, list[tuple[np.ndarray, float, tuple[int, int, int, int]]]]


def _hue_bins(bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Chromatic pixels (bool) and every pixel's hue bin."""
    if bgr.ndim != 3 or bgr.shape[2] != 3:
        raise ValueError(f"`image` must be a (H, W, 3) BGR colour image, got shape {bgr.shape}")
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    chromatic = (hsv[..., 1] >= MIN_SATURATION) & (hsv[..., 2] >= MIN_VALUE)
    return chromatic, (hsv[..., 0].astype(np.int32) * HUE_BINS // 180) % HUE_BINS


def _in_hue(chromatic: np.ndarray, bins: np.ndarray, b: int) -> np.ndarray:
    return chromatic & ((bins == b) | (bins == (b - 1) % HUE_BINS) | (bins == (b + 1) % HUE_BINS))


def _normalised(region: np.ndarray) -> np.ndarray:
    return cv2.resize(region.astype(np.uint8) * 255, (SIDE, SIDE), interpolation=cv2.INTER_AREA) > 127


def shape_template(bgr: np.ndarray, brand: str, name: str, box: tuple[int, int, int, int] | None = None,
                   source: str | None = None) -> ShapeTemplate | None:
    """The silhouette of the main colour region of ``bgr`` inside ``box`` (``x0, y0, x1, y1``, inclusive; None: the
    whole image), or None when the mark has too few chromatic pixels or no region large enough.

    Examples
    --------
    >>> img = np.full((60, 80, 3), 255, np.uint8)
    >>> _ = cv2.rectangle(img, (10, 10), (20, 50), (0, 200, 255), -1)  # an orange "L"
    >>> _ = cv2.rectangle(img, (10, 40), (60, 50), (0, 200, 255), -1)
    >>> t = shape_template(img, "L", "l.png")
    >>> float(round(t.aspect, 2)), 0.3 < t.fill < 0.5
    (1.24, True)
    """
    if box is not None:
        x0, y0, x1, y1 = box
        bgr = bgr[y0:y1 + 1, x0:x1 + 1]
    chromatic, bins = _hue_bins(bgr)
    if chromatic.mean() < MIN_CHROMATIC:
        return None
    hist = np.bincount(bins[chromatic], minlength=HUE_BINS)
    b = int(np.argmax(hist + np.roll(hist, 1) + np.roll(hist, -1)))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(_in_hue(chromatic, bins, b).astype(np.uint8))
    if n < 2:
        return None
    k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    x, y, w, h, area = stats[k]
    if area < MIN_TEMPLATE_SHARE * chromatic.size:
        return None
    return ShapeTemplate(brand, name, source, b, _normalised(labels[y:y + h, x:x + w] == k), w / h)


def scene_regions(bgr: np.ndarray, hue_bins: Sequence[int] | None = None) -> Regions:
    """The connected regions of each hue bin in ``hue_bins`` (default: all) of a scene, after a 3 x 3 closing that
    joins regions split by a line of noise."""
    chromatic, bins = _hue_bins(bgr)
    kernel = np.ones((3, 3), np.uint8)
    out: Regions = {}
    for b in range(HUE_BINS) if hue_bins is None else sorted(set(hue_bins)):
        m = cv2.morphologyEx(_in_hue(chromatic, bins, b).astype(np.uint8), cv2.MORPH_CLOSE, kernel)
        n, labels, stats, _ = cv2.connectedComponentsWithStats(m)
        found = []
        for c in range(1, n):
            x, y, w, h, area = (int(v) for v in stats[c])
            if area >= MIN_REGION_PIXELS and min(w, h) >= MIN_REGION_SIDE:
                found.append((_normalised(labels[y:y + h, x:x + w] == c), w / h, (x, y, w, h)))
        out[b] = found
    return out


def shape_score(t: ShapeTemplate, regions: Regions) -> tuple[float, tuple[int, int, int, int] | None]:
    """The best intersection over union of ``t`` with a region of its hue and a close aspect ratio, and that
    region's box (0 and None when there is none)."""
    best, where = 0.0, None
    for mask, aspect, box in regions.get(t.hue_bin, ()):
        if not t.aspect / ASPECT_TOLERANCE <= aspect <= t.aspect * ASPECT_TOLERANCE:
            continue
        iou = float((mask & t.mask).sum()) / max(int((mask | t.mask).sum()), 1)
        if iou > best:
            best, where = iou, box
    return best, where


def shape_scores(templates: Sequence[ShapeTemplate], regions: Sequence[Regions]) -> np.ndarray:
    """(templates, scenes) matrix of :func:`shape_score`."""
    return np.array([[shape_score(t, r)[0] for r in regions] for t in templates]).reshape(len(templates),
                                                                                           len(regions))


def calibrate_shapes(templates: Sequence[ShapeTemplate], scores: np.ndarray, photos: Sequence[str],
                     brands: Sequence[set[str]], margin: float = MARGIN) -> np.ndarray:
    """Each template's threshold, NaN for a template not kept.

    Parameters
    ----------
    templates : sequence of ShapeTemplate
    scores : (T, P) array
        :func:`shape_scores` of the templates on the calibration photos.
    photos : sequence of str
        The calibration photos' names (a template is neither calibrated nor confirmed on its own ``source``).
    brands : sequence of set of str
        The brands each calibration photo shows.
    margin : float
        How far above its chance level a template must find its brand on another photo to be kept.

    Returns
    -------
    (T,) float64
        The best score of the template on the photos without its brand (0 when there are none); NaN when the
        template fills more than :data:`MAX_FILL` of its box or finds no other photo of its brand above that plus
        ``margin``.
    """
    scores = np.asarray(scores, float)
    if scores.shape != (len(templates), len(photos)) or len(brands) != len(photos):
        raise ValueError(f"`scores` must be (templates, photos) = ({len(templates)}, {len(photos)}) with one brand "
                         f"set per photo, got {scores.shape} and {len(brands)}")
    out = np.full(len(templates), np.nan)
    for i, t in enumerate(templates):
        if t.fill > MAX_FILL:
            continue
        others = [j for j, (p, b) in enumerate(zip(photos, brands)) if p != t.source and t.brand not in b]
        own = [j for j, (p, b) in enumerate(zip(photos, brands)) if p != t.source and t.brand in b]
        chance = float(scores[i, others].max()) if others else 0.0
        if own and scores[i, own].max() > chance + margin:
            out[i] = chance
    return out


def kept_shapes(templates: Sequence[ShapeTemplate], thresholds: np.ndarray) -> tuple[list[ShapeTemplate], np.ndarray]:
    """The templates that :func:`calibrate_shapes` kept (their threshold is not NaN) and their thresholds."""
    thresholds = np.asarray(thresholds, float)
    if len(thresholds) != len(templates):
        raise ValueError(f"`thresholds` must hold one value per template ({len(templates)}), got {len(thresholds)}")
    kept = np.flatnonzero(~np.isnan(thresholds))
    return [templates[i] for i in kept], thresholds[kept]


def decide_shape(templates: Sequence[ShapeTemplate], thresholds: np.ndarray, scene_scores: np.ndarray,
                 margin: float = MARGIN) -> tuple[str, float, int] | None:
    """The brand of the kept template that clears its threshold by the largest margin above ``margin``, that
    margin and the template's index; None when no template does."""
    clear = np.asarray(scene_scores, float) - np.asarray(thresholds, float)
    clear[np.isnan(clear)] = -np.inf
    if len(clear) == 0 or clear.max() <= margin:
        return None
    i = int(np.argmax(clear))
    return templates[i].brand, float(clear[i]), i

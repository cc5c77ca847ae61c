"""The bundled sample data set, built offline and deterministically with its ground truth.

Material comes from pip packages only: scikit-image's bundled photos (including the Middlebury "motorcycle" stereo
pair with true disparity) and the CC0 brand marks of simple-icons, rendered with resvg. Every generator is a pure
function of a seed that returns images and truth in memory; ``stages/samples.py`` writes them to disk.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from .errors import require_extra
from .params import SamplesParams, section_or_default

#: the ``samples`` defaults: the one declaration of :func:`make_logo`'s scene counts
_SAMPLES = SamplesParams()

#: gallery brands (simple-icons slugs, CC0 marks with enough shape detail for local features)
LOGO_BRANDS = ("starbucks", "raspberrypi", "linux", "redbull", "ferrari",
               "porsche", "lamborghini", "cocacola", "unilever", "docker")
#: marks pasted into the no-logo scenes as distractors: they are not in the gallery, so the answer stays "none"
LOGO_DISTRACTORS = ("nasa", "bmw", "opencv", "reddit")
#: scikit-image photos usable as backgrounds (all ship inside the wheel, no download)
PHOTOS = ("astronaut", "coffee", "chelsea", "rocket", "hubble_deep_field", "immunohistochemistry",
          "retina", "motorcycle", "brick", "gravel", "coins", "clock", "camera", "moon")


@dataclass
class SampleSet:
    """Images (name -> array, written as files) and the truth document of one task."""

    images: dict[str, np.ndarray] = field(default_factory=dict)
    truth: dict[str, Any] = field(default_factory=dict)  # the task folder's truth.json (none when empty)
    arrays: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    texts: dict[str, str] = field(default_factory=dict)  # further text files by relative path (e.g. calib.txt)
    docs: dict[str, Any] = field(default_factory=dict)  # further JSON files by relative path (per-item truth.json)


# ----------------------------------------------------------------------------------------------------- helpers


def photo(name: str) -> np.ndarray:
    """A scikit-image photo as BGR uint8."""
    skimage_data = require_extra("skimage.data", "samples", "the bundled samples")

    if name == "motorcycle":
        img = skimage_data.stereo_motorcycle()[0]
    else:
        img = getattr(skimage_data, name)()
    img = np.asarray(img)
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    return np.ascontiguousarray(img[..., 2::-1])


def fit(img: np.ndarray, width: int, height: int, rng: np.random.Generator | None = None) -> np.ndarray:
    """Scale ``img`` to cover width x height and crop (centred, or at a random offset when ``rng`` is given)."""
    h, w = img.shape[:2]
    s = max(width / w, height / h)
    r = cv2.resize(img, (max(width, round(w * s)), max(height, round(h * s))), interpolation=cv2.INTER_AREA)
    dy, dx = r.shape[0] - height, r.shape[1] - width
    oy = int(rng.integers(0, dy + 1)) if rng is not None else dy // 2
    ox = int(rng.integers(0, dx + 1)) if rng is not None else dx // 2
    return np.ascontiguousarray(r[oy:oy + height, ox:ox + width])


def render_mark(slug: str, size: int = 256, pad: float = 0.1) -> np.ndarray:
    """A simple-icons brand mark in its brand colour on a white square card, BGR uint8 (size x size)."""
    resvg_py = require_extra("resvg_py", "samples", "the bundled samples' brand marks")
    simple_icons_pack = require_extra("simple_icons_pack", "samples", "the bundled samples' brand marks")

    icon = simple_icons_pack.get_icon(slug)
    if icon is None:
        raise ValueError(f"simple-icons has no mark named {slug!r}")
    inner = int(round(size * (1 - 2 * pad)))
    svg = icon.svg.replace("<svg ", f'<svg fill="#{icon.hex}" ', 1)
    png = resvg_py.svg_to_bytes(svg_string=svg, width=inner, height=inner, background="#ffffff")
    mark = cv2.imdecode(np.frombuffer(bytes(png), np.uint8), cv2.IMREAD_COLOR)
    card = np.full((size, size, 3), 255, np.uint8)
    o = (size - mark.shape[0]) // 2
    card[o:o + mark.shape[0], o:o + mark.shape[1]] = mark
    return card


def apply_homography(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Map (N, 2) points by a 3x3 homography."""
    p = np.c_[np.asarray(pts, np.float64), np.ones(len(pts))] @ np.asarray(H, np.float64).T
    return p[:, :2] / p[:, 2:3]


def corners(width: int, height: int) -> np.ndarray:
    """The four corner pixel centres of a width x height image, clockwise from the top-left."""
    return np.array([[0, 0], [width - 1, 0], [width - 1, height - 1], [0, height - 1]], np.float64)


def degrade(img: np.ndarray, rng: np.random.Generator, gain=(0.8, 1.15), bias=(-15, 15),
            blur=(0.0, 1.0), noise=(1.5, 4.0), jpeg: tuple[int, int] | None = (60, 92)) -> np.ndarray:
    """Lighting (gain, bias, a linear gradient), blur, Gaussian noise and JPEG loss, all drawn from ``rng``."""
    h, w = img.shape[:2]
    out = img.astype(np.float32)
    gx, gy = rng.uniform(-0.15, 0.15, 2)
    ramp = 1 + gx * (np.arange(w)[None, :] / w - 0.5) + gy * (np.arange(h)[:, None] / h - 0.5)
    out = out * (rng.uniform(*gain) * ramp)[..., None] + rng.uniform(*bias)
    sigma = rng.uniform(*blur)
    if sigma > 0.3:
        out = cv2.GaussianBlur(out, (0, 0), sigma)
    out += rng.normal(0, rng.uniform(*noise), out.shape)
    out = np.clip(out, 0, 255).astype(np.uint8)
    if jpeg is not None:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(*jpeg))])
        out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    return out


def paste(scene: np.ndarray, patch: np.ndarray, H: np.ndarray) -> np.ndarray:
    """Warp ``patch`` by ``H`` (patch -> scene pixels) and blend it over ``scene`` with anti-aliased edges."""
    h, w = scene.shape[:2]
    warped = cv2.warpPerspective(patch, H, (w, h), flags=cv2.INTER_LINEAR)
    alpha = cv2.warpPerspective(np.ones(patch.shape[:2], np.float32), H, (w, h), flags=cv2.INTER_LINEAR)
    a = alpha[..., None]
    return (scene * (1 - a) + warped * a).astype(np.uint8)


def random_view(rng: np.random.Generator, size: float, center: tuple[float, float], scale: float,
                max_rot_deg: float, persp: float) -> np.ndarray:
    """Homography mapping a size x size square onto a perspective quad of side ~``scale * size`` at ``center``."""
    src = corners(int(size) + 1, int(size) + 1).astype(np.float32)
    c = src.mean(0)
    t = np.deg2rad(rng.uniform(-max_rot_deg, max_rot_deg))
    R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    dst = (src - c) @ R.T * scale + np.asarray(center)
    dst += rng.uniform(-persp, persp, dst.shape) * scale * size
    return cv2.getPerspectiveTransform(src, dst.astype(np.float32)).astype(np.float64)


# ----------------------------------------------------------------------------------------------------- tasks


def make_logo(rng: np.random.Generator, n_scenes: int = _SAMPLES.logo_scenes,
              n_negatives: int = _SAMPLES.logo_negatives, width: int = 640, height: int = 480) -> SampleSet:
    """A 10-brand gallery and scenes with one mark each (known quad) plus scenes with no gallery mark."""
    out = SampleSet()
    gallery = {b: render_mark(b) for b in LOGO_BRANDS}
    for b, img in gallery.items():
        out.images[f"gallery/{b}.png"] = img
    scenes = []
    for i in range(n_scenes + n_negatives):
        bg = fit(photo(PHOTOS[int(rng.integers(len(PHOTOS)))]), width, height, rng)
        negative = i >= n_scenes
        brand = None if negative else LOGO_BRANDS[i % len(LOGO_BRANDS)]
        quad = None
        if not negative or rng.random() < 0.7:
            card = gallery[brand] if brand else render_mark(LOGO_DISTRACTORS[i % len(LOGO_DISTRACTORS)])
            side = rng.uniform(100, 220)
            cx, cy = rng.uniform(side * 0.8, width - side * 0.8), rng.uniform(side * 0.8, height - side * 0.8)
            H = random_view(rng, card.shape[1] - 1, (cx, cy), side / card.shape[1], 30, 0.08)
            bg = paste(bg, card, H)
            if brand:
                quad = apply_homography(H, corners(card.shape[1], card.shape[0])).round(2).tolist()
        name = f"scene_{i:02d}.jpg"
        out.images[f"scenes/{name}"] = degrade(bg, rng)
        scenes.append({"file": name, "brand": brand, "quad": quad})
    out.truth = {"brands": list(LOGO_BRANDS), "quad_convention": "gallery corner pixel centres mapped into the scene",
                 "scenes": scenes}
    return out


def _draw_line(img: np.ndarray, rho: float, theta: float, color, thickness: int) -> None:
    c, s = np.cos(theta), np.sin(theta)
    x0, y0, n = rho * c, rho * s, 4 * max(img.shape)
    p1 = (int(round(x0 - n * s)), int(round(y0 + n * c)))
    p2 = (int(round(x0 + n * s)), int(round(y0 - n * c)))
    cv2.line(img, p1, p2, color, thickness, cv2.LINE_8)


def make_hough(rng: np.random.Generator) -> SampleSet:
    """Line images with known (rho, theta): two synthetic drawings and two real photos with painted lines."""
    out = SampleSet()
    items = []
    specs = {
        "synthetic_grid.png": (np.zeros((240, 320, 3), np.uint8),
                               [(40.0, 0.0), (250.0, 0.0), (60.0, np.pi / 2), (180.0, np.pi / 2),
                                (-60.0, 3 * np.pi / 4), (200.0, np.pi / 4)], 1),
        "synthetic_star.png": (np.zeros((300, 300, 3), np.uint8),
                               [(150.0 * np.cos(t) + 150.0 * np.sin(t), t) for t in np.deg2rad([10, 55, 100, 145])]
                               + [(-40.0, np.deg2rad(120))], 1),
        "camera_lines.png": (photo("camera"), [(100.0, np.deg2rad(20)), (400.0, np.deg2rad(90)),
                                                (-120.0, np.deg2rad(135)), (300.0, 0.0)], 2),
        "coffee_lines.png": (fit(photo("coffee"), 480, 360), [(90.0, np.deg2rad(60)), (330.0, np.deg2rad(5)),
                                                               (-80.0, np.deg2rad(160))], 2),
    }
    for name, (img, lines, thick) in specs.items():
        img = img.copy()
        for rho, theta in lines:
            _draw_line(img, rho, theta, (255, 255, 255), thick)
        out.images[name] = img
        items.append({"file": name, "lines": [[round(float(r), 4), round(float(t), 6)] for r, t in lines]})
    out.truth = {"images": items, "convention": "cv2.HoughLines: x*cos(theta) + y*sin(theta) = rho"}
    return out


def _pcb(rng: np.random.Generator, size: int = 480) -> np.ndarray:
    """A synthetic circuit board: traces with 45-degree bends, pads, vias and silkscreen text on textured green."""
    board = np.empty((size, size, 3), np.uint8)
    board[:] = (40, 90, 30)
    tex = cv2.GaussianBlur(rng.normal(0, 8, (size, size)).astype(np.float32), (0, 0), 2)
    board = np.clip(board + tex[..., None], 0, 255).astype(np.uint8)
    copper = (60, 150, 200)
    for _ in range(26):
        p = rng.uniform(30, size - 30, 2)
        pts = [p.copy()]
        for _ in range(int(rng.integers(2, 5))):
            d = [(1, 0), (0, 1), (1, 1), (1, -1), (-1, 0), (0, -1)][int(rng.integers(6))]
            p = np.clip(p + np.array(d) * rng.uniform(30, 110), 20, size - 20)
            pts.append(p.copy())
        cv2.polylines(board, [np.array(pts, np.int32)], False, copper, int(rng.integers(3, 8)), cv2.LINE_AA)
        for q in (pts[0], pts[-1]):
            cv2.circle(board, tuple(int(v) for v in q), int(rng.integers(6, 11)), copper, -1, cv2.LINE_AA)
            cv2.circle(board, tuple(int(v) for v in q), 3, (20, 30, 20), -1, cv2.LINE_AA)
    for _ in range(10):
        x, y = rng.integers(20, size - 60, 2)
        cv2.rectangle(board, (int(x), int(y)), (int(x) + 22, int(y) + 14), copper, -1)
    for i in range(5):
        x, y = rng.integers(10, size - 120, 2)
        cv2.putText(board, f"U{i + 1} R{int(rng.integers(10, 99))}", (int(x), int(y)), cv2.FONT_HERSHEY_SIMPLEX,
                    0.5, (230, 230, 230), 1, cv2.LINE_AA)
    return board


def _small_motion(rng: np.random.Generator, size: int) -> np.ndarray:
    """A small random homography about the image centre: rotation <= 3 deg, scale +-3 %, shift <= 10 px."""
    c = size / 2
    t, s = np.deg2rad(rng.uniform(-3, 3)), rng.uniform(0.97, 1.03)
    A = np.array([[s * np.cos(t), -s * np.sin(t), 0], [s * np.sin(t), s * np.cos(t), 0], [0, 0, 1]])
    A[2, :2] = rng.uniform(-2e-5, 2e-5, 2)
    T = np.array([[1, 0, c + rng.uniform(-10, 10)], [0, 1, c + rng.uniform(-10, 10)], [0, 0, 1]])
    C = np.array([[1, 0, -c], [0, 1, -c], [0, 0, 1]])
    H = T @ A @ C
    return H / H[2, 2]


def _insert_defect(img: np.ndarray, kind: str, rng: np.random.Generator) -> list[float]:
    """Draw one defect into ``img`` (reference frame) and return its box [x1, y1, x2, y2]."""
    size = img.shape[0]
    x, y = rng.uniform(80, size - 80, 2)
    if kind == "scratch":
        a = rng.uniform(0, np.pi)
        L = rng.uniform(25, 50)
        p1 = (x - L * np.cos(a), y - L * np.sin(a))
        p2 = (x + L * np.cos(a), y + L * np.sin(a))
        cv2.line(img, tuple(int(v) for v in p1), tuple(int(v) for v in p2), (200, 200, 190), 2, cv2.LINE_AA)
        xs, ys = (p1[0], p2[0]), (p1[1], p2[1])
        return [min(xs) - 2, min(ys) - 2, max(xs) + 2, max(ys) + 2]
    if kind == "blob":
        ax, ay = rng.uniform(5, 11, 2)
        cv2.ellipse(img, (int(x), int(y)), (int(ax), int(ay)), float(rng.uniform(0, 180)), 0, 360,
                    (25, 25, 35), -1, cv2.LINE_AA)
        return [x - ax - 1, y - ax - 1, x + ax + 1, y + ay + 1] if ax > ay else [x - ay - 1, y - ay - 1,
                                                                                  x + ay + 1, y + ay + 1]
    # missing material: copper in a small square is etched away (painted with the bare-board colour)
    w, h = rng.uniform(12, 22, 2)
    region = img[int(y - h / 2):int(y + h / 2), int(x - w / 2):int(x + w / 2)]
    copper = (region[..., 2].astype(int) > 150)
    region[copper] = (40, 90, 30)
    return [x - w / 2, y - h / 2, x + w / 2, y + h / 2]


def _defect_visible(before: np.ndarray, after: np.ndarray, box: list[float]) -> bool:
    x1, y1, x2, y2 = (int(v) for v in box)
    diff = np.abs(before[y1:y2, x1:x2].astype(int) - after[y1:y2, x1:x2].astype(int)).max(axis=2)
    return int((diff > 40).sum()) >= 20


def make_defect(rng: np.random.Generator, n_faulty: int = 8, n_perfect: int = 6, size: int = 480) -> SampleSet:
    """A golden reference board and probes: faulty ones with inserted defects, perfect ones only moved/relit."""
    out = SampleSet()
    ref = _pcb(rng, size)
    out.images["reference.png"] = ref
    probes = []
    kinds = ("scratch", "blob", "missing")
    for i in range(n_faulty + n_perfect):
        faulty = i < n_faulty
        part, boxes = ref.copy(), []
        if faulty:
            for k in range(1 + int(i % 3 == 2)):
                for _ in range(50):  # retry until the defect really changes pixels (missing copper needs copper)
                    trial = part.copy()
                    box = _insert_defect(trial, kinds[(i + k) % 3], rng)
                    if _defect_visible(part, trial, box):
                        part, boxes = trial, boxes + [box]
                        break
        H = _small_motion(rng, size)
        warped = cv2.warpPerspective(part, H, (size, size), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        probe = degrade(warped, rng, gain=(0.85, 1.15), bias=(-12, 12), blur=(0.0, 0.8), noise=(1.5, 3.0), jpeg=None)
        probe_boxes = []
        for b in boxes:
            q = apply_homography(H, np.array([[b[0], b[1]], [b[2], b[1]], [b[2], b[3]], [b[0], b[3]]]))
            probe_boxes.append([round(float(v), 2) for v in (*q.min(0), *q.max(0))])
        name = f"probe_{i:02d}.png"
        out.images[f"probes/{name}"] = probe
        probes.append({"file": name, "verdict": "faulty" if faulty else "perfect", "boxes": probe_boxes,
                       "reference_boxes": [[round(float(v), 2) for v in b] for b in boxes], "H": H.tolist()})
    out.truth = {"probes": probes}
    return out


def make_homography(rng: np.random.Generator, width: int = 640, height: int = 480) -> SampleSet:
    """Pairs of views of real photos related by known homographies (A -> B), B relit, noisy and JPEG-compressed."""
    out = SampleSet()
    pairs = []
    for k, name in enumerate(("astronaut", "coffee", "chelsea", "rocket", "motorcycle", "immunohistochemistry",
                              "hubble_deep_field")):
        base = fit(photo(name), int(width * 1.3), int(height * 1.3))
        bh, bw = base.shape[:2]
        c = np.array([bw / 2, bh / 2])

        def view(max_rot, scale_rng, persp):
            t, s = np.deg2rad(rng.uniform(-max_rot, max_rot)), rng.uniform(*scale_rng)
            A = np.array([[s * np.cos(t), -s * np.sin(t), 0], [s * np.sin(t), s * np.cos(t), 0], [0, 0, 1]])
            A[2, :2] = rng.uniform(-persp, persp, 2)
            T = np.array([[1, 0, width / 2 + rng.uniform(-30, 30)], [0, 1, height / 2 + rng.uniform(-30, 30)],
                          [0, 0, 1]])
            C = np.array([[1, 0, -c[0]], [0, 1, -c[1]], [0, 0, 1]])
            return T @ A @ C

        Ha, Hb = view(5, (0.9, 1.0), 5e-5), view(30, (0.65, 1.25), 4e-4)
        A = cv2.warpPerspective(base, Ha, (width, height), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        B = cv2.warpPerspective(base, Hb, (width, height), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        H = Hb @ np.linalg.inv(Ha)
        H /= H[2, 2]
        pname = f"{k}_{name}"
        out.images[f"{pname}_a.jpg"] = degrade(A, rng, gain=(0.95, 1.05), bias=(-5, 5), blur=(0, 0.3),
                                               noise=(1, 2), jpeg=(90, 96))
        out.images[f"{pname}_b.jpg"] = degrade(B, rng)
        pairs.append({"name": pname, "a": f"{pname}_a.jpg", "b": f"{pname}_b.jpg", "H": H.tolist(),
                      "size_a": [width, height]})
    out.truth = {"pairs": pairs, "direction": "H maps A pixels to B pixels"}
    return out


def make_stereo() -> SampleSet:
    """The Middlebury motorcycle pair bundled with scikit-image, with its true disparity (NaN = unknown)."""
    skimage_data = require_extra("skimage.data", "samples", "the bundled samples")

    left, right, disp = skimage_data.stereo_motorcycle()
    disp = np.where(np.isfinite(disp), disp, np.nan).astype(np.float32)
    out = SampleSet()
    out.images["left.png"] = np.ascontiguousarray(left[..., ::-1])
    out.images["right.png"] = np.ascontiguousarray(right[..., ::-1])
    max_disp = int(np.ceil((np.nanmax(disp) + 1) / 16) * 16)
    out.arrays["truth.npz"] = {"disparity": disp}
    out.truth = {"max_disp": max_disp, "source": "Middlebury 2014 motorcycle via scikit-image"}
    return out


#: Middlebury calibration of scikit-image's (quarter-size, 741x500) motorcycle pair, from its docstring: focal
#: length, left principal point, doffs (principal column of the right minus the left), baseline in mm
MOTORCYCLE_CALIB = {"focal": 994.978, "cx": 311.193, "cy": 254.877, "doffs": 31.086, "baseline": 193.001}


def make_stereo_unrectified(rng: np.random.Generator, name: str = "motorcycle_unrectified",
                            max_rotation_deg: float = 2.0, max_shift: float = 6.0,
                            max_scale: float = 0.015) -> tuple[SampleSet, dict[str, str]]:
    """An unrectified pair with its calibration: the motorcycle pair with the right view turned and shifted.

    The right camera is rotated about its x (pitch) and z (roll) axes through its principal point (uniform in
    +-``max_rotation_deg``), its image scaled about the principal point (1 +- ``max_scale``) and shifted
    vertically (+-``max_shift`` px). There is no rotation about the vertical axis, so that the right principal
    column, and with it the calibration's ``doffs``, still hold after rectification: the Middlebury ``calib.txt``
    of the original rig then gives metric depth.

    Parameters
    ----------
    rng : numpy.random.Generator
        Draws the transform.
    name : str
        Folder of the pair inside the stereo sample folder.

    Returns
    -------
    SampleSet
        ``images``: ``<name>/left.png`` (the original left view), ``<name>/right.png`` (the transformed right
        view); ``arrays``: ``<name>/truth.npz`` with ``disparity`` (float32, the ORIGINAL pair's true disparity of
        the left image, NaN = unknown) and ``H_unrectify`` (3x3, original right pixels -> ``right.png`` pixels);
        ``truth``: ``{name: {"max_disp", "H_unrectify", "rotation_deg", "scale", "shift_y_px", "calib"}}``.
    texts : dict
        ``{"<name>/calib.txt": Middlebury calib.txt text}`` of the original rig at the sample's size.
    """
    skimage_data = require_extra("skimage.data", "samples", "the bundled samples")

    left, right, disp = skimage_data.stereo_motorcycle()
    disp = np.where(np.isfinite(disp), disp, np.nan).astype(np.float32)
    h, w = left.shape[:2]
    c = MOTORCYCLE_CALIB
    f, cx1, cy = c["focal"], c["cx"] + c["doffs"], c["cy"]
    K = np.array([[f, 0.0, cx1], [0.0, f, cy], [0.0, 0.0, 1.0]])
    ax, az = np.radians(rng.uniform(-max_rotation_deg, max_rotation_deg, 2))
    s = 1.0 + rng.uniform(-max_scale, max_scale)
    ty = rng.uniform(-max_shift, max_shift)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(ax), -np.sin(ax)], [0.0, np.sin(ax), np.cos(ax)]])
    Rz = np.array([[np.cos(az), -np.sin(az), 0.0], [np.sin(az), np.cos(az), 0.0], [0.0, 0.0, 1.0]])
    scale = np.array([[s, 0.0, (1 - s) * cx1], [0.0, s, (1 - s) * cy], [0.0, 0.0, 1.0]])
    H = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, ty], [0.0, 0.0, 1.0]]) @ scale @ K @ Rz @ Rx @ np.linalg.inv(K)
    H /= H[2, 2]
    right_bgr = np.ascontiguousarray(right[..., ::-1])
    out = SampleSet()
    out.images[f"{name}/left.png"] = np.ascontiguousarray(left[..., ::-1])
    out.images[f"{name}/right.png"] = cv2.warpPerspective(right_bgr, H, (w, h), flags=cv2.INTER_CUBIC,
                                                          borderMode=cv2.BORDER_CONSTANT)
    out.arrays[f"{name}/truth.npz"] = {"disparity": disp, "H_unrectify": H}
    max_disp = int(np.ceil((np.nanmax(disp) + 1) / 16) * 16)
    out.truth = {name: {"max_disp": max_disp, "H_unrectify": H.tolist(), "rotation_deg": [float(np.degrees(ax)), 0.0,
                                                                                          float(np.degrees(az))],
                        "scale": float(s), "shift_y_px": float(ty), "calib": "calib.txt",
                        "source": "Middlebury 2014 motorcycle via scikit-image, right view transformed"}}
    calib = (f"cam0=[{f:g} 0 {c['cx']:g}; 0 {f:g} {cy:g}; 0 0 1]\n"
             f"cam1=[{f:g} 0 {cx1:g}; 0 {f:g} {cy:g}; 0 0 1]\n"
             f"doffs={c['doffs']:g}\nbaseline={c['baseline']:g}\nwidth={w}\nheight={h}\nndisp={max_disp}\n")
    return out, {f"{name}/calib.txt": calib}


def make_panorama(rng: np.random.Generator) -> SampleSet:
    """Sets of overlapping perspective views cut from real photos, with the true homographies to the first view."""
    out = SampleSet()
    sets = []
    for name, n, vw, vh in (("motorcycle", 3, 340, 300), ("hubble_deep_field", 4, 300, 300), ("coffee", 3, 300, 260)):
        base = photo(name)
        if name == "hubble_deep_field":  # wide crop of a textured photo: 4 views with even overlap
            base = fit(base, 860, 420)
        bh, bw = base.shape[:2]
        step = (bw - vw) / (n - 1)
        Hs, files = [], []
        for i in range(n):
            x0 = i * step
            src = np.float32([[x0, 20], [x0 + vw, 20], [x0 + vw, 20 + vh], [x0, 20 + vh]])
            src[:, 1] = np.clip(src[:, 1], 0, bh - 1)
            dst = np.float32([[0, 0], [vw, 0], [vw, vh], [0, vh]]) + rng.uniform(-12, 12, (4, 2)).astype(np.float32)
            T = cv2.getPerspectiveTransform(src, dst).astype(np.float64)  # base -> view
            view = cv2.warpPerspective(base, T, (vw, vh), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
            fname = f"{name}/view_{i}.jpg"
            out.images[fname] = degrade(view, rng, gain=(0.9, 1.1), bias=(-8, 8), blur=(0, 0.4), noise=(1, 2),
                                        jpeg=(88, 95))
            Hs.append(T)
            files.append(fname)
        to_first = [(Hs[0] @ np.linalg.inv(T) / (Hs[0] @ np.linalg.inv(T))[2, 2]).tolist() for T in Hs]
        sets.append({"name": name, "images": files, "H": to_first})
    out.truth = {"sets": sets, "direction": "H[i] maps image i pixels to the first image's pixels"}
    return out


def build(params: SamplesParams | None = None) -> dict[str, SampleSet]:
    """Every task's sample set with the ``samples`` section (``seed``, ``logo_scenes``, ``logo_negatives``): the
    ``samples`` stage's entry point.

    Examples
    --------
    >>> from cvpipe.params import SamplesParams
    >>> sets = build(SamplesParams(seed=3, logo_scenes=2, logo_negatives=1))
    >>> sorted(sets)
    ['defect', 'homography', 'hough', 'logo', 'panorama', 'stereo']
    """
    p = section_or_default(params, SamplesParams, "samples")
    return build_all(p.seed, p.logo_scenes, p.logo_negatives)


def build_all(seed: int, logo_scenes: int, logo_negatives: int) -> dict[str, SampleSet]:
    """Every task's sample set from one seed (each task gets its own child stream, so they stay independent); the
    counts' defaults are the ``samples`` section's (:func:`build`)."""
    streams = np.random.SeedSequence(seed).spawn(6)  # child i depends on i only: adding one kept the others
    rngs = [np.random.default_rng(s) for s in streams]
    return {
        "logo": make_logo(rngs[0], logo_scenes, logo_negatives),
        "hough": make_hough(rngs[1]),
        "defect": make_defect(rngs[2]),
        "homography": make_homography(rngs[3]),
        "stereo": stereo_samples(rngs[5]),
        "panorama": make_panorama(rngs[4]),
    }


def stereo_samples(rng: np.random.Generator) -> SampleSet:
    """The stereo folder, one subfolder per pair: ``motorcycle/`` (the rectified pair, its truth.npz and
    truth.json) and ``motorcycle_unrectified/`` (:func:`make_stereo_unrectified`: truth.npz and calib.txt)."""
    rectified = make_stereo()
    unrect, texts = make_stereo_unrectified(rng)
    out = SampleSet(images={f"motorcycle/{k}": v for k, v in rectified.images.items()},
                    arrays={f"motorcycle/{k}": v for k, v in rectified.arrays.items()},
                    docs={"motorcycle/truth.json": rectified.truth})
    out.images.update(unrect.images)
    out.arrays.update(unrect.arrays)
    out.texts.update(texts)
    return out


README = """# Bundled sample data (generated by the `samples` stage; do not edit)

Built offline and deterministically from scikit-image's bundled photos and CC0 simple-icons marks.
Coordinates follow OpenCV: x = column, y = row, origin at the centre of the top-left pixel.
Each task folder holds its images and `truth.json`:

- `logo/`: `gallery/<brand>.png` (10 brands), `scenes/scene_NN.jpg`; truth `scenes[]` = file, brand (null = no
  gallery mark; some of those carry a distractor mark that is not in the gallery), quad = the gallery card's
  corner pixel centres mapped into the scene (clockwise from top-left), or null.
- `hough/`: `*.png`; truth `images[]` = file, lines = [[rho, theta]] in cv2.HoughLines convention
  (x cos theta + y sin theta = rho). Only the drawn lines are truth; the photos' own edges are not labelled.
- `defect/`: `reference.png`, `probes/probe_NN.png`; truth `probes[]` = file, verdict (faulty/perfect), boxes
  [[x1, y1, x2, y2]] in probe pixels, reference_boxes in reference pixels, H (reference -> probe).
- `homography/`: `<name>_a.jpg`, `<name>_b.jpg`; truth `pairs[]` = name, a, b, H (A -> B pixels).
- `stereo/<pair>/`: `left.png`, `right.png`, `truth.npz` (key `disparity`, float32 pixels, NaN = unknown, of the
  original rectified pair's left image). `motorcycle/` is rectified, its `truth.json` gives `max_disp`
  (disparities searched 0 .. max_disp - 1); `motorcycle_unrectified/` has the right view turned and shifted
  (`truth.npz` also holds `H_unrectify`, original right -> this right pixels) and the rig's Middlebury `calib.txt`.
- `panorama/<set>/view_i.jpg`; truth `sets[]` = name, images, H (image i -> first image pixels).
"""

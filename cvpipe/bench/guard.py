"""``cvpipe bench guard``: the speed guard of the from-scratch parts.

Each row times one of our parts against its OpenCV counterpart on the same input in this process (warm kernels,
best of ``--repeats`` calls on both sides, interleaved so that load from elsewhere hits both alike) and prints the
time ratio ours / OpenCV beside an accuracy figure of both, so that a row cannot get faster by getting worse. Rows
over a set of items report the worst item (``max``) or the median, as the limit's line says. A few rows are whole
processes or absolute times (start-up, a warm command, the time a command takes before its work starts, the
defect inspection per probe).

The limits live in ``guard_limits.txt`` beside this module, one line per row: the row, its limit, and why. The
command exits 1 naming every row over its limit. Rows on the real data sets run when ``--data`` (default
``$CVPIPE_DATA``) holds them and are skipped otherwise; the bundled samples (``data/samples``, made by
``dvc repro samples``) are always used.
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
import typing
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import EstimationError, InputError

if typing.TYPE_CHECKING:  # annotations only: `cvpipe bench guard --help` imports neither numpy nor cv2
    import numpy as np

HELP = "the speed guard: each from-scratch part against OpenCV in this process, checked against committed limits"
EXAMPLE = "cvpipe bench guard --samples data/samples --data ../shared/data"

LIMITS_FILE = Path(__file__).with_name("guard_limits.txt")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--samples", default="data/samples",
                        help="the bundled samples (made by `dvc repro samples`; default data/samples)")
    parser.add_argument("--data", default=os.environ.get("CVPIPE_DATA"),
                        help="root of the real data sets (default: $CVPIPE_DATA); their rows skip when absent")
    parser.add_argument("--repeats", type=int, default=3, help="timed calls per item and side, best taken")
    parser.add_argument("--rows", nargs="+", help="only these rows (default: all)")
    parser.add_argument("--limits", default=str(LIMITS_FILE), help="the limits file (default: the committed one)")
    parser.add_argument("--out", help="also write the results as JSON to this file")
    parser.add_argument("--json", action="store_true", help="print JSON instead of the table")


# ---------------------------------------------------------------------------------------------------- rows


@dataclass
class Row:
    """One measured row: ``value`` is a ratio ours / OpenCV (``unit == "x"``) or seconds (``unit == "s"``)."""

    name: str
    value: float
    unit: str
    what: str
    accuracy: str
    items: int
    detail: dict = field(default_factory=dict)


def best_of(fns: dict, repeats: int, warm_up: bool = True) -> dict:
    """Best wall time in seconds of each callable in ``fns``, calls interleaved, after one warm-up call of each
    (``warm_up=False``: the callables have just run)."""
    if warm_up:
        for fn in fns.values():
            fn()
    times = {k: float("inf") for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[k] = min(times[k], time.perf_counter() - t0)
    return times


def _images(folder: Path) -> list[Path]:
    return sorted(p for p in folder.glob("*") if p.suffix.lower() in (".png", ".jpg", ".jpeg"))


def _hough_pair(edges, rho: float, theta: float, threshold: int) -> dict:
    """The two calls that the hough row compares: ours (no refinement, as OpenCV) and ``cv2.HoughLines``."""
    import cv2

    from ..hough import hough_lines

    return {"ours": lambda: hough_lines(edges, rho, theta, threshold, refine=False),
            "opencv": lambda: cv2.HoughLines(edges, rho, theta, threshold)}


def row_hough(ctx: dict) -> list[Row]:
    """``hough_lines`` / ``cv2.HoughLines`` per edge map (the pipeline's Canny and line parameters): worst and
    median ratio; accuracy: images whose lines equal OpenCV's exactly."""
    import cv2
    import numpy as np

    from ..hough import canny_edges, hough_lines
    from ..params import HoughEdgesParams, HoughLinesParams

    e, p = HoughEdgesParams(), HoughLinesParams()
    theta = np.deg2rad(p.theta_deg)
    paths = _images(ctx["samples"] / "hough")
    if ctx["data"] is not None and (ctx["data"] / "yorkurban_lines" / "images").is_dir():
        paths += _images(ctx["data"] / "yorkurban_lines" / "images")
    ratios, same, timed = [], 0, []
    for path in ctx["progress"](paths, "guard hough"):
        edges = canny_edges(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), e.canny_low, e.canny_high,
                            aperture=e.aperture, l2_gradient=e.l2_gradient, blur_sigma=e.blur_sigma)
        ours = hough_lines(edges, p.rho, theta, p.threshold, refine=False)
        cv = cv2.HoughLines(edges, p.rho, theta, p.threshold)
        cv = np.zeros((0, 2), np.float32) if cv is None else cv[:, 0, :]
        same += bool(len(ours) == len(cv) and np.array_equal(ours[:, :2].astype(np.float32), cv))
        # a few milliseconds a call, and the worst of 106 ratios is kept: more calls per side keep that maximum from
        # being one unlucky call on a loaded machine (best of 3 gave 0.90x-0.95x worst at load 0.7-1.7)
        t = best_of(_hough_pair(edges, p.rho, theta, p.threshold), ctx["repeats"] + 4)
        ratios.append(t["ours"] / t["opencv"])
        timed.append(edges)
    # the worst of 106 best-of-7 ratios is mostly the unluckiest image (one descheduled call): the five worst are
    # measured again with 31 calls per side, and that estimate of their ratio is kept
    for i in sorted(range(len(ratios)), key=ratios.__getitem__)[-5:]:
        t = best_of(_hough_pair(timed[i], p.rho, theta, p.threshold), 31)
        ratios[i] = t["ours"] / t["opencv"]
    acc = f"same lines as OpenCV on {same}/{len(paths)} images"
    return [Row("hough_max", max(ratios), "x", "hough_lines / cv2.HoughLines, worst image", acc, len(paths)),
            Row("hough_median", statistics.median(ratios), "x", "hough_lines / cv2.HoughLines, median image", acc,
                len(paths))]


def _homography_pairs(ctx: dict) -> list[dict]:
    """Samples pairs, plus the Oxford and CMP pairs when the data root has them: name, images, true H."""
    import numpy as np

    from .. import io

    truth = io.load_json(ctx["samples"] / "homography" / "truth.json")
    pairs = [{"name": t["name"], "a": ctx["samples"] / "homography" / t["a"],
              "b": ctx["samples"] / "homography" / t["b"], "H": np.asarray(t["H"], float)} for t in truth["pairs"]]
    if ctx["data"] is not None:
        from .homography import real_pairs

        pairs += real_pairs(ctx["data"])
    return pairs


def row_homography(ctx: dict) -> list[Row]:
    """``find_homography`` (significance test included) / ``cv2.findHomography(USAC_MAGSAC)`` on the SIFT matches
    of every pair: median ratio; accuracy: median corner error of both, and the pairs each refuses."""
    import cv2
    import numpy as np

    from .. import io
    from ..homography import correspondences, find_homography
    from ..metrics import corner_error
    from ..params import HomographyEstimateParams

    est = HomographyEstimateParams()
    ratios, err_ours, err_cv, refused = [], [], [], []
    pairs = _homography_pairs(ctx)
    for pair in ctx["progress"](pairs, "guard homography"):
        a, b = io.read_image(pair["a"], "gray"), io.read_image(pair["b"], "gray")
        cv2.setRNGSeed(0)  # FLANN draws from OpenCV's global RNG: the same matches whatever ran before
        src, dst = correspondences(a, b)
        if len(src) < 8:
            continue

        def ours(src=src, dst=dst):
            try:
                return find_homography(src, dst, est.threshold, est.confidence, est.max_iters, rng=0).H
            except EstimationError:
                return None

        def opencv(src=src, dst=dst):
            return cv2.findHomography(src, dst, cv2.USAC_MAGSAC, est.threshold, confidence=est.confidence,
                                      maxIters=est.max_iters)[0]

        t = best_of({"ours": ours, "opencv": opencv}, ctx["repeats"])
        ratios.append(t["ours"] / t["opencv"])
        H_ours, H_cv = ours(), opencv()
        h, w = a.shape
        if H_ours is None:
            refused.append(pair["name"])
        else:
            err_ours.append(corner_error(H_ours, pair["H"], w, h))
        if H_cv is not None:
            err_cv.append(corner_error(H_cv, pair["H"], w, h))
    acc = (f"median corner error {np.median(err_ours):.3g} px (MAGSAC {np.median(err_cv):.3g}); "
           f"ours refuses {len(refused)}")
    return [Row("homography_median", statistics.median(ratios), "x",
                "find_homography / USAC_MAGSAC, median pair", acc, len(ratios), {"refused": refused})]


def _outlier_row(ctx: dict, name: str, outliers: float) -> Row:
    import cv2
    import numpy as np

    from ..homography import find_homography
    from ..metrics import corner_error
    from .homography import synthetic_scene

    ratios, err_ours, err_cv = [], [], []
    for seed in range(3):
        H, src, dst = synthetic_scene(np.random.default_rng(seed), 1000, outliers)
        t = best_of({"ours": lambda: find_homography(src, dst, 3.0, 0.999, 100_000, rng=0),
                     "opencv": lambda: cv2.findHomography(src, dst, cv2.USAC_MAGSAC, 3.0, confidence=0.999,
                                                          maxIters=100_000)}, ctx["repeats"])
        ratios.append(t["ours"] / t["opencv"])
        err_ours.append(corner_error(find_homography(src, dst, 3.0, 0.999, 100_000, rng=0).H, H, 640, 480))
        err_cv.append(corner_error(cv2.findHomography(src, dst, cv2.USAC_MAGSAC, 3.0, confidence=0.999,
                                                      maxIters=100_000)[0], H, 640, 480))
    acc = f"median corner error {np.median(err_ours):.3g} px (MAGSAC {np.median(err_cv):.3g})"
    return Row(name, statistics.median(ratios), "x",
               f"find_homography / USAC_MAGSAC, 1000 matches, {outliers:.0%} outliers, median of 3 scenes", acc, 3)


def row_homography_outliers(ctx: dict) -> list[Row]:
    """The same on synthetic matches with a known H at a low and at a 90 % outlier rate."""
    return [_outlier_row(ctx, "homography_10pct", 0.1), _outlier_row(ctx, "homography_90pct", 0.9)]


def _stereo_pairs(ctx: dict) -> dict:
    """name -> (left BGR, right BGR, true disparity): the Middlebury pairs and motorcycle when the data root has
    them, else the samples' motorcycle pair."""
    if ctx["data"] is not None and (ctx["data"] / "middlebury_stereo").is_dir():
        from .stereo_pairs import load_pairs

        return load_pairs(ctx["data"])
    import numpy as np
    import skimage.data

    left, right, disp = skimage.data.stereo_motorcycle()
    return {"motorcycle": (np.ascontiguousarray(left[..., ::-1]), np.ascontiguousarray(right[..., ::-1]),
                           np.where(np.isfinite(disp), disp, np.nan).astype(np.float32))}


def row_sgm(ctx: dict) -> list[Row]:
    """``disparity_sgm`` / ``StereoSGBM`` in its best mode (lowest bad-2.0 of its modes and block sizes) per pair:
    worst ratio; accuracy: bad-2.0 of both."""
    import numpy as np

    from .. import stereo
    from .stereo import _best_sgbm, disparity_range

    bad, timed = [], []
    pairs = _stereo_pairs(ctx)
    # every pair is run once before any is timed: the first calls of the process (OpenMP's and OpenCV's threads
    # starting, the first allocations of each size) are slower than the rest
    for name, (left, right, truth) in ctx["progress"](list(pairs.items()), "guard sgm"):
        nd = disparity_range(truth)
        cfg, disp_cv = _best_sgbm(left, right, nd, truth)
        disp = stereo.disparity_sgm(left, right, nd)
        bad.append(tuple(stereo.evaluate(d, truth, (2.0,))["bad_2.0"] for d in (disp, disp_cv)))
        timed.append((left, right, nd, cfg))
    def ratio(left, right, nd, cfg, calls, warm_up=True):
        t = best_of({"ours": lambda: stereo.disparity_sgm(left, right, nd),
                     "opencv": lambda: stereo.disparity_opencv_sgbm(left, right, nd, **cfg)}, calls, warm_up)
        return t["ours"] / t["opencv"]

    # ours runs on OpenMP's threads, whose start varies (and tsukuba takes 5 ms in SGBM): more calls for a stable best
    ratios = [ratio(*args, ctx["repeats"] + 6) for args in timed]
    # the worst of six best-of-9 ratios read 1.47-2.35x in six runs on an idle machine (one unlucky series of calls
    # decides it): the two worst pairs are measured again with 31 calls a side, and that estimate is kept, as the
    # hough row does for its five worst images
    for i in sorted(range(len(ratios)), key=ratios.__getitem__)[-2:]:
        ratios[i] = ratio(*timed[i], 31, warm_up=False)
    better = sum(o <= c for o, c in bad)
    acc = (f"bad-2.0 lower than SGBM's on {better}/{len(bad)} pairs; mean {100 * np.mean([o for o, _ in bad]):.1f} % "
           f"(SGBM {100 * np.mean([c for _, c in bad]):.1f} %)")
    return [Row("sgm_max", max(ratios), "x", "disparity_sgm / StereoSGBM best mode, worst pair", acc, len(ratios))]


def row_fundamental(ctx: dict) -> list[Row]:
    """``find_fundamental`` / ``cv2.findFundamentalMat(USAC_MAGSAC)`` on the SIFT matches of each stereo pair with
    its right view turned by a seeded random rotation: worst ratio; accuracy: median Sampson distance of the true
    correspondences under each estimate."""
    import cv2
    import numpy as np

    from .. import io, stereo
    from ..homography import correspondences
    from .stereo_rectify import THRESHOLD, true_correspondences, unrectifying_homography

    ratios, err_ours, err_cv = [], [], []
    pairs = _stereo_pairs(ctx)
    for seq, (name, (left, right, truth)) in zip(np.random.SeedSequence(0).spawn(len(pairs)),
                                                  ctx["progress"](list(pairs.items()), "guard fundamental")):
        rng = np.random.default_rng(seq)
        h, w = left.shape[:2]
        H_u, _ = unrectifying_homography(rng, (w, h))
        right_u = cv2.warpPerspective(right, H_u, (w, h), flags=cv2.INTER_LINEAR)
        cv2.setRNGSeed(0)
        p1, p2 = correspondences(io.to_gray(left), io.to_gray(right_u))
        t = best_of({"ours": lambda: stereo.find_fundamental(p1, p2, THRESHOLD, rng=0),
                     "opencv": lambda: cv2.findFundamentalMat(p1, p2, cv2.USAC_MAGSAC, THRESHOLD, 0.999)},
                    ctx["repeats"])
        ratios.append(t["ours"] / t["opencv"])
        pl, pr = true_correspondences(truth, H_u, (w, h))
        err_ours.append(float(np.median(stereo.sampson_distance(stereo.find_fundamental(p1, p2, THRESHOLD,
                                                                                          rng=0).F, pl, pr))))
        F_cv = cv2.findFundamentalMat(p1, p2, cv2.USAC_MAGSAC, THRESHOLD, 0.999)[0][:3]
        err_cv.append(float(np.median(stereo.sampson_distance(F_cv, pl, pr))))
    acc = (f"median Sampson distance of the true matches {np.mean(err_ours):.3f} px (MAGSAC {np.mean(err_cv):.3f}), "
           "mean over pairs")
    return [Row("fundamental_max", max(ratios), "x", "find_fundamental / findFundamentalMat MAGSAC, worst pair",
                acc, len(ratios))]


def _panorama_sets(ctx: dict) -> dict:
    """name -> image paths: the samples' sets, plus budapest and weir when the data root has them."""
    sets = {f"samples/{d.name}": _images(d) for d in sorted((ctx["samples"] / "panorama").iterdir()) if d.is_dir()}
    if ctx["data"] is not None:
        from .panorama import SETS

        for name in ("budapest",):
            folder, files, _ = SETS[name]
            paths = [ctx["data"] / folder / f for f in files]
            if all(p.is_file() for p in paths):
                sets[name] = paths
    return sets


def _cv_stitch(images):
    import cv2

    status, pano = cv2.Stitcher.create(cv2.Stitcher_PANORAMA).stitch(images)
    return pano if status == cv2.Stitcher_OK else None


def _panorama_truth(paths: list[Path]) -> dict[tuple[int, int], np.ndarray]:
    """Ground-truth pair homographies (input position i -> j) of a samples set from its ``truth.json`` (``H[i]``
    maps image i to the first image); empty when the set has none."""
    import numpy as np

    from .. import io

    truth = paths[0].parent.parent / "truth.json"
    if not truth.is_file():
        return {}
    name = paths[0].parent.name
    for s in io.load_json(truth).get("sets", []):
        if s["name"] == name:
            pos = {Path(f).name: k for k, f in enumerate(s["images"])}
            H = {pos[p.name]: np.array(s["H"][pos[p.name]]) for p in paths if p.name in pos}
            return {(i, j): np.linalg.inv(H[j]) @ H[i] for i in H for j in H if i != j}
    return {}


def row_stitch(ctx: dict) -> list[Row]:
    """``panorama.stitch`` with each preset (``default``, ``fast``) / ``cv2.Stitcher`` in this process per set:
    worst ratio per preset; accuracy: on sets with ground truth, the median corner error of the pair homographies
    of ours (each preset) and of those cv2.Stitcher's cameras imply (:func:`cvpipe.bench.panorama.pair_error_median`),
    elsewhere the images each used."""
    from .. import io, panorama
    from ..params import PanoramaFeaturesParams, PanoramaMatchParams, PanoramaWarpParams
    from .panorama import pair_error_median

    presets = ("default", "fast")
    ratios = {k: [] for k in presets}
    notes, names = [], []
    for name, paths in ctx["progress"](list(_panorama_sets(ctx).items()), "guard stitch"):
        images = [io.read_image(p) for p in paths]
        sizes = [(im.shape[1], im.shape[0]) for im in images]
        names.append(name)

        def ours(preset, images=images):
            try:
                return panorama.stitch(images, **panorama.preset_sections(preset), rng=0)
            except EstimationError:
                return None

        fns = {k: (lambda k=k: ours(k)) for k in presets}
        # best of `repeats` interleaved calls per side: a single call's ratio spreads over 1.2-1.6x on budapest
        # across quiet runs, most of it cv2.Stitcher's own spread (0.77-1.10 s)
        t = best_of({**fns, "opencv": lambda: _cv_stitch(images)}, ctx["repeats"])
        for k in presets:
            ratios[k].append(t[k] / t["opencv"])
        gt = _panorama_truth(paths)
        cv = panorama.opencv_stitch_cameras(images, PanoramaFeaturesParams().work_megapix,
                                            PanoramaWarpParams().compose_megapix,
                                            PanoramaMatchParams().min_confidence, seed=0)
        got = {k: ours(k) for k in presets}
        fmt = (lambda v: "over half the pairs failed" if v is None else f"{v:.2f} px")
        if gt:
            errs = {k: None if p is None else pair_error_median(p.homographies, gt, sizes) for k, p in got.items()}
            notes.append(f"{name}: " + ", ".join(f"{k} {fmt(errs[k])}" for k in presets)
                         + f", cv2 {fmt(pair_error_median(cv.homographies, gt, sizes))}")
        else:
            notes.append(f"{name}: " + ", ".join(f"{k} uses {0 if p is None else len(p.registration.used)}"
                                                 f"/{len(images)}" for k, p in got.items())
                         + f", cv2 {len(cv.used)}/{len(images)}")
    acc = "GT pair error (median corner px) or images used: " + "; ".join(notes)
    return [Row("stitch_max", max(ratios["default"]), "x",
                "panorama.stitch (default preset) / cv2.Stitcher in process, worst set", acc, len(ratios["default"]),
                {"ratio_per_set": dict(zip(names, ratios["default"]))}),
            Row("stitch_fast_max", max(ratios["fast"]), "x",
                "panorama.stitch --preset fast / cv2.Stitcher in process, worst set", "as stitch_max",
                len(ratios["fast"]), {"ratio_per_set": dict(zip(names, ratios["fast"]))})]


_CV2_STITCH_COMMAND = """
import sys, cv2
images = [cv2.imread(p) for p in sys.argv[2:]]
status, pano = cv2.Stitcher.create(cv2.Stitcher_PANORAMA).stitch(images)
sys.exit(0 if status == cv2.Stitcher_OK and cv2.imwrite(sys.argv[1], pano) else 1)
"""


def _wall(cmd: list[str], repeats: int) -> float:
    """Best wall time in seconds of the command ``cmd`` run ``repeats`` times (after one warm-up run)."""
    best = float("inf")
    for k in range(repeats + 1):
        t0 = time.perf_counter()
        done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, check=False)
        if k:
            best = min(best, time.perf_counter() - t0)
        if done.returncode not in (0, 1):
            raise InputError(f"`{' '.join(cmd[:4])} ...` failed: {done.stderr.strip()[-300:]}")
    return best


def _cvpipe() -> list[str]:
    return [sys.executable, "-m", "cvpipe"]


def row_stitch_command(ctx: dict) -> list[Row]:
    """``cvpipe stitch`` against a Python command that reads, stitches with ``cv2.Stitcher`` and writes, as whole
    processes, per set: worst ratio."""
    ratios = []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "pano.png"
        for name, paths in ctx["progress"](list(_panorama_sets(ctx).items()), "guard stitch command"):
            files = [str(p) for p in paths]
            ours = _wall([*_cvpipe(), "-q", "stitch", *files, "-o", str(out)], max(1, ctx["repeats"] // 3))
            cv = _wall([sys.executable, "-c", _CV2_STITCH_COMMAND, str(out), *files], max(1, ctx["repeats"] // 3))
            ratios.append(ours / cv)
    return [Row("stitch_command_max", max(ratios), "x",
                "`cvpipe stitch` / a cv2.Stitcher Python command, wall, worst set", "as stitch_max", len(ratios))]


#: the line that ``cvpipe -v stitch`` logs on stderr when its stitch step ends (:func:`cvpipe.commands.step`)
_STITCH_STEP = re.compile(r"^cvpipe: stitch \d+ images: (?P<seconds>[0-9.]+) s$")


def _before_step(cmd: list[str], step: re.Pattern, repeats: int) -> float:
    """Best, over ``repeats`` runs after one warm-up run, of the seconds that the command ``cmd`` (run with ``-v``)
    spends before the step whose log line matches ``step``.

    Measured from the outside: from just before the process is started to the arrival of the step's line on its
    stderr, less the step's own seconds that the line gives (its group ``seconds``, to the millisecond). The line is
    read as it comes (Python's stderr is line-buffered, and the log handler flushes each record), so what it adds is
    the pipe's latency, microseconds.
    """
    best = float("inf")
    for k in range(repeats + 1):
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        before, tail = None, collections.deque(maxlen=5)
        for line in proc.stderr:
            found = step.match(line.rstrip("\n"))
            if found is not None and before is None:
                before = time.perf_counter() - t0 - float(found["seconds"])
            tail.append(line)
        if proc.wait() != 0 or before is None:
            why = f"exit {proc.returncode}" if proc.returncode else "no line of the step"
            raise InputError(f"`{' '.join(cmd[:5])} ...`: {why}: {''.join(tail).strip()[-300:]}")
        if k:
            best = min(best, before)
    return best


def row_startup(ctx: dict) -> list[Row]:
    """Wall time of ``cvpipe --version`` and of a warm ``cvpipe hough`` on a sample image, best of the repeats; and
    the seconds that ``cvpipe stitch`` spends before stitching (process start, imports, reading the photos) on each
    of the samples' panorama sets, best of the repeats: the worst set."""
    image = _images(ctx["samples"] / "hough")[0]
    version = _wall([*_cvpipe(), "--version"], ctx["repeats"])
    hough = _wall([*_cvpipe(), "hough", str(image), "--json"], ctx["repeats"] + 2)
    startup = {}
    with tempfile.TemporaryDirectory() as tmp:
        sets = _panorama_sets({**ctx, "data": None})  # the samples' sets only: the row is the same with --data
        for name, paths in ctx["progress"](list(sets.items()), "guard stitch start-up"):
            cmd = [*_cvpipe(), "-v", "stitch", *map(str, paths), "-o", str(Path(tmp) / "pano.png")]
            startup[name] = _before_step(cmd, _STITCH_STEP, ctx["repeats"] + 2)
    worst = max(startup, key=startup.__getitem__)
    return [Row("version_s", version, "s", "`cvpipe --version` wall", "-", 1),
            Row("hough_command_s", hough, "s", f"warm `cvpipe hough {image.name} --json` wall", "-", 1),
            Row("stitch_startup_s", startup[worst], "s",
                f"`cvpipe stitch` before stitching (start, imports, reading), worst samples set ({worst})", "-",
                len(startup), {"seconds_per_set": startup})]


def row_defect(ctx: dict) -> list[Row]:
    """``defect.inspect`` per probe of the samples in this process (reference features computed once): mean
    seconds per probe, best of the repeats; accuracy: verdicts that match the truth."""
    from .. import defect, io
    from ..features import detect_with
    from ..params import InspectParams

    folder = ctx["samples"] / "defect"
    truth = io.load_json(folder / "truth.json")
    reference = io.read_image(folder / "reference.png", "gray")
    probes = {p.name: io.read_image(p, "gray") for p in _images(folder / "probes")}
    feats = detect_with(reference, InspectParams().features)

    def run_all():
        return {n: defect.inspect(reference, img, reference_features=feats).verdict for n, img in probes.items()}

    verdicts = run_all()
    seconds = best_of({"ours": run_all}, max(1, ctx["repeats"] // 3))["ours"] / len(probes)
    expected = {p["file"]: p["verdict"] for p in truth["probes"]}
    right = sum(verdicts.get(k) == v for k, v in expected.items())
    return [Row("defect_probe_s", seconds, "s", "defect.inspect per probe, in process",
                f"right verdict on {right}/{len(expected)} probes", len(probes))]


#: row group -> function; the rows each group produces are named in the limits file
GROUPS = {
    "hough": row_hough,
    "homography": row_homography,
    "homography_outliers": row_homography_outliers,
    "sgm": row_sgm,
    "fundamental": row_fundamental,
    "stitch": row_stitch,
    "stitch_command": row_stitch_command,
    "startup": row_startup,
    "defect": row_defect,
}


# -------------------------------------------------------------------------------------------------- limits


#: the largest limits file read, bytes (the committed one is a few kB)
MAX_LIMITS_BYTES = 1_000_000


def read_limits(path: str | os.PathLike) -> dict[str, tuple[float, str]]:
    """row -> (limit, why) from a limits file: ``row limit why...`` per line, ``#`` starts a comment line.

    The file must be a regular UTF-8 text file of at most :data:`MAX_LIMITS_BYTES` (a device such as
    ``/dev/zero`` is refused before anything is read); each refusal is one line naming it.
    """
    from .. import io

    p = Path(path)
    if p.exists() and not p.is_dir() and not p.is_file():
        raise InputError(f"{p}: not a regular file, expected a limits text file", file=str(p))
    text = io.read_text(p, "limits", max_bytes=MAX_LIMITS_BYTES)
    limits = {}
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        parts = line.split(None, 2)
        try:
            limits[parts[0]] = (float(parts[1]), parts[2] if len(parts) > 2 else "")
        except (IndexError, ValueError):
            raise InputError(f"{path}:{number}: expected `row limit why`, got {line!r}") from None
    return limits


def _cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo ("unknown" elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


def _versions() -> dict[str, str]:
    """The versions that the ratios depend on: OpenCV's (the baseline: 5.1's HoughLines is about 40 % faster than
    5.0's) and numpy's. cvpipe's own kernels are compiled ahead of time with fixed flags (meson.build)."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for name in ("opencv-contrib-python-headless", "numpy"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


def run(args: argparse.Namespace) -> int:
    from .. import io

    if args.repeats < 1:
        raise InputError(f"`--repeats` must be >= 1, got {args.repeats}")
    samples = Path(args.samples)
    if not (samples / "hough").is_dir():
        raise InputError(f"{samples}: no bundled samples there; make them with `dvc repro samples`")
    data = Path(args.data) if args.data else None
    if data is not None and not data.is_dir():
        raise InputError(f"--data {data}: no such folder")
    unknown = sorted(set(args.rows or ()) - set(GROUPS))
    if unknown:
        raise InputError(f"--rows: unknown {', '.join(unknown)}; choices: {', '.join(GROUPS)}")
    limits = read_limits(args.limits)
    if args.out:  # before the rows: a result that cannot be written must not cost the measuring first
        io.check_output_path(args.out, "--out")
    ctx = {"samples": samples, "data": data, "repeats": args.repeats,
           "progress": lambda items, desc: io.progress(items, desc)}
    rows: list[Row] = []
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    for group in args.rows or GROUPS:
        rows += GROUPS[group](ctx)
    seconds = time.perf_counter() - t0
    over, missing = [], []
    results = []
    for r in rows:
        limit = limits.get(r.name)
        if limit is None:
            missing.append(r.name)
        elif not r.value <= limit[0]:
            over.append(r.name)
        results.append({"row": r.name, "value": r.value, "unit": r.unit, "limit": None if limit is None else limit[0],
                        "over": r.name in over, "what": r.what, "accuracy": r.accuracy, "items": r.items,
                        **r.detail})
    summary = {"rows": results, "over": over, "no_limit": missing, "seconds": seconds,
               "load_average_1min": [load0, os.getloadavg()[0]], "cpus": os.cpu_count(), "machine": _cpu_model(),
               "versions": _versions(),
               "command": "cvpipe bench guard" + (" --data $CVPIPE_DATA" if data is not None else ""),
               "data": None if data is None else str(data)}
    if args.out:
        io.save_json(args.out, summary)
    if args.json:
        print(io.dumps_json(summary))
    else:
        print(f"{'row':<20} {'value':>8} {'limit':>6}  {'n':>4}  what; accuracy")
        for r in results:
            lim = "-" if r["limit"] is None else f"{r['limit']:g}"
            mark = "  OVER" if r["over"] else ""
            print(f"{r['row']:<20} {r['value']:7.3f}{r['unit']} {lim:>6}  {r['items']:>4}  {r['what']}; "
                  f"{r['accuracy']}{mark}")
        print(f"{seconds:.0f} s; load average {load0:.2f} -> {os.getloadavg()[0]:.2f} on {os.cpu_count()} cpus; "
              f"real data: {'yes' if data is not None else 'no ($CVPIPE_DATA unset: those rows use the samples only)'}")
    if missing:
        print(f"cvpipe: error: rows without a limit in {args.limits}: {', '.join(missing)}", file=sys.stderr)
    if over:
        print(f"cvpipe: error: over the limit: {', '.join(over)}", file=sys.stderr)
    return 1 if over or missing else 0

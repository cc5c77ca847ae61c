"""``cvpipe bench panorama --data DIR``: our stitcher vs ``cv2.Stitcher`` on the Adobe and OpenStitching sets.

Per set: success of both, images used and dropped (with our reasons), the pairwise corner error of our homographies
against the Adobe ground truth (``HiitoJJ.txt`` maps image ii -> jj) measured two ways (each pair's own homography
from the match graph, "direct", and the pair composed from the global homographies, "composed"; see
:func:`_accuracy`), how consistent the ground truth itself is, the share of empty pixels after our crop, a ghosting
measure (mean absolute grey difference of the overlapping warped images, after gain compensation) and the time of
both, measured in the same process, interleaved, after a warm-up run, at the same registration and compose
resolutions; the first set's warm-up run, the first stitch of the process, is reported on its own. What a user
waits for is also measured: the whole ``cvpipe stitch`` command in a subprocess (Python start-up, imports, reading,
stitching, writing), against ``cv2.Stitcher`` in this process, in wall time and in CPU time (user + system of all
threads: the command's from ``getrusage`` of the finished child, ``cv2.Stitcher``'s from this process's CPU clock),
which a busy shared machine distorts much less.
Both axes per set and preset (``--presets``, :mod:`cvpipe.panorama.presets`): the in-process time of each of our
presets over cv2.Stitcher's, and the median corner error over the ground-truth pairs of the pair homographies
composed from each stitcher's global geometry (ours: ``Panorama.homographies``; cv2.Stitcher, seeded with
``cv2.setRNGSeed(0)``: those its cameras imply, :func:`cvpipe.panorama.camera_homographies`), an image left out
counting as a failure for both (:func:`pair_error_median`).
On the sets of :data:`EXPOSURE_SETS` every exposure compensator (:data:`cvpipe.panorama.GAIN_CHOICES`) blends the
same warped images, and the colour difference across the seam in the sky is measured (:func:`seam_colour_difference`).
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import typing
from pathlib import Path

from ..errors import EstimationError, InputError
from ..commands.stitch import PRESET_CHOICES
from ..params import (PanoramaBlendParams, PanoramaFeaturesParams, PanoramaHomographiesParams, PanoramaMatchParams,
                      PanoramaWarpParams, replace)

if typing.TYPE_CHECKING:  # annotations only: the modules are imported inside the functions that use them,
    # so that `cvpipe bench panorama --help` imports neither numpy nor cv2
    import numpy as np

    from .. import panorama


HELP = "panorama stitching vs cv2.Stitcher on the Adobe and OpenStitching sets"
EXAMPLE = "cvpipe bench panorama --data ../shared/data --repeat 3 --json"

#: --projection and --refine choices (cvpipe.panorama's PROJECTIONS and REFINEMENTS), read from the params models
#: so that --help needs no cv2
PROJECTIONS = typing.get_args(PanoramaWarpParams.model_fields["projection"].annotation)
REFINEMENTS = typing.get_args(PanoramaHomographiesParams.model_fields["refine"].annotation)

#: set name -> (folder under the data root, file names in input order, files that must be dropped)
SETS = {
    "goldengate": ("adobe_panoramas/goldengate", [f"goldengate-{k:02d}.png" for k in range(6)], []),
    "halfdome-6": ("adobe_panoramas/halfdome", [f"halfdome-{k:02d}.png" for k in range(6)], []),
    "halfdome-14": ("adobe_panoramas/halfdome", [f"halfdome-{k:02d}.png" for k in range(14)], []),
    "budapest": ("stitching_tutorial/imgs", [f"budapest{k}.jpg" for k in range(1, 7)], []),
    # the distractor sits between the real views, and those are shuffled: order must not matter
    "weir+noise": ("stitching_tutorial/imgs", ["weir_3.jpg", "weir_noise.jpg", "weir_1.jpg", "weir_2.jpg"],
                   ["weir_noise.jpg"]),
    "exposure_error": ("stitching_tutorial/imgs", ["exposure_error_1.jpg", "exposure_error_2.jpg"], []),
}
#: sets on which every exposure compensator is compared (a sky across the seam, shot at two exposures)
EXPOSURE_SETS = ("exposure_error",)
#: share of the panorama's rows, from the top, where :func:`seam_colour_difference` measures (the sky)
SKY_ROWS = 0.25


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", default=os.environ.get("CVPIPE_DATA"),
                        help="data root holding adobe_panoramas/ and stitching_tutorial/ (default $CVPIPE_DATA)")
    parser.add_argument("--sets", nargs="+", choices=list(SETS), default=list(SETS), help="sets to run (default all)")
    parser.add_argument("--repeat", type=int, default=3, help="timed runs of each method per set (default 3)")
    parser.add_argument("--projection", choices=PROJECTIONS, default="spherical",
                        help="our projection (default spherical, cv2.Stitcher's default warper)")
    parser.add_argument("--detector", default=PanoramaFeaturesParams().detector, help="our feature detector")
    parser.add_argument("--refine", choices=REFINEMENTS, default=PanoramaHomographiesParams().refine,
                        help="our global model refinement (default from params)")
    parser.add_argument("--refit-threshold", type=float, default=PanoramaMatchParams().refit_threshold,
                        help="refit each accepted pair on its inliers with this threshold in px, 0 = off "
                             "(default from params)")
    parser.add_argument("--presets", nargs="+", choices=PRESET_CHOICES, default=list(PRESET_CHOICES),
                        help="our presets to time and measure beside cv2.Stitcher (default all); the first one is "
                             "the one the detailed columns describe")
    parser.add_argument("--out", help="folder for the panoramas (ours and OpenCV's) and results.json")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")


def _gt_pairs(folder: Path, files: list[str]) -> dict[tuple[int, int], np.ndarray]:
    """Ground-truth homographies (input position i -> j) of the Adobe files that are in ``files``."""
    import numpy as np

    pos = {int(re.search(r"-(\d+)\.", f).group(1)): k for k, f in enumerate(files)}
    out = {}
    for p in folder.glob("H*to*.txt"):
        ii, jj = (int(v) for v in re.fullmatch(r"H(\d+)to(\d+)\.txt", p.name).groups())
        if ii in pos and jj in pos:
            out[(pos[ii], pos[jj])] = np.loadtxt(p)
    return out


def _accuracy(pano: panorama.Panorama, gt: dict, sizes: list) -> dict:
    """Corner error of every ground-truth pair i -> j, in full-resolution pixels, measured two ways.

    * direct: the pair's own homography from the match graph (estimated from that pair's matches only), i.e. what
      the pairwise stage produced; a ground-truth pair that is not an edge of our graph counts as a failure
      (infinite error) in ``direct_error_median`` (the figure the target is judged on) and is left out of
      ``direct_error_median_matched``; ``direct_or_composed_median`` takes the composed error for those pairs
      instead (what the panorama draws them with), for information;
    * composed: ``G_j^-1 G_i`` from our global homographies (the panorama's geometry), with its median and max,
      the median over adjacent pairs (ii = jj + 1) and the mean error over the ground-truth overlap.
    """
    import numpy as np
    from .. import panorama
    from ..geometry import apply_homography
    from ..metrics import corner_error

    corner, overlap, adjacent, direct, filled = [], [], [], [], []
    graph = pano.graph
    S = {k: panorama.resize_matrix(sizes[k], graph.sizes[k]) for k in range(len(sizes))} if graph else {}
    for (i, j), H_gt in gt.items():
        e = graph.edges.get((min(i, j), max(i, j))) if graph else None
        if e is not None:
            H_work = e.H if e.i == i else np.linalg.inv(e.H)
            direct.append(corner_error(np.linalg.inv(S[j]) @ H_work @ S[i], H_gt, *sizes[i]))
        else:
            direct.append(float("inf"))
        if i not in pano.homographies or j not in pano.homographies:
            filled.append(direct[-1])
            continue
        H = np.linalg.inv(pano.homographies[j]) @ pano.homographies[i]
        err = corner_error(H, H_gt, *sizes[i])
        corner.append(err)
        filled.append(direct[-1] if np.isfinite(direct[-1]) else err)
        if abs(i - j) == 1:
            adjacent.append(err)
        w, h = sizes[i]
        gx, gy = np.meshgrid(np.linspace(0, w - 1, 24), np.linspace(0, h - 1, 24))
        g = np.column_stack([gx.ravel(), gy.ravel()])
        t = apply_homography(H_gt, g)
        inside = (t[:, 0] >= 0) & (t[:, 0] <= sizes[j][0] - 1) & (t[:, 1] >= 0) & (t[:, 1] <= sizes[j][1] - 1)
        if inside.any():
            overlap.append(float(np.linalg.norm(apply_homography(H, g[inside]) - t[inside], axis=1).mean()))
    med = (lambda v: float(np.median(v)) if v else None)
    matched = [d for d in direct if np.isfinite(d)]
    direct_all = med(direct)
    return {"gt_pairs": len(direct), "direct_pairs": len(matched),
            "direct_error_median": direct_all if direct_all is not None and np.isfinite(direct_all) else None,
            "direct_error_median_matched": med(matched), "direct_or_composed_median": med(filled),
            "direct_share_within_2px": float(np.mean(np.array(direct) <= 2.0)) if direct else None,
            "corner_error_median": med(corner), "corner_error_max": max(corner) if corner else None,
            "corner_error_adjacent_median": med(adjacent), "overlap_error_median": med(overlap)}


def pair_error_median(G: dict, gt: dict, sizes: list) -> float | None:
    """Median corner error over the ground-truth pairs i -> j of the pair homographies ``inv(G[j]) @ G[i]``
    composed from per-image homographies ``G`` (ours: ``Panorama.homographies``; cv2.Stitcher's: those its cameras
    imply, :func:`cvpipe.panorama.camera_homographies`), in full-resolution pixels. A pair with an image that the
    stitcher left out counts as a failure (infinite error), for both alike; None without ground truth or when the
    median is a failure."""
    import numpy as np
    from ..metrics import corner_error

    if not gt:
        return None
    errs = [corner_error(np.linalg.inv(G[j]) @ G[i], H, *sizes[i]) if i in G and j in G else float("inf")
            for (i, j), H in gt.items()]
    m = float(np.median(errs))
    return m if np.isfinite(m) else None


def _gt_floor(gt: dict, sizes: list) -> float | None:
    """Median corner error against the ground truth of the consistent set of global homographies fitted to the
    ground-truth pairs themselves (robust least squares on the corner positions): roughly the best the composed
    measure can reach with any single set of global homographies, however good the registration."""
    import numpy as np
    from scipy.optimize import least_squares
    from ..metrics import corner_error

    nodes = sorted({k for ij in gt for k in ij})
    if len(nodes) < 2:
        return None
    ref = nodes[0]
    G = {ref: np.eye(3)}
    grown = True
    while grown:  # chain the ground truth from the first image
        grown = False
        for (i, j), H in gt.items():
            if j in G and i not in G:
                G[i], grown = G[j] @ H, True
            elif i in G and j not in G:
                G[j], grown = G[i] @ np.linalg.inv(H), True
    free = [k for k in nodes if k in G and k != ref]
    pairs = [(i, j, H) for (i, j), H in gt.items() if i in G and j in G]
    corners = {k: np.array([[0, 0, 1], [sizes[k][0] - 1, 0, 1], [sizes[k][0] - 1, sizes[k][1] - 1, 1],
                            [0, sizes[k][1] - 1, 1]], float).T for k in nodes}

    def unpack(x):
        out = {ref: np.eye(3)}
        for n, k in enumerate(free):
            out[k] = np.append(x[8 * n:8 * n + 8], 1.0).reshape(3, 3)
        return out

    def residuals(x):
        Gs = unpack(x)
        r = []
        for i, j, H in pairs:
            for a, b, M in ((i, j, H), (j, i, np.linalg.inv(H))):
                p, q = np.linalg.inv(Gs[b]) @ Gs[a] @ corners[a], M @ corners[a]
                r.append((p[:2] / p[2] - q[:2] / q[2]).ravel())
        return np.concatenate(r)

    x0 = np.concatenate([(G[k] / G[k][2, 2]).ravel()[:8] for k in free])
    x = least_squares(residuals, x0, loss="soft_l1", f_scale=2.0, x_scale="jac").x
    Gs = unpack(x)
    return float(np.median([corner_error(np.linalg.inv(Gs[j]) @ Gs[i], H, *sizes[i]) for i, j, H in pairs]))


def _gt_consistency(gt: dict, sizes: list) -> float | None:
    """Median corner disagreement between a ground-truth pair i -> j and its composition through a third image:
    how far the ground truth itself is from one consistent set of homographies."""
    import numpy as np
    from ..metrics import corner_error

    errs = []
    for (i, j), H in gt.items():
        for (a, k), H1 in gt.items():
            if a == i and (k, j) in gt and k != j:
                errs.append(corner_error(gt[(k, j)] @ H1, H, *sizes[i]))
    return float(np.median(errs)) if errs else None


def seam_colour_difference(pano: np.ndarray, labels: np.ndarray, rows: float = SKY_ROWS,
                           near: tuple[int, int] = (24, 120)) -> dict | None:
    """Colour difference across the seam in the top ``rows`` share of the panorama (its sky, in the sets used).

    Per row, the first place where the source image changes (``labels``, from :func:`cvpipe.panorama.seam_labels`)
    is the seam; the pixels ``near[0]`` to ``near[1]`` px left of it and right of it are the two sides. Returns the
    CIELAB difference of the two sides' mean colours, ``delta_e`` (all of L*a*b*) and ``delta_ab`` (a*, b* only:
    the colour cast, without the brightness step), and the number of rows used; None when no row has a seam with
    both sides covered.
    """
    import cv2
    import numpy as np

    left, right, used = [], [], 0
    for r in range(int(rows * labels.shape[0])):
        lab = labels[r]
        step = np.flatnonzero((lab[:-1] != lab[1:]) & (lab[:-1] >= 0) & (lab[1:] >= 0))
        if not len(step):
            continue
        c = int(step[0]) + 1
        a, b = slice(c - near[1], c - near[0]), slice(c + near[0], c + near[1])
        if c - near[1] < 0 or c + near[1] > lab.size or (lab[a] < 0).any() or (lab[b] < 0).any():
            continue
        left.append(pano[r, a])
        right.append(pano[r, b])
        used += 1
    if not used:
        return None
    mean = [cv2.cvtColor(np.concatenate(x)[None].astype(np.float32) / 255, cv2.COLOR_BGR2Lab)[0].mean(0)
            for x in (left, right)]
    d = mean[0] - mean[1]
    return {"delta_e": float(np.linalg.norm(d)), "delta_ab": float(np.linalg.norm(d[1:])), "rows": used}


def _compare_exposure(w, name: str, out: str | None) -> dict:
    """Every compensator on the same warped images: the seam's colour difference in the sky and the blend time; with
    ``out``, ``<name>_sky_<mode>.jpg`` (the sky around the seam) and ``<name>_sky.png`` (all of them side by side,
    in the order of :data:`cvpipe.panorama.GAIN_CHOICES`)."""
    import numpy as np
    from .. import io, panorama
    from ..panorama import report as pictures

    labels = panorama.seam_labels(w)
    found, crops = {}, []
    for mode in panorama.GAIN_CHOICES:
        t = time.perf_counter()
        pano, _, _ = panorama.compose(w, "multiband", PanoramaBlendParams().bands, mode)
        found[mode] = {"seconds": time.perf_counter() - t, **(seam_colour_difference(pano, labels) or {})}
        if out:
            top = int(SKY_ROWS * labels.shape[0])
            seam = np.flatnonzero(panorama.seam_lines(labels)[:top].any(axis=0))
            c = int(np.median(seam)) if len(seam) else labels.shape[1] // 2
            crop = pano[:top, max(0, c - 2 * top):c + 2 * top]
            io.save_image(Path(out) / f"{name}_sky_{mode}.jpg", crop, 90)
            crops.append(crop)
    if out:
        io.save_image(Path(out) / f"{name}_sky.png", pictures.side_by_side(crops, 240, max_width=2400))
    return found


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _run_command(paths: list[Path], projection: str, out: Path) -> tuple[float, float]:
    """Wall and CPU time (user + system, all threads) of the whole ``cvpipe stitch`` command on ``paths`` in a fresh
    Python process, seconds."""
    cmd = [sys.executable, "-m", "cvpipe.cli", "-q", "stitch", *map(str, paths), "-o", str(out),
           "--projection", projection]
    cpu, t = _children_cpu(), time.perf_counter()
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, check=False)
    seconds, cpu = time.perf_counter() - t, _children_cpu() - cpu
    if done.returncode not in (0, 1):  # 1: no panorama, which the in-process run reports as well
        raise InputError(f"`cvpipe stitch` failed on {paths[0].parent}: {done.stderr.strip()[-300:]}")
    return seconds, cpu


def _run_ours(images, cfg):
    from .. import panorama

    try:
        return panorama.stitch(images, **cfg, rng=0), None
    except EstimationError as exc:
        return None, str(exc)


def run(args: argparse.Namespace) -> int:
    from .. import io, panorama
    from ..panorama import warp as warping

    if not args.data:
        raise InputError("no data root: pass --data DIR or set CVPIPE_DATA")
    if args.repeat < 1:
        raise ValueError(f"`--repeat` must be at least 1, got {args.repeat}")
    root = Path(args.data)
    presets = list(dict.fromkeys(args.presets))
    feats = replace(PanoramaFeaturesParams(), detector=args.detector)
    match = replace(PanoramaMatchParams(), refit_threshold=args.refit_threshold)
    warp = replace(PanoramaWarpParams(), projection=args.projection)
    homs = replace(PanoramaHomographiesParams(), refine=args.refine)
    # the command-line settings are the default preset's; another preset sets its own fields on top of them
    cfgs = {k: panorama.preset_sections(k, features=feats, matching=match, homographies=homs, warp=warp,
                                        blend=PanoramaBlendParams()) for k in presets}
    cfg = cfgs[presets[0]]
    feats = cfg["features"]
    results, first_call = [], None
    for name in args.sets:
        folder, files, must_drop = SETS[name]
        paths = [root / folder / f for f in files]
        if not all(p.exists() for p in paths):
            raise InputError(f"{root / folder}: missing {[p.name for p in paths if not p.exists()]}")
        images = [io.read_image(p, "color") for p in paths]
        sizes = [(im.shape[1], im.shape[0]) for im in images]
        t = time.perf_counter()
        ours, err = _run_ours(images, cfg)  # warm-up run, also the result reported
        if first_call is None:  # the first stitch of this process: OpenCV's initialisation, first allocations
            first_call = {"set": name, "seconds": time.perf_counter() - t}
        others = {k: _run_ours(images, cfgs[k])[0] for k in presets[1:]}  # warm-up runs, also reported

        def cv_run():
            return panorama.opencv_stitch_cameras(images, feats.work_megapix, warp.compose_megapix,
                                                  match.min_confidence, seed=0)

        cv_full = cv_run()
        cv = (cv_full.status, cv_full.pano, cv_full.used)
        t_ours, t_cv, t_cmd, cpu_cv, cpu_cmd = [], [], [], [], []
        t_presets = {k: [] for k in presets[1:]}
        with tempfile.TemporaryDirectory() as tmp:
            _run_command(paths, args.projection, Path(tmp) / "pano.png")  # warm-up: files in the OS page cache
            for _ in range(args.repeat):  # interleaved, so all of them see the same machine load
                t = time.perf_counter()
                _run_ours(images, cfg)
                t_ours.append(time.perf_counter() - t)
                for k in t_presets:
                    t = time.perf_counter()
                    _run_ours(images, cfgs[k])
                    t_presets[k].append(time.perf_counter() - t)
                cpu, t = time.process_time(), time.perf_counter()
                cv_run()
                t_cv.append(time.perf_counter() - t)
                cpu_cv.append(time.process_time() - cpu)
                wall, cpu = _run_command(paths, args.projection, Path(tmp) / "pano.png")
                t_cmd.append(wall)
                cpu_cmd.append(cpu)
        gt = _gt_pairs(root / folder, files) if folder.startswith("adobe") else {}
        row = {"set": name, "images": len(files), "ours_ok": ours is not None, "ours_error": err,
               "opencv_status": cv[0], "opencv_used": [files[k] for k in cv[2]],
               "ours_seconds": statistics.median(t_ours), "opencv_seconds": statistics.median(t_cv),
               "command_seconds": statistics.median(t_cmd), "opencv_cpu_seconds": statistics.median(cpu_cv),
               "command_cpu_seconds": statistics.median(cpu_cmd)}
        row["time_ratio"] = row["ours_seconds"] / row["opencv_seconds"]
        if gt:
            row["opencv_pair_error_median"] = pair_error_median(cv_full.homographies, gt, sizes)
        row["presets"] = {presets[0]: {"seconds": row["ours_seconds"], "time_ratio": row["time_ratio"],
                                       "used": None if ours is None else len(ours.registration.used)}}
        for k, pano_k in others.items():
            sec = statistics.median(t_presets[k])
            row["presets"][k] = {"seconds": sec, "time_ratio": sec / row["opencv_seconds"],
                                 "used": None if pano_k is None else len(pano_k.registration.used)}
        if gt:
            for k, pano_k in {presets[0]: ours, **others}.items():
                if pano_k is not None:
                    acc = _accuracy(pano_k, gt, sizes)
                    row["presets"][k].update(direct_error_median=acc["direct_error_median"],
                                             pair_error_median=pair_error_median(pano_k.homographies, gt, sizes))
        row["command_ratio"] = row["command_seconds"] / row["opencv_seconds"]
        row["command_cpu_ratio"] = row["command_cpu_seconds"] / row["opencv_cpu_seconds"]
        if ours is not None:
            reg = ours.registration
            dropped = {files[k]: why for k, why in reg.dropped}
            row.update(used=[files[k] for k in reg.used], dropped=dropped, model=reg.model,
                       expected_drops_ok=set(dropped) == set(must_drop), size=list(ours.image.shape[1::-1]),
                       empty_share=float(1.0 - ours.mask.mean()), timings=ours.timings)
            comp = panorama.compose_inputs(images, reg, panorama.working_images(images, feats.work_megapix)[1],
                                           warp.compose_megapix)
            w = warping.warp_images(comp.images, comp.G, warp.projection, comp.focal, comp.ref_size,
                                    warp.max_canvas_megapix)
            row["ghosting"] = panorama.overlap_difference(w, panorama.gain_compensation(w))
            if name in EXPOSURE_SETS:
                row["exposure"] = _compare_exposure(w, name, args.out)
            if gt:
                row.update(_accuracy(ours, gt, sizes), gt_self_consistency=_gt_consistency(gt, sizes),
                           gt_consistent_floor=_gt_floor(gt, sizes))
            if args.out:
                io.save_image(Path(args.out) / f"{name}_ours.jpg", ours.image, 90)
        if args.out and cv[1] is not None:
            io.save_image(Path(args.out) / f"{name}_opencv.jpg", cv[1], 90)
        results.append(row)
    summary = {
        "sets": results, "first_call": first_call, "repeat": args.repeat,
        "projection": args.projection, "detector": args.detector, "refine": args.refine,
        "refit_threshold": args.refit_threshold, "presets": presets,
        "work_megapix": feats.work_megapix, "compose_megapix": warp.compose_megapix,
        "all_stitched": all(r["ours_ok"] for r in results),
        "time_ratio_total": sum(r["ours_seconds"] for r in results) / sum(r["opencv_seconds"] for r in results),
        "command_ratio_max": max(r["command_ratio"] for r in results),
        "command_cpu_ratio_max": max(r["command_cpu_ratio"] for r in results),
        "load_average": list(os.getloadavg()),
    }
    adobe = [r for r in results if r.get("corner_error_median") is not None]
    if adobe:
        summary["adobe_corner_error_median"] = {r["set"]: r["corner_error_median"] for r in adobe}
        summary["adobe_direct_error_median"] = {r["set"]: r["direct_error_median"] for r in adobe}
    if args.out:
        io.save_json(Path(args.out) / "results.json", summary)
    if args.json:
        print(io.dumps_json(summary))
        return 0
    print(f"panorama benchmark: projection {args.projection}, detector {args.detector}, registration "
          f"{feats.work_megapix} MP, compose {'full' if warp.compose_megapix <= 0 else warp.compose_megapix} "
          f"resolution, median of {args.repeat} interleaved runs; first stitch of the process "
          f"({first_call['set']}) {first_call['seconds']:.2f} s")
    print(f"{'set':15s} {'ours':>5s} {'cv2':>28s} {'used':>5s} {'direct px':>9s} {'dir/comp':>8s} {'corner px':>9s} "
          f"{'adj px':>7s} "
          f"{'ovl px':>7s} {'empty':>6s} {'ghost':>6s} {'ours s':>7s} {'cv2 s':>6s} {'ratio':>5s} {'cmd s':>6s} "
          f"{'cmd/cv2':>7s} {'cmd cpu':>7s} {'cv2 cpu':>7s} {'cpu/cv2':>7s}")
    fmt = (lambda v, f: "-" if v is None else format(v, f))
    for r in results:
        print(f"{r['set']:15s} {str(r['ours_ok']):>5s} {r['opencv_status'] + ' ' + str(len(r['opencv_used'])):>28s} "
              f"{len(r.get('used', [])):>5d} {fmt(r.get('direct_error_median'), '.2f'):>9s} "
              f"{fmt(r.get('direct_or_composed_median'), '.2f'):>8s} "
              f"{fmt(r.get('corner_error_median'), '.2f'):>9s} "
              f"{fmt(r.get('corner_error_adjacent_median'), '.2f'):>7s} "
              f"{fmt(r.get('overlap_error_median'), '.2f'):>7s} "
              f"{fmt(r.get('empty_share'), '.3f'):>6s} {fmt(r.get('ghosting'), '.2f'):>6s} "
              f"{r['ours_seconds']:7.2f} {r['opencv_seconds']:6.2f} {r['time_ratio']:5.2f} "
              f"{r['command_seconds']:6.2f} {r['command_ratio']:7.2f} {r['command_cpu_seconds']:7.2f} "
              f"{r['opencv_cpu_seconds']:7.2f} {r['command_cpu_ratio']:7.2f}")
        for f, why in r.get("dropped", {}).items():
            print(f"{'':15s} dropped {f}: {why}")
    print("both axes: in-process time / cv2.Stitcher's, and the median corner error over the ground-truth pairs "
          "of the homographies composed from each one's global model (ours) or cameras (cv2.Stitcher), px, an image "
          "left out counting as a failure; in brackets our pairwise stage's own (direct) error")
    head = "".join(f" {k + ' ratio':>14s} {k + ' px':>18s}" for k in presets)
    print(f"{'set':15s}{head} {'cv2 s':>6s} {'cv2 px':>7s}")
    for r in results:
        cells = ""
        for k in presets:
            q = r["presets"][k]
            px = f"{fmt(q.get('pair_error_median'), '.2f')} ({fmt(q.get('direct_error_median'), '.2f')})"
            cells += f" {q['time_ratio']:14.2f} {px:>18s}"
        print(f"{r['set']:15s}{cells} {r['opencv_seconds']:6.2f} {fmt(r.get('opencv_pair_error_median'), '.2f'):>7s}")
    print(f"total time ratio ours / cv2.Stitcher: {summary['time_ratio_total']:.2f}; the `cvpipe stitch` command "
          f"(subprocess, imports included) / cv2.Stitcher in this process: at most "
          f"{summary['command_ratio_max']:.2f} in wall time, {summary['command_cpu_ratio_max']:.2f} in CPU time; load average {' '.join(f'{v:.1f}' for v in summary['load_average'])}")
    for r in results:
        if r.get("exposure"):
            print(f"{r['set']}: colour difference across the seam in the top {SKY_ROWS:.0%} of the rows (CIELAB; "
                  f"delta ab = colour cast without the brightness step)")
            for mode, e in r["exposure"].items():
                print(f"  {mode:15s} delta E {fmt(e.get('delta_e'), '6.2f')}  delta ab {fmt(e.get('delta_ab'), '6.2f')}"
                      f"  blend {e['seconds']:.2f} s")
    return 0

"""The panorama task's results per set: accuracy against optional truth, metrics, report summary and plot rows.

Pure functions on the panorama stages' JSON records (``stages/panorama_*.py``), so the report stage only reads and
writes files. The records per set are:

- ``homographies`` (``panorama_homographies``): ``{"ok", "files", "work_sizes", "full_sizes"}`` plus, when ok,
  :meth:`cvpipe.panorama.Registration.to_json` (``used``, ``dropped`` as input positions); else ``error`` and
  ``failed_in``.
- ``crop`` (``panorama_crop``): ``{"ok", "size": [w, h], "empty_share", ...}`` or ``{"ok": false, "error",
  "failed_in"}`` (a failure of any of our stages travels down to it).
- ``blend`` (``panorama_blend``): ``{"ok", "ghosting", ...}``.
- ``opencv`` (``panorama_opencv_stitcher``): ``{"ok", "status", "files", "used", "full_sizes", "size"}`` and,
  when it registered, ``G`` (input position -> the homography its cameras imply, full resolution).

A set that never reached a stage has no record there (``None``); its reason is in the first stage's drops.
"""

from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from ..datasets import PanoramaSet
from ..metrics import corner_error, not_processed_table
from .features import rescale_homographies

#: the compared methods, in table order
METHODS = ("ours", "opencv_stitcher")
#: what the tables show where a set has no truth
NO_TRUTH = "no ground truth"


def metric_key(name: str) -> str:
    """``name`` usable as one key of DVC's dotted metric paths (dots would add levels)."""
    return name.replace(".", "_")


def median_corner_error(h: dict, truth: Sequence[np.ndarray | None]) -> float | None:
    """Median corner error (full-resolution pixels) of our pairwise homographies between the used images.

    Parameters
    ----------
    h : dict
        The set's ``panorama_homographies`` record (``G`` per used input position at the registration
        resolution, ``work_sizes``, ``full_sizes``, ``reference``).
    truth : sequence of (3, 3) or None
        Per input image (the record's ``files`` order), image -> first truth image pixels; None for an image the
        truth does not know.

    Returns
    -------
    float or None
        Over every pair (p, q) of used images that both have truth, the corner error of our p -> q homography
        (``G[q]^-1 G[p]``) against the true one (``T[q]^-1 T[p]``) at p's full size; None with fewer than two such
        images. ``inf`` when a corner crosses the horizon (see :func:`cvpipe.metrics.corner_error`).
    """
    if not h.get("ok") or len(h["used"]) < 2:
        return None
    used = h["used"]
    G = rescale_homographies([np.array(h["G"][str(a)]) for a in used], [h["work_sizes"][a] for a in used],
                             [h["full_sizes"][a] for a in used], used.index(h["reference"]))
    return pairwise_median_error(dict(zip(used, G)), truth, h["full_sizes"])


def pairwise_median_error(G: dict, truth: Sequence[np.ndarray | None], full_sizes: Sequence) -> float | None:
    """Median corner error of the pairwise homographies ``G[q]^-1 G[p]`` (``G``: input position -> homography to a
    common frame, full-resolution pixels) against the true ones, over every pair of positions in ``G`` that both
    have truth, at p's full size; None with fewer than two such positions."""
    known = [a for a in sorted(G) if truth[a] is not None]
    errs = []
    for i, p in enumerate(known):
        for q in known[i + 1:]:
            est = np.linalg.inv(G[q]) @ G[p]
            true = np.linalg.inv(truth[q]) @ truth[p]
            errs.append(corner_error(est, true, *full_sizes[p]))
    return float(np.median(errs)) if errs else None


def _ours(s: PanoramaSet, h: dict | None, blend: dict | None, crop: dict | None) -> dict:
    files = [f.name for f in s.files]
    row: dict = {"ok": bool(crop and crop.get("ok")), "used_images": 0, "dropped_images": len(files)}
    if h is None:
        row["error"] = "not processed (see the table Not processed)"
        return row
    if h.get("ok"):
        row.update(used_images=len(h["used"]), dropped_images=len(files) - len(h["used"]))
        if s.H is not None:
            truth = [dict(zip(files, s.H)).get(name) for name in h["files"]]
            err = median_corner_error(h, truth)
            if err is not None:
                row["corner_error_px"] = err
    if crop is not None and crop.get("ok"):
        row.update(width=int(crop["size"][0]), height=int(crop["size"][1]), empty_share=crop["empty_share"])
    elif crop is not None or not h.get("ok"):
        failed = crop if crop is not None else h
        row["error"] = f"{failed.get('failed_in', 'panorama')}: {failed.get('error')}"
        row.update(used_images=0, dropped_images=len(files))
    if blend is not None and blend.get("ok"):
        row["ghosting"] = blend["ghosting"]
    return row


def _opencv(s: PanoramaSet, cv: dict | None) -> dict:
    n = len(s.files)
    if cv is None:
        return {"ok": False, "used_images": 0, "dropped_images": n, "error": "not processed"}
    row = {"ok": bool(cv["ok"]), "used_images": len(cv["used"]), "dropped_images": n - len(cv["used"]),
           "status": cv["status"]}
    if cv["ok"]:
        row.update(width=int(cv["size"][0]), height=int(cv["size"][1]), empty_share=cv["empty_share"])
        if s.H is not None and cv.get("G"):
            truth = [dict(zip([f.name for f in s.files], s.H)).get(name) for name in cv["files"]]
            err = pairwise_median_error({int(k): np.array(v) for k, v in cv["G"].items()}, truth, cv["full_sizes"])
            if err is not None:
                row["corner_error_px"] = err
    else:
        row["error"] = f"cv2.Stitcher: {cv['status']}"
    return row


def compare_sets(sets: Sequence[PanoramaSet], homographies: dict, blends: dict, crops: dict,
                 opencv: dict) -> list[dict]:
    """One result per set: ``{"set", "images", "truth": bool, "ours": {...}, "opencv_stitcher": {...}}``.

    Parameters
    ----------
    sets : list of PanoramaSet
        ``cvpipe.datasets.find_panorama`` of the input folder (truth optional).
    homographies, blends, crops, opencv : dict
        Set name -> that stage's record (module docstring); a set missing from a dict never reached the stage.

    Returns
    -------
    list of dict
        Per method: ``ok``, ``used_images``, ``dropped_images`` (the set's images not in the panorama, whatever
        the reason) and, when stitched, ``width``/``height`` (pixels of
        the final panorama: ours cropped, cv2.Stitcher's as returned) and ``empty_share``; both
        ``corner_error_px`` (when the set has truth for two or more used images: cv2.Stitcher's from the homographies
        its cameras imply), ours also ``ghosting``; a failure's ``error``.
    """
    out = []
    for s in sets:
        out.append({"set": s.name, "images": len(s.files), "truth": s.H is not None and
                    sum(h is not None for h in s.H) >= 2,
                    "ours": _ours(s, homographies.get(s.name), blends.get(s.name), crops.get(s.name)),
                    "opencv_stitcher": _opencv(s, opencv.get(s.name))})
    return out


def not_processed(features_dropped: Sequence[dict], homographies: dict, crops: dict, opencv: dict) -> list[dict]:
    """Every input or set that was not processed, with its reason: ``[{"item", "reason"}]``.

    ``features_dropped`` are the first stage's drops (layout, unreadable images, too small sets); then the images
    our registration left out (``<set>/<file>``), the sets one of our stages failed on, and what cv2.Stitcher left
    out or failed on.
    """
    rows = [{"item": d["item"], "reason": d["reason"]} for d in features_dropped]
    for name in sorted(homographies):
        h = homographies[name]
        for d in h.get("dropped", []):
            rows.append({"item": f"{name}/{h['files'][d['image']]}", "reason": f"ours: {d['reason']}"})
        crop = crops.get(name)
        failed = h if not h.get("ok") else crop if crop is not None and not crop.get("ok") else None
        if failed is not None:
            rows.append({"item": name, "reason": f"ours ({failed.get('failed_in', 'panorama')}): {failed['error']}"})
    for name in sorted(opencv):
        cv = opencv[name]
        if not cv["ok"]:
            rows.append({"item": name, "reason": f"cv2.Stitcher: {cv['status']}"})
            continue
        for k, f in enumerate(cv["files"]):
            if k not in cv["used"]:
                rows.append({"item": f"{name}/{f}", "reason": "cv2.Stitcher: left out, it gives no reason"})
    return rows


def metrics_of(results: Sequence[dict]) -> dict:
    """Flat numeric metrics ``{"panorama": {<method>: {"all": {...}, <set>: {...}}}}`` (bool -> int, no strings).

    Per set: ``ok``, ``used_images``, ``dropped_images``, ``width``, ``height`` (when stitched) and
    ``corner_error_px`` (when the set has truth and the error is finite). ``all``: ``sets``, ``ok_sets``,
    ``used_images`` and, with truth, ``median_corner_error_px`` over the sets.
    """
    out = {}
    for method in METHODS:
        per_set, errors = {}, []
        for r in results:
            m = r[method]
            row = {"ok": int(m["ok"]), "used_images": int(m["used_images"]), "dropped_images": int(m["dropped_images"])}
            for key in ("width", "height"):
                if key in m:
                    row[key] = int(m[key])
            err = m.get("corner_error_px")
            if err is not None and np.isfinite(err):
                row["corner_error_px"] = round(float(err), 4)
                errors.append(err)
            per_set[metric_key(r["set"])] = row
        summary = {"sets": len(results), "ok_sets": sum(int(r[method]["ok"]) for r in results),
                   "used_images": sum(int(r[method]["used_images"]) for r in results)}
        if errors:
            summary["median_corner_error_px"] = round(float(np.median(errors)), 4)
        out[method] = {"all": summary, **per_set}
    return {"panorama": out}


def _fmt(v, digits: int = 2):
    return round(float(v), digits) if v is not None else "-"


def report_summary(results: Sequence[dict], pictures: list[dict], dropped: Sequence[dict]) -> dict:
    """The report page's summary of the panorama task (schema in :mod:`cvpipe.report`).

    Parameters
    ----------
    results : list of dict
        :func:`compare_sets` output.
    pictures : list of dict
        ``{"path", "caption"}``, repo-relative paths.
    dropped : list of dict
        :func:`not_processed` output.
    """
    rows = []
    for r in results:
        for method in METHODS:
            m = r[method]
            err = m.get("corner_error_px")
            acc = _fmt(err) if err is not None else (NO_TRUTH if not r["truth"] else "-")
            size = f"{m['width']}x{m['height']}" if "width" in m else "-"
            rows.append([r["set"], method, bool(m["ok"]), f"{m['used_images']} of {r['images']}", size, acc,
                         _fmt(m.get("empty_share"), 4), _fmt(m.get("ghosting")), m.get("error", "")])
    with_truth = [r["set"] for r in results if r["truth"]]
    if not with_truth:
        truth_note = "These sets have no ground truth: the table compares what each method stitched."
    elif len(with_truth) == len(results):
        truth_note = "Every set has true homographies: corner error is the median over pairs of used images."
    else:
        truth_note = (f"Sets with true homographies: {', '.join(with_truth)} (corner error is the median over pairs "
                      "of used images); the others have no ground truth.")
    ok = sum(r["ours"]["ok"] for r in results)
    ok_cv = sum(r["opencv_stitcher"]["ok"] for r in results)
    tables = [{"title": "Per set",
               "columns": ["set", "method", "stitched", "images used", "size (w x h)",
                           "median pairwise corner error px", "empty share", "ghosting (grey levels)", "failure"],
               "rows": rows}]
    tables += not_processed_table(dropped)
    return {
        "task": "panorama",
        "title": "Panorama stitching: ours vs cv2.Stitcher",
        "description": (
            f"Each of the {len(results)} sets is stitched by our pipeline (match graph, spanning-tree chaining, joint "
            "least-squares refinement, gain compensation, multi-band blending, crop; stitched "
            f"{ok} of {len(results)}) and by cv2.Stitcher at the same resolutions (stitched {ok_cv}). {truth_note} "
            "Empty share is measured after our crop (cv2.Stitcher: share of black pixels, it does not crop). "
            "Images and sets that were left out are listed with their reason. Times: `dvc plots show` "
            "(outputs/timings) and `cvpipe bench panorama`."),
        "pictures": pictures,
        "tables": tables,
    }


def quality_plot(results: Sequence[dict]) -> list[dict]:
    """``dvc plots`` rows, one per set and method: ``{"label", "set", "method", "used_images", "stitched",
    "corner_error_px"}``; ``corner_error_px`` is null where it is unknown (no truth, cv2.Stitcher, not finite), so
    that the corner-error plot still finds its field when no set has truth."""
    rows = []
    for r in results:
        for method in METHODS:
            m = r[method]
            row = {"label": f"{r['set']} {method}", "set": r["set"], "method": method,
                   "used_images": int(m["used_images"]), "stitched": int(m["ok"])}
            err = m.get("corner_error_px")
            row["corner_error_px"] = round(float(err), 4) if err is not None and np.isfinite(err) else None
            rows.append(row)
    return rows


def overlay_seams(pano: np.ndarray, seams: np.ndarray, color=(0, 0, 255), width: int = 3) -> np.ndarray:
    """``pano`` with the seam lines drawn over it (``width`` pixels wide) for the report."""
    k = np.ones((width, width), np.uint8)
    thick = cv2.dilate(seams.astype(np.uint8), k) > 0
    out = pano.copy() if pano.ndim == 3 else cv2.cvtColor(pano, cv2.COLOR_GRAY2BGR)
    out[thick] = color
    return out


def side_by_side(images: Sequence[np.ndarray | None], height: int, gap: int = 8,
                 max_width: int = 1200) -> np.ndarray:
    """Images scaled to one ``height`` and put next to each other (a grey box for a missing one), then shrunk
    to at most ``max_width`` pixels wide."""
    tiles = []
    for img in images:
        if img is None:
            tiles.append(np.full((height, height, 3), 64, np.uint8))
            continue
        img = img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        w = max(1, int(round(img.shape[1] * height / img.shape[0])))
        tiles.append(cv2.resize(img, (w, height), interpolation=cv2.INTER_AREA))
        tiles.append(np.full((height, gap, 3), 255, np.uint8))
    out = np.hstack(tiles[:-1] if images and images[-1] is not None else tiles)
    if out.shape[1] > max_width:
        out = cv2.resize(out, (max_width, max(1, int(out.shape[0] * max_width / out.shape[1]))),
                         interpolation=cv2.INTER_AREA)
    return out

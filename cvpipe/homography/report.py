"""Pictures, metrics and the summary of the homography report: alignment panels, per-method corner errors against
the ground truth, and the plots' data. Nothing here estimates a homography."""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError, check_int
from ..metrics import not_processed_table
from ..params import HomographyReportParams

#: the ``homography.report`` defaults: the one declaration of the keyword defaults below
_REPORT = HomographyReportParams()


def alignment_checkerboard(img_a: np.ndarray, img_b: np.ndarray, H_ab, tiles: int = _REPORT.checker_tiles
                           ) -> np.ndarray:
    """B warped into A's frame by ``H_ab`` (A -> B), interleaved with A in a checkerboard to show misalignment.

    Parameters
    ----------
    img_a, img_b : (H, W) or (H, W, 3) uint8
        The two views (gray or BGR).
    H_ab : (3, 3) array_like
        Homography mapping A's pixels to B's.
    tiles : int
        Number of checkerboard squares along the longer side of A.

    Returns
    -------
    (Ha, Wa, 3) uint8 BGR
        Dark squares where the warped B does not cover A. Straight edges that continue across squares mean a
        good alignment; steps at square borders are the residual error.

    Examples
    --------
    >>> import numpy as np
    >>> from cvpipe.homography import alignment_checkerboard
    >>> a = np.zeros((40, 60, 3), np.uint8)
    >>> alignment_checkerboard(a, a + 255, np.eye(3), tiles=2).shape
    (40, 60, 3)
    """
    import cv2

    H = np.asarray(H_ab, dtype=np.float64)
    if H.shape != (3, 3) or not np.isfinite(H).all():
        raise InputError(f"`H_ab` must be a finite (3, 3) array, got shape {H.shape}")
    check_int("tiles", tiles, 1)
    a = img_a if img_a.ndim == 3 else cv2.cvtColor(img_a, cv2.COLOR_GRAY2BGR)
    b = img_b if img_b.ndim == 3 else cv2.cvtColor(img_b, cv2.COLOR_GRAY2BGR)
    h, w = a.shape[:2]
    # sample B at H @ (x, y) for every pixel (x, y) of A
    warped = cv2.warpPerspective(b, H, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    covered = cv2.warpPerspective(np.full(b.shape[:2], 255, np.uint8), H, (w, h),
                                  flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP, borderValue=0) > 0
    side = max(1, int(math.ceil(max(h, w) / tiles)))
    yy, xx = np.mgrid[0:h, 0:w]
    use_b = (((yy // side) + (xx // side)) % 2 == 1) & covered
    out = np.where(use_b[..., None], warped, a)
    out[~covered] = (a[~covered] // 3)
    return out.astype(np.uint8)


def alignment_panel(img_a: np.ndarray, img_b: np.ndarray, panels: dict, tiles: int = _REPORT.checker_tiles,
                    width: int = 400) -> np.ndarray:
    """Side-by-side :func:`alignment_checkerboard` pictures, one per labelled homography.

    Parameters
    ----------
    img_a, img_b : uint8 images
        The two views.
    panels : dict
        Label -> H (A -> B, (3, 3) array_like) or None (drawn as a grey "no result" panel).
    tiles : int
        Checkerboard squares along the longer side.
    width : int
        Width of each panel in pixels (A is resized keeping its aspect ratio).

    Returns
    -------
    (h + 24, width * len(panels), 3) uint8 BGR
        The panels with their labels in a bar above each.
    """
    import cv2

    h = max(1, int(round(img_a.shape[0] * width / img_a.shape[1])))
    cols = []
    for label, H in panels.items():
        if H is None:
            pic = np.full((h, width, 3), 96, np.uint8)
        else:
            pic = cv2.resize(alignment_checkerboard(img_a, img_b, np.asarray(H, float), tiles), (width, h),
                             interpolation=cv2.INTER_AREA)
        bar = np.full((24, width, 3), 255, np.uint8)
        cv2.putText(bar, str(label), (4, 17), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        cols.append(np.vstack([bar, pic]))
    return np.hstack(cols)


def metric_key(name: str) -> str:
    """A pair name as a metrics key: no dots (DVC joins nested keys with dots) and never ``all``."""
    key = str(name).replace(".", "_")
    return "pair_all" if key == "all" else key


def compare_methods(pairs: list[dict], runs: dict, success_px: float = _REPORT.success_px) -> dict:
    """Corner error (pairs with truth), inliers and failures of every method on every matched pair.

    Parameters
    ----------
    pairs : list of dict
        ``{"name", "matches", "size_a": [w, h], "H": (3, 3) true A -> B or None}`` per matched pair.
    runs : dict
        Method -> a ``homography_estimate`` result ``{"pairs": {name: {"H", "inliers", ...}}, "dropped": [...]}``;
        a pair missing from ``pairs`` of a run is a failed estimate.
    success_px : float
        A pair with truth succeeds when its corner error is at most this many pixels.

    Returns
    -------
    dict
        ``methods`` (names), ``pairs`` and ``truth_pairs`` (counts), ``success_px``, ``per_pair`` (name ->
        ``{"matches", "truth": bool, method: {"inliers", "estimated", "corner_error_px" (truth and an estimate),
        "within" (truth)}}``, in the order of ``pairs``) and ``all`` (method -> ``pairs``, ``estimated``,
        ``failures``, ``median_inliers`` (when any estimate) and, when any pair has truth, ``truth_pairs``,
        ``pairs_within``, ``success_rate``, ``median_corner_error_px`` (a failure counts as infinite; omitted when
        infinite) and ``mean_corner_error_px`` (over the successes; omitted without one)).

    Examples
    --------
    >>> import numpy as np
    >>> from cvpipe.homography import compare_methods
    >>> pairs = [{"name": "p", "matches": 50, "size_a": [100, 80], "H": np.eye(3)}]
    >>> runs = {"ours": {"pairs": {"p": {"H": np.eye(3), "inliers": 45}}, "dropped": []}}
    >>> compare_methods(pairs, runs)["all"]["ours"]["success_rate"]
    1.0
    """
    from ..metrics import corner_error

    methods = list(runs)
    per_pair: dict = {}
    for q in pairs:
        row: dict = {"matches": int(q["matches"]), "truth": q.get("H") is not None}
        for m in methods:
            est = runs[m]["pairs"].get(q["name"])
            r: dict = {"inliers": int(est["inliers"]) if est else 0, "estimated": int(est is not None)}
            if row["truth"]:
                w, h = (int(v) for v in q["size_a"])
                err = corner_error(est["H"], q["H"], w, h) if est else math.inf
                if math.isfinite(err):
                    r["corner_error_px"] = float(err)
                r["within"] = int(err <= success_px)
            row[m] = r
        per_pair[q["name"]] = row
    truth_names = [n for n, row in per_pair.items() if row["truth"]]
    summary: dict = {}
    for m in methods:
        rows = [row[m] for row in per_pair.values()]
        inl = [r["inliers"] for r in rows if r["estimated"]]
        s: dict = {"pairs": len(rows), "estimated": len(inl), "failures": len(rows) - len(inl)}
        if inl:
            s["median_inliers"] = float(np.median(inl))
        if truth_names:
            errs = np.array([per_pair[n][m].get("corner_error_px", math.inf) for n in truth_names])
            ok = errs <= success_px
            s.update(truth_pairs=len(errs), pairs_within=int(ok.sum()), success_rate=float(ok.mean()))
            if np.isfinite(np.median(errs)):
                s["median_corner_error_px"] = float(np.median(errs))
            if ok.any():
                s["mean_corner_error_px"] = float(errs[ok].mean())
        summary[m] = s
    return {"methods": methods, "pairs": len(per_pair), "truth_pairs": len(truth_names), "success_px": success_px,
            "per_pair": per_pair, "all": summary}


def metrics_of(compared: dict) -> dict:
    """The numeric metrics of :func:`compare_methods` output: ``{"homography": {method: {"all": {...}, pair: {...}}}}``
    (DVC shows them as ``homography.<method>.<pair>.corner_error_px``)."""
    out: dict = {}
    for m in compared["methods"]:
        out[m] = {"all": dict(compared["all"][m])}
        for name, row in compared["per_pair"].items():
            out[m][metric_key(name)] = {"matches": row["matches"], **row[m]}
    return {"homography": out}


def picture_panels(compared: dict, name: str, true_H, estimates: dict) -> tuple[dict, str]:
    """The labelled panels of one pair's :func:`alignment_panel` and its caption.

    Parameters
    ----------
    compared : dict
        :func:`compare_methods` output.
    name : str
        The pair.
    true_H : (3, 3) array_like or None
        The true homography A -> B, when known (then it is the first panel).
    estimates : dict
        Method -> estimated H A -> B, or None when the method failed on the pair.
    """
    row = compared["per_pair"][name]
    panels: dict = {} if true_H is None else {"truth": true_H}
    for m in compared["methods"]:
        r = row[m]
        if not r["estimated"]:
            label = f"{m}: failed"
        elif "corner_error_px" in r:
            label = f"{m}: {r['corner_error_px']:.2f} px"
        else:
            label = f"{m}: {r['inliers']} inliers"
        panels[label] = estimates.get(m)
    first = "the true homography, then each method" if true_H is not None else "each method (no ground truth)"
    return panels, f"{name}: B warped onto A as a checkerboard, {first}"


def report_summary(compared: dict, pictures: list, dropped: list[dict]) -> dict:
    """The report page's summary of the homography task (schema in ``cvpipe.report``).

    Parameters
    ----------
    compared : dict
        :func:`compare_methods` output.
    pictures : list of dict
        ``{"path", "caption"}`` per pair picture, repo-relative paths.
    dropped : list of dict
        ``{"item", "reason"}`` for every input, pair or estimate that was not processed.
    """
    methods, px = compared["methods"], compared["success_px"]
    none = "no ground truth"
    has_truth = compared["truth_pairs"] > 0

    def r(v, nd=3):
        return None if v is None else round(float(v), nd)

    per_method = []
    for m in methods:
        s = compared["all"][m]
        per_method.append([m, f"{s['estimated']} / {s['pairs']}", r(s.get("median_inliers"), 1),
                           r(s.get("median_corner_error_px")) if has_truth else none,
                           f"{s['pairs_within']} / {s['truth_pairs']}" if has_truth else none])
    rows = []
    for name, row in compared["per_pair"].items():
        errs = [(r(row[m]["corner_error_px"]) if "corner_error_px" in row[m] else "failed") if row["truth"] else none
                for m in methods]
        inl = [row[m]["inliers"] if row[m]["estimated"] else "failed" for m in methods]
        rows.append([name, row["matches"], *errs, *inl])
    tables = [
        {"title": "Per method",
         "columns": ["method", "pairs estimated", "median inliers", "median corner error (px)",
                     f"pairs within {px:g} px"], "rows": per_method},
        {"title": "Per pair",
         "columns": ["pair", "matches", *(f"{m} corner error (px)" for m in methods),
                     *(f"{m} inliers" for m in methods)], "rows": rows},
    ]
    tables += not_processed_table(dropped)
    if has_truth:
        truth_note = (f"{compared['truth_pairs']} of {compared['pairs']} pairs have a true homography: corner error is "
                      "the mean distance of A's four corners mapped by the estimated and the true H, and a pair "
                      f"succeeds within {px:g} px.")
        without = [n for n, row in compared["per_pair"].items() if not row["truth"]]
        if without:
            truth_note += f" Without ground truth (inliers only): {', '.join(without)}."
    else:
        truth_note = ("These pairs have no ground truth: the tables compare the methods by inliers (matches within "
                      "the threshold) and the pictures show each method's alignment.")
    return {
        "task": "homography",
        "title": "Our normalized DLT + LO-RANSAC against OpenCV RANSAC and USAC_MAGSAC, on the same matches",
        "description": (
            "The matches of each pair (A, B) go to every estimator with the same threshold, confidence and "
            f"iteration cap. {truth_note} Pictures: B warped into A's frame as a checkerboard, one panel per "
            "method; misalignment shows as steps at the square borders. Times: `dvc plots show` (outputs/timings) "
            "and `cvpipe bench homography`."),
        "pictures": pictures,
        "tables": tables,
    }


def quality_plots(compared: dict) -> dict[str, list[dict]]:
    """``dvc plots`` rows per file: ``corner_error`` (pairs with truth and an estimate) and ``inliers`` (every pair;
    0 for a failed estimate), each row ``{"pair", "method", "label", <value>}``."""
    corner, inliers = [], []
    for name, row in compared["per_pair"].items():
        for m in compared["methods"]:
            base = {"pair": name, "method": m, "label": f"{name} {m}"}
            inliers.append({**base, "inliers": row[m]["inliers"]})
            if "corner_error_px" in row[m]:
                corner.append({**base, "corner_error_px": row[m]["corner_error_px"]})
    return {"corner_error": corner, "inliers": inliers}

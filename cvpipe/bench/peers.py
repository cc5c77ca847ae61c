"""Ours against each peer, per benchmark: the comparison table, the README headline and the plot.

Each function reads one benchmark's JSON result (as ``python -m cvpipe.bench.record`` writes it) and nothing else,
so BENCHMARKS.md, the plots under ``benchmarks/`` and the README's headline column all come from the same files.
A figure absent from a result shows as ``-``; a result without the figures a headline needs gives ``None``.
"""

from __future__ import annotations

import math
import statistics
from typing import Any, Callable

from . import plots

Table = tuple[list[str], list[list[Any]]]


def _get(d: Any, path: str) -> Any:
    for part in path.split("/"):
        if not isinstance(d, dict) or part not in d:
            return None
        d = d[part]
    return d


def _summary(data: dict) -> dict:
    s = data.get("summary")
    return s if isinstance(s, dict) else data


def _mean(values: list) -> float | None:
    vals = [v for v in values if isinstance(v, (int, float)) and math.isfinite(v)]
    return statistics.fmean(vals) if vals else None


def pct(v: float | None, digits: int = 1) -> str:
    return "-" if v is None else f"{100 * v:.{digits}f} %"


def num(v: float | None, digits: int = 3) -> str:
    return "-" if v is None else f"{v:.{digits}g}"


def ratio(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}x"


# ----------------------------------------------------------------------------------------------------- hough


def hough_table(data: dict) -> Table:
    s = _summary(data)
    n = s.get("images")
    same = f"{s.get('images_identical')}/{n}" if n else "-"
    ms = s.get("ms_median") or {}
    rec = s.get("recall") or {}
    rows = [["ours (standard)", pct(rec.get("ours")), same, num(ms.get("ours")), ratio(s.get("time_ratio_median"))],
            ["cv2.HoughLines", pct(rec.get("opencv")), "-", num(ms.get("opencv")), ratio(1.0)],
            ["ours (probabilistic)", pct(rec.get("ours_prob")), "-", "-", "-"],
            ["cv2.HoughLinesP", pct(rec.get("opencv_prob")), "-", "-", "-"]]
    return (["method", "recall of the true segments", "identical lines to OpenCV's", "median ms per image",
             "time / OpenCV"], rows)


def hough_headline(data: dict) -> str | None:
    s = _summary(data)
    if s.get("images") is None or s.get("time_ratio_median") is None:
        return None
    rec = s.get("recall") or {}
    return (f"York Urban, {s['images']} photos: the same lines as `cv2.HoughLines` on {s.get('images_identical')}/"
            f"{s['images']}, in {ratio(s['time_ratio_median'])} its time; segment recall {pct(rec.get('ours'))} "
            f"(OpenCV {pct(rec.get('opencv'))})")


# ------------------------------------------------------------------------------------------------ homography

HOMOGRAPHY_NAMES = {"ours": "ours (LO-RANSAC)", "opencv_ransac": "cv2 RANSAC", "opencv_magsac": "cv2 USAC_MAGSAC"}


def homography_table(data: dict) -> Table:
    s = data.get("summary") or {}
    magsac = _get(s, "opencv_magsac/median_time_ms")
    px = data.get("success_px", 3.0)
    rows = []
    for m, name in HOMOGRAPHY_NAMES.items():
        r = s.get(m) or {}
        t = r.get("median_time_ms")
        rows.append([name, f"{r.get('pairs_within')}/{r.get('pairs')}" if r else "-",
                     num(r.get("median_corner_error_px")), num(r.get("cmp_median_vpts_error_px")),
                     r.get("pairs_better_than_magsac", "-"), num(t), ratio(t / magsac if t and magsac else None)])
    return (["method", f"pairs within {num(px)} px", "median corner error (px)", "CMP validation-point error (px)",
             "pairs better than MAGSAC", "median ms", "time / MAGSAC"], rows)


def homography_plot(data: dict) -> str | None:
    syn = data.get("synthetic")
    if not isinstance(syn, list) or not syn:
        return None
    series = {name: [(100 * r["outliers"], _get(r, f"methods/{m}/median_corner_error_px")) for r in syn]
              for m, name in HOMOGRAPHY_NAMES.items()}
    return plots.xy_chart(series, "Synthetic 1000 matches: error against outliers", "outliers (%)",
                          "median corner error (px)")


def homography_headline(data: dict) -> str | None:
    s = data.get("summary") or {}
    ours, magsac = s.get("ours"), s.get("opencv_magsac")
    if not ours or not magsac:
        return None
    t, tm = ours.get("median_time_ms"), magsac.get("median_time_ms")
    return (f"Oxford + CMP, {ours['pairs']} pairs: within {num(data.get('success_px', 3.0))} px on "
            f"{ours['pairs_within']} (MAGSAC {magsac['pairs_within']}), median corner error "
            f"{num(ours['median_corner_error_px'])} px (MAGSAC {num(magsac['median_corner_error_px'])}), "
            f"{ratio(t / tm if t and tm else None)} MAGSAC's time")


# ---------------------------------------------------------------------------------------------------- defect

DEFECT_NAMES = {"ours": "ours", "ours_tight_boxes": "ours, unpadded boxes",
                "baseline": "plain registration + difference (the seed's method)"}


def defect_table(data: dict) -> Table:
    methods = data.get("methods") or {}
    rows = [[DEFECT_NAMES.get(m, m), pct(r.get("accuracy")), pct(r.get("faulty_flagged")),
             pct(r.get("false_alarm_rate")), num(r.get("precision")), num(r.get("recall")), num(r.get("f1")),
             num(r.get("median_s_per_probe"))] for m, r in methods.items()]
    return (["method", "verdict accuracy", "faulty flagged", "false alarms on perfect probes", "box precision",
             "box recall", "box F1", "median s per probe"], rows)


def defect_headline(data: dict) -> str | None:
    ours, base = _get(data, "methods/ours"), _get(data, "methods/baseline")
    if not ours:
        return None
    text = (f"DeepPCB, {data.get('probes')} warped probes: verdict accuracy {pct(ours.get('accuracy'))}, "
            f"defect-box F1 {num(ours.get('f1'), 2)}")
    if base:
        text += (f" (plain difference: {pct(base.get('accuracy'))}, F1 {num(base.get('f1'), 2)}); "
                 f"in {ratio(ours['median_s_per_probe'] / base['median_s_per_probe'])} its time"
                 if ours.get("median_s_per_probe") and base.get("median_s_per_probe") else "")
    return text


# ---------------------------------------------------------------------------------------------------- stereo

STEREO_NAMES = {"sgm": "ours (SGM, 8 paths)", "sgm_4path": "ours (SGM, 4 paths)", "sgm_fill": "ours (SGM, filled)",
                "opencv_sgbm": "cv2 SGBM, best mode per pair", "opencv_sgbm_fill": "cv2 SGBM, filled",
                "opencv_bm": "cv2 StereoBM"}


def _stereo_rows(data: dict) -> list[dict]:
    rows = data.get("rows")
    return rows if isinstance(rows, list) else []


def stereo_table(data: dict) -> Table:
    rows = _stereo_rows(data)
    methods = list(dict.fromkeys(r["method"] for r in rows))
    sgbm_total = sum(r["seconds"] or 0 for r in rows if r["method"] == "opencv_sgbm")
    out = []
    for m in methods:
        mine = [r for r in rows if r["method"] == m]
        secs = [r["seconds"] for r in mine if r.get("seconds") is not None]
        total = sum(secs) if len(secs) == len(mine) else None
        out.append([STEREO_NAMES.get(m, m), len(mine), pct(_mean([r.get("bad_2.0") for r in mine])),
                    pct(_mean([r.get("bad_1.0") for r in mine])), num(_mean([r.get("mean_error") for r in mine])),
                    pct(_mean([r.get("density") for r in mine])), num(total),
                    ratio(total / sgbm_total if total is not None and sgbm_total else None)])
    return (["method", "pairs", "mean bad-2.0", "mean bad-1.0", "mean abs. error (px)", "mean density",
             "total s (median per pair)", "time / SGBM"], out)


def stereo_plot(data: dict) -> str | None:
    rows = _stereo_rows(data)
    pairs = list(dict.fromkeys(r["pair"] for r in rows))
    if not pairs:
        return None
    series = {}
    for m, label in (("sgm", "ours (SGM)"), ("opencv_sgbm", "cv2 SGBM"), ("opencv_bm", "cv2 StereoBM")):
        by = {r["pair"]: r.get("bad_2.0") for r in rows if r["method"] == m}
        if by:
            series[label] = [None if by.get(p) is None else 100 * by[p] for p in pairs]
    return plots.bar_chart(pairs, series, "bad-2.0 per pair (lower is better)", "bad-2.0 (%)")


def stereo_headline(data: dict, rectify: dict | None = None) -> str | None:
    rows = _stereo_rows(data)
    sgm = {r["pair"]: r for r in rows if r["method"] == "sgm"}
    sgbm = {r["pair"]: r for r in rows if r["method"] == "opencv_sgbm"}
    if not sgm or not sgbm:
        return None
    better = sum(sgm[p]["bad_2.0"] <= sgbm[p]["bad_2.0"] for p in sgm if p in sgbm)
    t = sum(r["seconds"] for r in sgm.values()) / sum(r["seconds"] for r in sgbm.values())
    ours, peer = (pct(_mean([r["bad_2.0"] for r in d.values()])) for d in (sgm, sgbm))
    text = (f"Middlebury + motorcycle, {len(sgm)} pairs: mean bad-2.0 {ours} (best-mode SGBM {peer}), lower or "
            f"equal on {better}/{len(sgm)}, in {ratio(t)} its time")
    if rectify:
        v = _get(rectify, "summary/mean_vertical_median_px")
        if isinstance(v, dict) and v.get("ours") is not None:
            text += (f"; rectification: vertical error {num(v['ours'], 2)} px (OpenCV {num(v.get('opencv'), 2)}) "
                     f"over {len(_stereo_rows(rectify))} draws")
    return text


# -------------------------------------------------------------------------------------------- stereo_rectify


def stereo_rectify_table(data: dict) -> Table:
    rows = _stereo_rows(data)
    out = []
    for m, name in (("ours", "ours (7-point RANSAC, Hartley + Loop-Zhang)"),
                    ("opencv", "cv2 MAGSAC F + stereoRectifyUncalibrated"),
                    ("truth_ls", "noise floor: least-squares F of the true inliers")):
        secs = [r.get(f"seconds_{m}") for r in rows if r.get(f"seconds_{m}") is not None]
        out.append([name, len(rows), num(_mean([r.get(f"vertical_median_px_{m}") for r in rows])),
                    num(_mean([r.get(f"vertical_p95_px_{m}") for r in rows])),
                    num(statistics.median(secs)) if secs else "-"])
    return (["method", "draws", "mean of the median vertical error (px)", "mean p95 vertical error (px)",
             "median s"], out)


# ----------------------------------------------------------------------------------------------------- scale


def scale_table(data: dict) -> Table:
    rows = data.get("rows") if isinstance(data.get("rows"), list) else []
    out = [[r.get("mode"), r.get("probes"), num(r.get("probes_per_s")), ratio(r.get("speedup_vs_serial")),
            ratio(r.get("speedup_vs_local1")), num(r.get("peak_rss_mb")), r.get("identical_results", "-"),
            r.get("error", "-")] for r in rows]
    return (["mode", "probes", "probes/s", "x serial", "x local1", "peak MB", "same results as serial", "error"],
            out)


def scale_plot(data: dict) -> str | None:
    rows = [r for r in data.get("rows") or [] if "probes_per_s" in r]
    if not rows:
        return None
    modes = list(dict.fromkeys(r["mode"] for r in rows))
    sizes = sorted({r["probes"] for r in rows})
    series = {f"{n} probes": [next((r["probes_per_s"] for r in rows if r["mode"] == m and r["probes"] == n), None)
                              for m in modes] for n in sizes}
    return plots.bar_chart(modes, series, "Inspection throughput per mode", "probes / s")


# ------------------------------------------------------------------------------------------------------ logo


def _logo_methods(data: dict) -> dict:
    m = data.get("methods")
    return m if isinstance(m, dict) else {}


def logo_table(data: dict) -> Table:
    rows = []
    for m, ev in _logo_methods(data).items():
        rows.append([m, num(ev.get("precision")), num(ev.get("recall")), num(ev.get("accuracy")),
                     num(ev.get("best_recall_at_precision_0.95")), num(ev.get("best_precision_at_recall_0.70")),
                     num(ev.get("time_per_scene_median_s"))])
    return (["method", "precision", "recall", "accuracy", "recall at precision >= 0.95",
             "precision at recall >= 0.70", "median s per scene"], rows)


def logo_plot(data: dict) -> str | None:
    series = {}
    for m, ev in _logo_methods(data).items():
        curve = ev.get("curve")
        if isinstance(curve, list) and curve:
            # in the order of the swept threshold, high to low: recall grows along the curve
            ordered = sorted(curve, key=lambda c: -(c.get("threshold") or 0.0))
            series[m] = [(c.get("recall"), c.get("precision")) for c in ordered]
    if not series:
        return None
    return plots.xy_chart(series, "Precision against recall (score threshold swept)", "recall", "precision",
                          x_range=(0.0, 1.0), y_range=(0.0, 1.0))


def _best_logo(data: dict) -> tuple[str, dict] | None:
    methods = _logo_methods(data)
    scored = [(m, ev) for m, ev in methods.items() if ev.get("accuracy") is not None]
    return max(scored, key=lambda x: x[1]["accuracy"]) if scored else None


def logo_headline(data: dict) -> str | None:
    best = _best_logo(data)
    if best is None:
        return None
    m, ev = best
    scenes = _get(data, "protocol/test_scenes")
    singles = [(k, v) for k, v in _logo_methods(data).items() if k != m and v.get("accuracy") is not None]
    text = (f"FlickrLogos-27 subset, {scenes} test photos: {m} accuracy {num(ev['accuracy'], 2)}, recall "
            f"{num(ev.get('best_recall_at_precision_0.95'), 2)} at precision >= 0.95")
    if singles:
        k, v = max(singles, key=lambda x: x[1]["accuracy"])
        text += f" (next best, {k}: accuracy {num(v['accuracy'], 2)}); no external peer in the run"
    return text


# -------------------------------------------------------------------------------------------------- panorama

#: keys of cv2.Stitcher's accuracy in a panorama set record (the pair error of the homographies its cameras imply)
OPENCV_ERROR_KEYS = ("opencv_pair_error_median", "opencv_corner_error_median")


def _sets(data: dict) -> list[dict]:
    s = data.get("sets", _get(data, "summary/sets"))
    return s if isinstance(s, list) else []


def _presets(data: dict) -> list[str]:
    """Our presets measured, the default (the one the detailed columns describe) first; ``[""]`` for a result
    from before presets (one configuration, its figures at the set record's top level)."""
    p = data.get("presets", _get(data, "summary/presets"))
    return list(p) if isinstance(p, list) and p else [""]


def _ours(r: dict, preset: str) -> dict:
    """Seconds, time ratio and ground-truth pair error (None without ground truth) of our ``preset`` on set ``r``."""
    q = _get(r, f"presets/{preset}") if preset else None
    if isinstance(q, dict):
        return {"seconds": q.get("seconds"), "time_ratio": q.get("time_ratio"), "used": q.get("used"),
                "error": q.get("pair_error_median")}
    used = r.get("used")
    return {"seconds": r.get("ours_seconds"), "time_ratio": r.get("time_ratio"),
            "used": len(used) if isinstance(used, list) else None, "error": r.get("corner_error_median")}


def _opencv_error(r: dict) -> float | None:
    return next((r[k] for k in OPENCV_ERROR_KEYS if r.get(k) is not None), None)


def _ours_name(preset: str) -> str:
    return f"ours ({preset})" if preset else "ours"


def panorama_table(data: dict) -> Table:
    presets = _presets(data)
    header = ["set", "images", "cv2.Stitcher status"]
    for k in presets:
        header += [f"{_ours_name(k)} error (px)", f"{_ours_name(k)} s", f"{_ours_name(k)} / OpenCV time"]
    header += ["cv2.Stitcher error (px)", "cv2.Stitcher s"]
    rows = []
    for r in _sets(data):
        row = [r.get("set"), r.get("images"), r.get("opencv_status")]
        for k in presets:
            q = _ours(r, k)
            row += [num(q["error"]), num(q["seconds"]), ratio(q["time_ratio"])]
        rows.append(row + [num(_opencv_error(r)), num(r.get("opencv_seconds"))])
    return header, rows


def panorama_plot(data: dict) -> str | None:
    sets = _sets(data)
    series = {_ours_name(k): [(_ours(r, k)["seconds"], _ours(r, k)["error"]) for r in sets
                              if _ours(r, k)["error"] is not None] for k in _presets(data)}
    series["cv2.Stitcher"] = [(r.get("opencv_seconds"), _opencv_error(r)) for r in sets
                              if _opencv_error(r) is not None]
    series = {k: v for k, v in series.items() if v}
    if not series:
        return None
    return plots.xy_chart(series, "Sets with ground truth: error against time", "seconds per panorama",
                          "median corner error (px)", lines=False)


def panorama_headline(data: dict) -> str | None:
    sets = _sets(data)
    if not sets:
        return None
    preset = _presets(data)[0]
    ours = [_ours(r, preset) for r in sets]
    ok = sum(bool(r.get("ours_ok")) for r in sets)
    cv_ok = sum(r.get("opencv_status") == "OK" for r in sets)
    text = f"Adobe + OpenStitching, {len(sets)} sets: ours stitched {ok}, `cv2.Stitcher` {cv_ok}"
    gt = [(q["error"], _opencv_error(r)) for q, r in zip(ours, sets) if q["error"] is not None]
    if gt:
        text += f"; median corner error {num(_mean([e for e, _ in gt]), 2)} px over {len(gt)} sets with ground truth"
        cv = [c for _, c in gt if c is not None]
        if cv:
            text += f" (OpenCV {num(_mean(cv), 2)} px)"
    secs = [(q["seconds"], r.get("opencv_seconds")) for q, r in zip(ours, sets)]
    if secs and all(a is not None and b for a, b in secs):
        text += f"; in {ratio(sum(a for a, _ in secs) / sum(b for _, b in secs))} its time"
    return text


# ----------------------------------------------------------------------------------------------------- table

#: benchmark -> (comparison table, plot or None)
SECTIONS: dict[str, tuple[Callable[[dict], Table], Callable[[dict], str | None] | None]] = {
    "hough": (hough_table, None),
    "homography": (homography_table, homography_plot),
    "defect": (defect_table, None),
    "logo": (logo_table, logo_plot),
    "logo_loo": (logo_table, logo_plot),
    "stereo": (stereo_table, stereo_plot),
    "stereo_rectify": (stereo_rectify_table, None),
    "panorama": (panorama_table, panorama_plot),
    "scale": (scale_table, scale_plot),
}

#: README task -> the benchmark(s) its headline reads (the first is required)
HEADLINES: dict[str, tuple[str, ...]] = {
    "logo": ("logo",), "hough": ("hough",), "defect": ("defect",), "homography": ("homography",),
    "stereo": ("stereo", "stereo_rectify"), "panorama": ("panorama",),
}

NOT_MEASURED = "not measured yet (`make benchmarks`)"


def headline(task: str, results: dict[str, Any]) -> str:
    """The README cell of ``task``: ours against the best peer, from ``results`` (benchmark name -> JSON or None)."""
    names = HEADLINES[task]
    data = results.get(names[0])
    if not isinstance(data, dict):
        return NOT_MEASURED
    if task == "stereo":
        text = stereo_headline(data, results.get("stereo_rectify"))
    else:
        text = {"logo": logo_headline, "hough": hough_headline, "defect": defect_headline,
                "homography": homography_headline, "panorama": panorama_headline}[task](data)
    return (text or NOT_MEASURED).replace("|", "\\|")

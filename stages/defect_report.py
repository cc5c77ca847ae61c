"""Stage `defect_report`: overlays (regions red, truth green), heat maps, metrics against truth, summary.json.

Also times the whole inspection of each probe (ours) and the seed's plain difference, in this process, interleaved.
"""

import argparse
import statistics
import time
from pathlib import Path

import cv2
import numpy as np

from cvpipe import defects, io
from cvpipe.bench.defect import seed_method
from cvpipe.errors import CvpipeError
from cvpipe.features import detect
from cvpipe.metrics import corner_error


def montage(images: list, cols: int, width: int = 1200) -> np.ndarray:
    """Tiles of equal size in a grid ``width`` pixels wide."""
    side = width // cols
    tiles = [cv2.resize(im, (side, side), interpolation=cv2.INTER_AREA) for im in images]
    tiles += [np.zeros_like(tiles[0])] * (-len(tiles) % cols)
    return np.vstack([np.hstack(tiles[i:i + cols]) for i in range(0, len(tiles), cols)])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--images", required=True, help="data/samples/defect")
    ap.add_argument("--results", required=True, help="outputs/defect/results.json")
    ap.add_argument("--registration", required=True)
    ap.add_argument("--diff", required=True)
    ap.add_argument("--out", required=True, help="outputs/defect")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    images, out = Path(args.images), Path(args.out)
    truth = io.load_json(images / "truth.json")["probes"]
    results = {r["probe"]: r for r in io.load_json(args.results)}
    registration = io.load_json(args.registration)
    ref = io.read_image(images / "reference.png", "color")
    ref_gray = io.to_gray(ref)
    params = defects.load_inspect_params(args.params)
    ref_feats = detect(ref_gray, params.features.detector, params.features.max_features)
    ref_sift = detect(ref_gray, "sift", 4000)  # the seed's registration features
    overlays, heats, seed_records, times, reg_err = [], [], [], {"ours": [], "seed": []}, []
    for t in truth:
        io.safe_name(t["file"], "truth.json: probe file")
        probe = io.read_image(images / "probes" / t["file"], "color")
        r = results[t["file"]]
        over = defects.draw_regions(probe, r["regions"], t["boxes"])
        cv2.putText(over, f"{t['file']}: {r['verdict'] or 'error'} (truth {t['verdict']})", (8, 24),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2, cv2.LINE_AA)
        overlays.append(over)
        io.save_image(out / "overlays" / t["file"], over)
        if r["verdict"] is not None:
            heats.append(defects.heat_map(io.load_npz(Path(args.diff) / f"{Path(t['file']).stem}.npz")["diff"],
                                          r["threshold"]))
            reg_err.append(corner_error(r["H"], t["H"], ref.shape[1], ref.shape[0]))
        gray = io.to_gray(probe)
        for name, fn in (("ours", lambda: defects.inspect(ref_gray, gray, params, reference_features=ref_feats)),
                         ("seed", lambda: seed_method(ref_gray, gray, ref_sift))):
            t0 = time.perf_counter()
            try:
                res = fn()
            except CvpipeError:
                res = None
            times[name].append(time.perf_counter() - t0)
            if name == "seed":
                seed_records.append({"probe": t["file"], "verdict": None if res is None else
                                     ("faulty" if len(res) else "perfect"), "regions": [] if res is None else res})
    ours, seed = defects.evaluate(list(results.values()), truth), defects.evaluate(seed_records, truth)
    ours["registration_corner_error_px"] = {"median": statistics.median(reg_err), "max": max(reg_err)}
    ours["direct_registrations"] = sum(v.get("method") == "direct" for v in registration.values())
    timings = {k: statistics.median(v) for k, v in times.items()}
    io.save_json(out / "metrics.json", {"ours": ours, "seed": seed, "median_seconds_per_probe": timings})
    io.save_image(out / "overlays.png", montage(overlays, 5))
    io.save_image(out / "heatmaps.png", montage(heats, 5))
    io.save_json(out / "plots" / "scores.json", [{"probe": t["file"], "score": results[t["file"]]["score"] or 0.0,
                                                  "truth": t["verdict"]} for t in truth])
    io.save_json(out / "plots" / "timings.json", [{"method": k, "seconds": v} for k, v in timings.items()])
    cols = ["method", "accuracy", "faulty flagged", "false alarms", "precision", "recall", "F1", "s/probe"]
    rows = [[k, m["accuracy"], m["faulty_flagged"], m["false_alarm_rate"], m["precision"], m["recall"], m["f1"],
             timings[k]] for k, m in (("ours", ours), ("seed", seed))]
    io.save_json(out / "summary.json", {
        "task": "defect", "title": "Defect inspection against a golden reference",
        "description": "Each probe is registered to the golden board (ORB + RANSAC homography, ECC refinement), "
                       "corrected for gain and bias and compared with a difference that tolerates a few pixels of "
                       "misregistration. Red boxes are found defects, green boxes the inserted ones; the seed's "
                       "plain difference flags every probe.",
        "pictures": [{"path": str(out / "overlays.png"), "caption": "probes with found regions (red) and truth "
                      "(green)"}, {"path": str(out / "heatmaps.png"), "caption": "tolerant difference, in the "
                      "reference frame (the colour scale saturates at twice the threshold)"}],
        "tables": [{"title": f"sample probes, defect-level scores at IoU >= {ours['iou']}", "columns": cols,
                    "rows": rows}],
        "timings": timings})


if __name__ == "__main__":
    main()

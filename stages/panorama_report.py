"""Stage `panorama_report`: ours vs cv2.Stitcher side by side, our seams, metrics.json, plots and summary.json."""

import argparse
from pathlib import Path

import numpy as np

from cvpipe import blending, io, panorama
from cvpipe.metrics import corner_error


def _corner_error(h: dict, truth: dict) -> float | None:
    """Median corner error (full-resolution pixels) of our pairwise homographies between the used images against
    the truth (``truth["H"][i]`` maps image i to image 0, so image a -> b is ``H[b]^-1 H[a]``)."""
    if not h["ok"] or len(h["used"]) < 2:
        return None
    used = h["used"]
    G = panorama.rescale_homographies([np.array(h["G"][str(a)]) for a in used], [h["work_sizes"][a] for a in used],
                                      [h["full_sizes"][a] for a in used], used.index(h["reference"]))
    T = [np.array(truth["H"][a]) for a in used]
    errs = []
    for p in range(len(used)):
        for q in range(p + 1, len(used)):
            ours, true = np.linalg.inv(G[q]) @ G[p], np.linalg.inv(T[q]) @ T[p]
            errs.append(corner_error(ours, true, *h["full_sizes"][used[p]]))
    return float(np.median(errs))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    for name in ("truth", "homographies", "blend", "crop", "opencv"):
        ap.add_argument(f"--{name}", required=True)
    ap.add_argument("--out", required=True, help="outputs/panorama: writes summary.json, metrics.json, plots/, report/")
    args = ap.parse_args()
    out, rows, pictures, plot, timings = Path(args.out), [], [], [], {"ours": 0.0, "opencv_stitcher": 0.0}
    truth = {s["name"]: s for s in io.load_json(args.truth)["sets"]}
    for name in sorted(truth):
        h = io.load_json(Path(args.homographies) / f"{name}.json")
        b, c = io.load_json(Path(args.blend) / f"{name}.json"), io.load_json(Path(args.crop) / f"{name}.json")
        cv = io.load_json(Path(args.opencv) / f"{name}.json")
        ours_img = io.read_image(Path(args.crop) / f"{name}.png") if c["ok"] else None
        cv_img = io.read_image(Path(args.opencv) / f"{name}.png") if cv["ok"] else None
        io.save_image(out / "report" / f"{name}_side_by_side.png", blending.side_by_side([ours_img, cv_img], 300))
        pictures.append({"path": str(out / "report" / f"{name}_side_by_side.png"),
                         "caption": f"{name}: ours (left, cropped) vs cv2.Stitcher (right, {cv['status']})"})
        if b["ok"]:
            seams = io.read_image(Path(args.blend) / f"{name}_seams.png", "gray") > 0
            over = blending.overlay_seams(io.read_image(Path(args.blend) / f"{name}.png"), seams)
            io.save_image(out / "report" / f"{name}_seams.png", blending.side_by_side([over], over.shape[0]))
            pictures.append({"path": str(out / "report" / f"{name}_seams.png"),
                             "caption": f"{name}: our seam lines (red)"})
        seconds = h["seconds"] + sum(x.get("seconds", 0.0) for x in (b, c))
        dropped = "; ".join(f"{d['image']}: {d['reason']}" for d in h.get("dropped", []))
        rows.append([name, "ours", c["ok"], len(h.get("used", [])), dropped or "-", _corner_error(h, truth[name]),
                     c.get("empty_share"), b.get("ghosting"), seconds])
        cv_empty = float((cv_img == 0).all(axis=2).mean()) if cv_img is not None else None
        rows.append([name, "opencv_stitcher", cv["ok"], len(cv["used"]), "-", None, cv_empty, None, cv["seconds"]])
        timings["ours"] += seconds
        timings["opencv_stitcher"] += cv["seconds"]
        plot += [{"label": f"{name} ours", "set": name, "method": "ours", "seconds": seconds},
                 {"label": f"{name} cv2.Stitcher", "set": name, "method": "opencv_stitcher", "seconds": cv["seconds"]}]
    columns = ["set", "method", "stitched", "images used", "dropped (why)", "median pairwise corner error px",
               "empty share", "ghosting (grey levels)", "seconds"]
    io.save_json(out / "metrics.json", {"rows": [dict(zip(columns, r)) for r in rows]})
    io.save_json(out / "plots" / "times.json", plot)
    io.save_json(out / "summary.json", {
        "task": "panorama", "title": "Panorama stitching: ours vs cv2.Stitcher on the sample sets",
        "description": ("Each sample set is stitched by our pipeline (match graph, spanning-tree chaining, joint "
                        "least-squares refinement, gain compensation, multi-band blending, crop) and by cv2.Stitcher "
                        "at the same resolutions. Corner error is against the true homographies; empty share is "
                        "measured after our crop (cv2.Stitcher: share of black pixels, it does not crop)."),
        "pictures": pictures, "tables": [{"title": "per set", "columns": columns, "rows": rows}],
        "timings": timings})


if __name__ == "__main__":
    main()

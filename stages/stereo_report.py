"""Stage `stereo_report`: per pair the rectification picture (before / after, epipolar lines of a few matches), the
depth picture (pairs with a calibration) and one picture of the methods side by side in the rectified frame (and,
for pairs with a truth.npz in that frame, the true disparity and each method's error map), the comparison tables and
the quality plots (bad-2.0 where there is truth, the valid fraction for every pair, the vertical error)."""

from pathlib import Path

from cvpipe import datasets, io, stereo
from ._runner import REPORT_ARGS, Stage, run


def stereo_report(st: Stage) -> None:
    p, a = st.params, st.args
    rectified, depth_dir = Path(a.rectified), Path(a.depth)
    rect_run, depth_run = io.load_json(rectified / "run.json"), io.load_json(depth_dir / "run.json")
    rects = rect_run["pairs"]
    pairs, _ = datasets.find_stereo(a.pairs)  # what it drops, stereo_rectify recorded
    runs = {}
    for folder in a.disparities:
        r = io.load_json(Path(folder) / "run.json")
        runs[r["method"]] = {**r, "folder": Path(folder)}
    out, pictures, extra = Path(a.out), [], []
    for pair in st.progress([q for q in pairs if q.name in rects], "stereo pictures"):
        rec, here = rects[pair.name], rectified / pair.name
        left, right = io.read_image(here / "left.png"), io.read_image(here / "right.png")
        m = io.load_npz(here / "matches.npz", ("left", "right"))
        path = out / f"{pair.name}_rectified.png"
        io.save_picture(path, stereo.rectification_picture(
            io.read_image(pair.left), io.read_image(pair.right), left, right, rec["H_left"], rec["H_right"],
            m["left"], m["right"]))
        err = rec.get("vertical_error_median_px")
        extra.append({"path": path.as_posix(), "caption": (
            f"{pair.name}: rectification {rec['kind']}; vertical error median "
            f"{'n/a' if err is None else f'{err:.2f}'} px over {rec['vertical_error_over']} (top: original, "
            "bottom: rectified; a match's right point should lie on its line)")})
        if pair.name in depth_run["pairs"]:
            z = io.load_npy(depth_dir / pair.name / "depth.npy", "depth")
            unit = depth_run["units"][pair.name]
            path = out / f"{pair.name}_depth.png"
            io.save_picture(path, stereo.depth_picture(left, z, unit))
            extra.append({"path": path.as_posix(), "caption": (
                f"{pair.name}: depth in {unit} from {depth_run['method']} (black = no depth); point cloud "
                f"{(depth_dir / pair.name / 'cloud.ply').as_posix()}")})
        if not any(pair.name in r["pairs"] for r in runs.values()):
            continue
        max_disp = next(r["pairs"][pair.name]["max_disp"] for r in runs.values() if pair.name in r["pairs"])
        disps = {m: (io.load_npy(r["folder"] / pair.name / "disparity.npy", "disparity")
                     if pair.name in r["pairs"] else None) for m, r in runs.items()}
        in_frame = pair.truth is not None and rec["kind"] == "none"
        truth = datasets.read_stereo_truth(pair.truth, left.shape[:2]) if in_frame else None
        path = out / f"{pair.name}.png"
        io.save_picture(path, stereo.comparison_picture(left, disps, max_disp, truth, p.error_clip))
        what = "top: left image and each method's disparity; bottom: true disparity and each method's |error|" \
            if truth is not None else "left image and each method's disparity (no ground truth" + \
            (" in the rectified frame)" if pair.truth is not None else ")")
        pictures.append({"path": path.as_posix(), "caption": f"{pair.name} (max_disp {max_disp}): {what}"})
    dropped = rect_run["dropped"] + stereo.merge_dropped(runs) + depth_run["dropped"]
    summary = stereo.report_summary(runs, pictures, dropped, p.error_clip)
    with_truth = tuple(q.name for q in pairs if q.truth is not None)
    plots = {**stereo.quality_plots(runs), "vertical_error": stereo.vertical_error_plot(rects)}
    st.write_report(stereo.extend_summary(summary, rects, depth_run, extra, with_truth), None, plots, dropped)
    st.made(f"{len(pictures)} pairs compared over {len(runs)} methods, pictures in {out}")


if __name__ == "__main__":
    run(stereo_report, section="stereo.report",
        args={"pairs": "the stereo.data folder", "rectified": "stereo_rectify's output folder",
              "disparities": "+stereo_disparity output folders, one per method", "depth": "stereo_depth's folder",
              "out": "folder for the pictures", **{k: v for k, v in REPORT_ARGS.items() if k != "metrics"}})

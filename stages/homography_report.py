"""Stage `homography_report`: corner error against the truth (pairs that have one), inliers and failures per method,
one picture per pair (B warped onto A as a checkerboard: the truth, then each method), metrics (git-tracked) and the
quality plots."""

from pathlib import Path

from cvpipe import datasets, homography, io
from ._runner import REPORT_ARGS, Stage, run


def homography_report(st: Stage) -> None:
    p, a = st.params, st.args
    pairs, _ = datasets.find_homography(a.images)  # what it drops, homography_match recorded
    dropped = list(io.load_json(Path(a.matches) / "dropped.json"))
    runs = {}
    for folder in a.estimates:
        est = io.load_json(Path(folder) / "estimates.json")
        runs[est["method"]] = est
        dropped += [{"item": f"{d['item']} ({est['method']})", "reason": d["reason"]} for d in est["dropped"]]
    matched = []
    for q in pairs:
        f = Path(a.matches) / f"{q.name}.npz"
        if f.is_file():
            m = io.load_npz(f, ("src", "size_a"))
            matched.append({"name": q.name, "matches": len(m["src"]), "size_a": m["size_a"].tolist(), "H": q.H})
    compared = homography.compare_methods(matched, runs, p.success_px)
    out, pictures = Path(a.out), []
    for q in st.progress([q for q in pairs if q.name in compared["per_pair"]], "homography pictures"):
        img_a, img_b = io.read_image(q.a, "color"), io.read_image(q.b, "color")
        estimates = {m: (r["pairs"][q.name]["H"] if q.name in r["pairs"] else None) for m, r in runs.items()}
        panels, caption = homography.picture_panels(compared, q.name, q.H, estimates)
        path = out / f"{q.name}.png"
        io.save_picture(path, homography.alignment_panel(img_a, img_b, panels, p.checker_tiles))
        pictures.append({"path": path.as_posix(), "caption": caption})
    st.write_report(homography.report_summary(compared, pictures, dropped), homography.metrics_of(compared),
                    homography.quality_plots(compared), dropped)
    st.made(f"{compared['pairs']} pairs compared ({compared['truth_pairs']} with ground truth), "
            f"{len(pictures)} pictures in {out}")


if __name__ == "__main__":
    run(homography_report, section="homography.report",
        args={"images": "the homography.data folder", "matches": "homography_match output (its dropped.json)",
              "estimates": "+homography_estimate output folders, one per method", "out": "folder for the pictures",
              **REPORT_ARGS})

"""Stage `panorama_report`: ours vs cv2.Stitcher side by side, our seams, the accuracy against the truth where the
folder has a truth.json, what was not processed and why, metrics (git-tracked) and a quality plot."""

from pathlib import Path

from cvpipe import datasets, io
from cvpipe.panorama import report as pr
from ._runner import Stage, run

#: height in pixels of the report's side-by-side pictures
PICTURE_HEIGHT = 300


def _records(folder: str, names: list[str], suffix: str = ".json") -> dict:
    """Set name -> that stage's JSON record, for the sets that reached the stage."""
    return {n: io.load_json(Path(folder) / f"{n}{suffix}") for n in names if (Path(folder) / f"{n}{suffix}").is_file()}


def _pictures(st: Stage, results: list[dict]) -> list[dict]:
    a, pictures = st.args, []
    for r in st.progress(results, "panorama pictures"):
        name, ours, cv = r["set"], r["ours"], r["opencv_stitcher"]
        ours_img = io.read_image(Path(a.crop) / f"{name}.png") if ours["ok"] else None
        cv_img = io.read_image(Path(a.opencv) / f"{name}.png") if cv["ok"] else None
        path = Path(a.pictures) / f"{name}_side_by_side.png"
        io.save_picture(path, pr.side_by_side([ours_img, cv_img], PICTURE_HEIGHT))
        status = cv.get("status", "not run")
        pictures.append({"path": path.as_posix(),
                         "caption": f"{name}: ours (left, cropped) vs cv2.Stitcher (right, {status})"})
        if (Path(a.blend) / f"{name}_seams.png").is_file():
            seams = io.read_image(Path(a.blend) / f"{name}_seams.png", "gray") > 0
            over = pr.overlay_seams(io.read_image(Path(a.blend) / f"{name}.png"), seams)
            path = Path(a.pictures) / f"{name}_seams.png"
            io.save_picture(path, pr.side_by_side([over], over.shape[0]))
            pictures.append({"path": path.as_posix(), "caption": f"{name}: our seam lines (red)"})
    return pictures


def panorama_report(st: Stage) -> None:
    a = st.args
    sets, _ = datasets.find_panorama(a.images)
    names = [s.name for s in sets]
    homs, blends, crops = _records(a.homographies, names), _records(a.blend, names), _records(a.crop, names)
    opencv = _records(a.opencv, names)
    results = pr.compare_sets(sets, homs, blends, crops, opencv)
    dropped = pr.not_processed(io.load_json(Path(a.features) / "dropped.json"), homs, crops, opencv)
    st.save_metrics(a.metrics, pr.metrics_of(results))
    io.save_json(a.summary, pr.report_summary(results, _pictures(st, results), dropped))
    st.save_plot(Path(a.plots) / "sets.json", pr.quality_plot(results))
    ok = sum(r["ours"]["ok"] for r in results)
    st.made(f"{len(results)} sets compared (ours stitched {ok}, cv2.Stitcher "
            f"{sum(r['opencv_stitcher']['ok'] for r in results)}; {sum(r['truth'] for r in results)} with truth)")
    for d in dropped:
        st.drop(d["item"], d["reason"])


if __name__ == "__main__":
    run(panorama_report,
        args={"images": "the panorama.data folder", "features": "panorama_features output (its dropped.json)",
              "homographies": "panorama_homographies output", "blend": "panorama_blend output",
              "crop": "panorama_crop output", "opencv": "panorama_opencv_stitcher output",
              "pictures": "folder for the report's pictures", "metrics": "metrics JSON (git-tracked)",
              "summary": "summary JSON for the report page", "plots": "folder for dvc plots data"})

"""Stage `hough_report`: agreement of our lines with OpenCV's, recall of the true lines where the folder has a
truth.json, overlays of both, metrics (git-tracked) and a quality plot."""

from pathlib import Path

import numpy as np

from cvpipe import datasets, hough, io
from ._runner import Stage, run

#: strongest lines drawn per overlay (all of them still count in the metrics)
MAX_DRAWN = 60
#: overlays shown on the report page
MAX_PICTURES = 12


def _scaled(lines: list, f: float) -> np.ndarray:
    """Lines ``[rho, theta, ...]`` of an image in the pixels of that image resized by ``f`` (pixel centres map as
    in ``cv2.resize``: ``x' = (x + 0.5) f - 0.5``, so ``rho' = f (rho + h) - h`` with ``h = (cos + sin) / 2``)."""
    out = np.array(lines, float)
    if f != 1.0 and out.size:
        h = (np.cos(out[:, 1]) + np.sin(out[:, 1])) / 2
        out[:, 0] = f * (out[:, 0] + h) - h
    return out


def hough_report(st: Stage) -> None:
    p, a = st.params, st.args
    items, _ = datasets.find_hough(a.images)
    truth = {it.name: it.truth_lines for it in items if it.truth_lines is not None}
    ours, opencv = io.load_json(a.ours), io.load_json(a.opencv)
    compared = hough.compare_runs(ours, opencv, truth, p)
    lines = {Path(i["file"]).stem: {"ours": i["lines"]} for i in ours["images"]}
    for i in opencv["images"]:
        lines[Path(i["file"]).stem]["opencv"] = i["lines"]
    pictures = []
    for it in st.progress([it for it in items if it.name in lines], "hough overlays"):
        full = io.read_image(it.path, "color")
        img = io.fit_picture(full, io.PICTURE_MAX_PIXELS // 2)  # two panels side by side
        f = img.shape[1] / full.shape[1]
        del full
        left = hough.draw_lines(img, _scaled(lines[it.name]["ours"][:MAX_DRAWN], f), (0, 0, 255))
        right = hough.draw_lines(img, _scaled(lines[it.name]["opencv"][:MAX_DRAWN], f), (0, 255, 0))
        path = Path(a.overlays) / f"{it.name}.png"
        io.save_picture(path, np.hstack([left, right]))
        pictures.append({"path": path.as_posix(), "caption": f"{it.name}: ours (red, left), OpenCV (green, right)"})
    dropped = io.load_json(Path(a.edges) / "dropped.json")
    st.write_report(hough.report_summary(compared, ours, opencv, pictures[:MAX_PICTURES], dropped),
                    hough.metrics_of(compared), {"lines": hough.quality_plot(compared)}, dropped)
    st.made(f"{compared['images']} images compared ({compared['identical_images']} identical, "
            f"{compared['truth_images']} with ground truth), {len(pictures)} overlays")


if __name__ == "__main__":
    run(hough_report, section="hough.report",
        args={"images": "the hough.data folder", "edges": "hough_edges output (its dropped.json)",
              "ours": "hough_lines@ours JSON", "opencv": "hough_lines@opencv JSON", "overlays": "overlay folder",
              "metrics": "metrics JSON (git-tracked)", "summary": "summary JSON for the report page",
              "plots": "folder for dvc plots data"})

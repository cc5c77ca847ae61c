"""Stage `hough_lines@{ours,opencv}`: standard Hough lines of every edge map (the median time per image goes to the
uncached timings)."""

from pathlib import Path

from cvpipe import hough, io
from ._runner import Stage, run


def hough_lines(st: Stage) -> None:
    p, method = st.params, st.args.method
    files = io.list_images(st.args.edges)
    images = []
    for name, (lines, first, median) in st.map(hough.lines_item, (io.read_image(f, "gray") for f in files),
                                               shared=(method, p), desc=f"hough lines {method}",
                                               names=[f.name for f in files]):
        key = "first_call" if not images else "calls"  # the process's first: warms OpenCV and the allocations
        st.timings[key] = st.timings.get(key, 0.0) + first
        st.timings[f"median.{Path(name).stem}"] = median
        images.append({"file": name, "lines": lines.tolist()})
    rho, theta = hough.hough_steps(p)  # the run's steps in the units of its lines, for hough_report
    io.save_json(st.args.out, {"impl": method, "rho": rho, "theta": theta, "threshold": p.threshold,
                               "refine": p.refine and method == "ours", "images": images})
    st.made(f"{sum(len(i['lines']) for i in images)} lines in {len(images)} images -> {st.args.out}")


if __name__ == "__main__":
    run(hough_lines, section="hough.lines", item="method", args={"edges": "folder of edge maps", "out": "JSON file"},
        options={"method": {"required": True, "choices": sorted(hough.IMPLEMENTATIONS)}})

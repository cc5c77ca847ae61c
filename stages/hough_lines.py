"""Stage `hough_lines@{ours,opencv}`: standard Hough lines of every edge map (the median time per image goes to the
uncached timings)."""

import math

from cvpipe import hough, io
from stages._runner import Stage, run


def hough_lines(st: Stage) -> None:
    p = st.params
    fn = hough.get_impl(st.args.method)
    kwargs = {"refine": p.refine} if st.args.method == "ours" else {}
    theta = math.radians(p.theta_deg)
    images = []
    for f in st.progress(io.list_images(st.args.edges), f"hough lines {st.args.method}"):
        edges = io.read_image(f, "gray")
        with st.timer("first_call" if not images else "calls"):  # ours' first: numba compile or cache load
            lines = fn(edges, p.rho, theta, p.threshold, **kwargs)
        st.timings[f"median.{f.stem}"] = hough.median_seconds(
            lambda: fn(edges, p.rho, theta, p.threshold, **kwargs), p.repeats)
        images.append({"file": f.name, "lines": lines.tolist()})
    io.save_json(st.args.out, {"impl": st.args.method, "rho": p.rho, "theta": theta, "threshold": p.threshold,
                               "refine": bool(kwargs.get("refine", False)), "images": images})
    st.made(f"{sum(len(i['lines']) for i in images)} lines in {len(images)} images -> {st.args.out}")


if __name__ == "__main__":
    run(hough_lines, section="hough.lines", item="method", args={"edges": "folder of edge maps", "out": "JSON file"},
        options={"method": {"required": True, "choices": sorted(hough.IMPLEMENTATIONS)}})

"""Stage `homography_estimate@{ours,opencv_ransac,opencv_magsac}`: a robust homography A -> B for every matched
pair: ``<pair>.npz`` (``H``, ``inliers``) and ``estimates.json`` (per pair H, matches, inliers; the pairs without an
estimate under ``dropped`` with the reason). Times go to the uncached timings only."""

from pathlib import Path

from cvpipe import io
from cvpipe.errors import InputError
from cvpipe.homography import METHODS, estimate_item
from ._runner import Stage, run


def homography_estimate(st: Stage) -> None:
    p, a = st.params, st.args
    files = sorted(Path(a.matches).glob("*.npz"))
    if not files:
        raise InputError(f"{a.matches}: no <pair>.npz matches (run homography_match)")
    out, results = Path(a.out), {}
    # read lazily, sent with the task
    pairs = (tuple(io.load_npz(f, ("src", "dst"))[k] for k in ("src", "dst")) for f in files)
    first = True
    for name, (fit, seconds) in st.map(estimate_item, pairs, shared=(a.method, p), desc=f"estimate {a.method}",
                                       names=[f.stem for f in files]):
        # the process's first call warms OpenCV and the first allocations: timed apart from the others
        key = "first_call" if first and not st.dropped else "estimates"
        st.timings[key] = st.timings.get(key, 0.0) + seconds
        first = False
        io.save_npz(out / f"{name}.npz", H=fit.H, inliers=fit.inliers)
        results[name] = {"H": fit.H, "matches": len(fit.inliers), "inliers": fit.num_inliers}
    io.save_json(out / "estimates.json", {"method": a.method, "pairs": results, "dropped": st.dropped})
    st.made(f"{len(results)} of {len(files)} pairs estimated -> {out}")


if __name__ == "__main__":
    run(homography_estimate, section="homography.estimate", item="method",
        args={"matches": "homography_match output folder", "out": "folder for <pair>.npz and estimates.json"},
        options={"method": {"required": True, "choices": sorted(METHODS)}})

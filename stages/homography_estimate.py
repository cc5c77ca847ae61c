"""Stage `homography_estimate@{ours,opencv_ransac,opencv_magsac}`: a robust homography A -> B for every matched
pair: ``<pair>.npz`` (``H``, ``inliers``) and ``estimates.json`` (per pair H, matches, inliers; the pairs without an
estimate under ``dropped`` with the reason). Times go to the uncached timings only."""

from pathlib import Path

from cvpipe import io
from cvpipe.errors import EstimationError, InputError
from cvpipe.homography import METHODS, estimate
from stages._runner import Stage, run


def homography_estimate(st: Stage) -> None:
    p, a = st.params, st.args
    kw = dict(threshold=p.threshold, confidence=p.confidence, max_iters=p.max_iters, rng=p.seed)
    files = sorted(Path(a.matches).glob("*.npz"))
    if not files:
        raise InputError(f"{a.matches}: no <pair>.npz matches (run homography_match)")
    out, results = Path(a.out), {}
    for f in st.progress(files, f"estimate {a.method}"):
        m = io.load_npz(f)
        with st.timer("first_call" if not results and not st.dropped else "estimates"):  # numba cache load first
            try:
                fit = estimate(a.method, m["src"], m["dst"], **kw)
            except (EstimationError, InputError) as exc:
                st.drop(f.stem, f"{len(m['src'])} matches: {exc}")
                continue
        io.save_npz(out / f.name, H=fit.H, inliers=fit.inliers)
        results[f.stem] = {"H": fit.H, "matches": len(m["src"]), "inliers": fit.num_inliers}
    io.save_json(out / "estimates.json", {"method": a.method, "pairs": results, "dropped": st.dropped})
    st.made(f"{len(results)} of {len(files)} pairs estimated -> {out}")


if __name__ == "__main__":
    run(homography_estimate, section="homography.estimate", item="method",
        args={"matches": "homography_match output folder", "out": "folder for <pair>.npz and estimates.json"},
        options={"method": {"required": True, "choices": sorted(METHODS)}})

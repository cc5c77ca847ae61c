"""Stage `panorama_opencv_stitcher`: the cv2.Stitcher baseline on the same sets of `panorama.data` and at the same
resolutions, its RNG seeded with `panorama.match.seed` (`<out>/<set>.png`, `<set>.json` with the homographies its
cameras imply; its failures and the images it leaves out are recorded)."""

from pathlib import Path

import numpy as np

from cvpipe import datasets, io, panorama
from cvpipe.errors import InputError
from ._runner import Stage, run


def panorama_opencv_stitcher(st: Stage) -> None:
    out = Path(st.args.out)
    sections = [st.sections[f"panorama.{k}"] for k in ("features", "match", "warp")]
    sets, _ = datasets.find_panorama(st.args.images)  # what the layout drops, panorama_features reports
    made = 0
    for s in st.progress(sets, "cv2.Stitcher"):
        files, images = [], []
        for f in s.files:
            try:
                images.append(io.read_image(f, "color"))
                files.append(f.name)
            except InputError as exc:
                st.drop(f"{s.name}/{f.name}", str(exc))
        with st.timer("stitch"):
            r = panorama.opencv_stitch_with(images, *sections) if len(images) >= 2 else None
        status, pano, used = ("ERR_NEED_MORE_IMGS", None, []) if r is None else (r.status, r.pano, r.used)
        result = {"ok": status == "OK", "status": status, "used": used, "files": files,
                  "full_sizes": [[img.shape[1], img.shape[0]] for img in images]}
        if r is not None and r.homographies:  # what its cameras imply, input -> common frame, full resolution
            result["G"] = {str(k): np.asarray(H).tolist() for k, H in r.homographies.items()}
        if pano is not None:
            io.save_image(out / f"{s.name}.png", pano)
            result.update(size=[pano.shape[1], pano.shape[0]], empty_share=float((pano == 0).all(axis=2).mean()))
            made += 1
            for k, name in enumerate(files):
                if k not in used:
                    st.drop(f"{s.name}/{name}", "left out by cv2.Stitcher, which gives no reason")
        else:
            st.drop(s.name, f"cv2.Stitcher failed: {status}")
        io.save_json(out / f"{s.name}.json", result)
    out.mkdir(parents=True, exist_ok=True)
    st.made(f"cv2.Stitcher stitched {made} of {len(sets)} sets into {out}")


if __name__ == "__main__":
    run(panorama_opencv_stitcher, section=["panorama.features", "panorama.match", "panorama.warp"],
        args={"images": "the panorama.data folder", "out": "folder for <set>.png and <set>.json"})

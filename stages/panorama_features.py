"""Stage `panorama_features`: per set of `panorama.data`, every image shrunk to the registration resolution, then
its features, stored with that grey image (`panorama_match` tracks in it when asked). Layout: every subfolder is
one set, its images in any order (truth.json optional). Writes `<out>/<set>/<image stem>.npz` and
`<out>/dropped.json` (sets and images not used, with the reason)."""

from pathlib import Path

import numpy as np

from cvpipe import datasets, io, panorama
from cvpipe.errors import InputError
from ._runner import Stage, run

#: smallest side of an image the pipeline accepts (as `cvpipe.panorama.stitch`)
MIN_SIDE = 16


def _readable(st: Stage, s: datasets.PanoramaSet) -> list[tuple[Path, np.ndarray]]:
    """The set's images that can be read and are large enough (the others are dropped with their reason)."""
    got, stems = [], {}
    for f in s.files:
        try:
            img = io.read_image(f, "gray")
        except InputError as exc:
            st.drop(f"{s.name}/{f.name}", str(exc))
            continue
        if min(img.shape) < MIN_SIDE:
            st.drop(f"{s.name}/{f.name}", f"{img.shape[1]}x{img.shape[0]} pixels, expected at least "
                                          f"{MIN_SIDE}x{MIN_SIDE}")
        elif f.stem in stems:
            st.drop(f"{s.name}/{f.name}", f"same name as {stems[f.stem]}; rename one")
        else:
            stems[f.stem] = f.name
            got.append((f, img))
    return got


def panorama_features(st: Stage) -> None:
    p, out = st.params, Path(st.args.out)
    sets, dropped = datasets.find_panorama(st.args.images)
    for d in dropped:
        st.drop(d["item"], d["reason"])
    done = 0
    for s in st.progress(sets, "panorama features"):
        got = _readable(st, s)
        if len(got) < 2:
            st.drop(s.name, f"{len(got)} usable image(s), a panorama needs at least 2")
            continue
        with st.timer("features"):
            sizes, feats, grays = panorama.features_and_images_of([img for _, img in got], p)
        for (f, img), size, ft, gray in zip(got, sizes, feats, grays):
            # the grey image at the registration resolution: panorama_match tracks in it (panorama.match.pair_refine)
            io.save_npz(out / s.name / f"{f.stem}.npz", **ft.to_arrays(), work_size=size, work_gray=gray,
                        full_size=(img.shape[1], img.shape[0]), image_file=f.name)
        done += 1
    st.finish(out, done, f"sets' features in {out}", f"{st.args.images}: no panorama set with 2 or more usable images")


if __name__ == "__main__":
    run(panorama_features, section="panorama.features",
        args={"images": "the panorama.data folder", "out": "folder for <set>/<image>.npz and dropped.json"})

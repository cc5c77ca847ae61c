"""Stage `logo_match@det`: match every scene's features against the indexed gallery, one .npz per scene.

Layout of `logo.data`: `gallery/` (one image per brand named after it, `<brand>.<ext>`, or one subfolder per brand,
`<brand>/*.<ext>`, with several references) and `scenes/`; a truth.json is optional. Features come from
`logo_features@det` (one .npz per image file, at the image's path). Writes `<scene>.npz`, `index.json` (the
references in index order and the matched scenes) and `dropped.json`.
"""

from pathlib import Path

from cvpipe import datasets, io, logo
from cvpipe.errors import CvpipeError, InputError
from cvpipe.features import DETECTORS, Features
from cvpipe.logo.cached import feature_reasons, features_of, load_gallery
from ._runner import Stage, run


def logo_match(st: Stage) -> None:
    root, features, out = Path(st.args.images), Path(st.args.features), Path(st.args.out)
    inputs, found_dropped = datasets.find_logo(root)
    for d in found_dropped:
        st.drop(d["item"], d["reason"])
    gallery, gallery_dropped = load_gallery(inputs, root, features, st.params)
    for d in gallery_dropped:
        st.drop(d["item"], d["reason"])
    if gallery.detector != st.args.detector:
        raise InputError(f"{features}: features of {gallery.detector!r}, expected {st.args.detector!r}")
    reasons, matched = feature_reasons(features), []
    names = [sc.path.relative_to(root).as_posix() for sc in inputs.scenes]
    scene_of = dict(zip(names, inputs.scenes))

    def scene_data():
        # read here, lazily: each scene's features travel with its task
        for sc in inputs.scenes:
            got = features_of(features, root, sc.path, reasons)
            try:
                yield InputError(got) if isinstance(got, str) else Features.from_arrays(got)
            except (CvpipeError, ValueError) as exc:
                yield InputError(str(exc))

    for name, (m, seconds) in st.map(logo.match_item, scene_data(), shared=(gallery, st.params),
                                     desc=f"match {st.args.detector}", names=names):
        st.timings["match"] = st.timings.get("match", 0.0) + seconds
        io.save_npz(out / f"{scene_of[name].name}.npz", **m.to_arrays())
        matched.append(scene_of[name].name)
    if not matched:
        raise InputError(f"{root / 'scenes'}: no scene could be matched")
    io.save_json(out / "index.json", {"detector": gallery.detector, "scenes": matched,
                                      "references": [r.name for r in gallery.references]})
    io.save_json(out / "dropped.json", st.dropped)
    st.made(f"{len(matched)} scenes matched against {len(gallery.references)} references of "
            f"{len(gallery.brands)} brands -> {out}")


if __name__ == "__main__":
    run(logo_match, section="logo.match", item="detector",
        args={"images": "the logo.data folder", "features": "logo_features@det output",
              "out": "folder for <scene>.npz, index.json, dropped.json"},
        options={"detector": {"required": True, "choices": sorted(DETECTORS)}})

"""Stage `logo_verify@det`: homography verification and the brand decision per scene; metrics (git-tracked) and the
precision-recall curve over the scenes with ground truth (an empty curve when none has it). `--detector fused` weighs
the matches of several detectors under one decision (`cvpipe.logo.METHODS`); its `--features` and `--matches` are the
parent folders of the detectors' `logo_features@det` and `logo_match@det` outputs.

Writes `decisions.json` (one record per scene, see `cvpipe.logo.scene_record`), `<scene>.npz` with the inliers of
the best plausible hypothesis, and `dropped.json` (what `logo_match` and this stage did not process, and why).
"""

from pathlib import Path

from cvpipe import datasets, io, logo
from cvpipe.errors import CvpipeError, InputError
from cvpipe.features import NPZ_ARRAYS, Features
from cvpipe.logo.cached import load_gallery
from ._runner import Stage, run


def logo_verify(st: Stage) -> None:
    a, mp, vp = st.args, st.sections["logo.match"], st.sections["logo.verify"]
    root, out = Path(a.images), Path(a.out)
    inputs, _ = datasets.find_logo(root)  # what it drops, logo_match has listed
    detectors = logo.method_detectors(a.detector)
    # one detector: --features and --matches are its folders; several (fused): one subfolder per detector in each
    folder = {d: (Path(a.features), Path(a.matches)) if len(detectors) == 1 else
              (Path(a.features) / d, Path(a.matches) / d) for d in detectors}
    galleries, index = {}, {}
    for d, (features, matched) in folder.items():
        galleries[d], _ = load_gallery(inputs, root, features, mp)
        index[d] = io.load_json(matched / "index.json")
        if index[d]["references"] != [r.name for r in galleries[d].references]:
            raise InputError(f"{matched}: matched against another gallery than {root / 'gallery'}; rerun logo_match")
    names_in = [n for n in index[detectors[0]]["scenes"] if all(n in index[d]["scenes"] for d in detectors)]
    scenes = {sc.name: sc for sc in inputs.scenes}
    rel = {n: scenes[n].path.relative_to(root) for n in names_in if n in scenes}

    def scene_data():
        # read here, lazily: each scene's features and matches travel with its task
        for name in names_in:
            if name not in scenes:
                yield InputError("matched, but no longer in the scenes folder; rerun logo_match")
                continue
            try:
                feats, matches = {}, {}
                for d, (features, matched) in folder.items():
                    arrays = io.load_npz(features / rel[name].with_suffix(".npz"), NPZ_ARRAYS)
                    feats[d], size = Features.from_arrays(arrays), tuple(int(v) for v in arrays["image_size"])
                    matches[d] = logo.Matches.from_arrays(io.load_npz(matched / f"{name}.npz", logo.Matches.ARRAYS))
                yield matches, feats, size
            except CvpipeError as exc:
                yield exc

    # a dropped scene is named by its file, as logo_match names it (or by its name when the file is gone)
    names = [rel[n].as_posix() if n in rel else n for n in names_in]
    scene_of = {rel[n].as_posix(): scenes[n] for n in rel}
    records, ref_names = [], {d: [r.name for r in g.references] for d, g in galleries.items()}
    for item, (det, scene_xy, seconds) in st.map(logo.verify_method_scene, scene_data(), shared=(galleries, vp),
                                                 desc=f"verify {a.detector}", names=names):
        sc = scene_of[item]
        st.timings["verify"] = st.timings.get("verify", 0.0) + seconds
        best = det.best
        truth = (sc.brand, sc.quad) if sc.labelled else None
        reference = galleries[best.detector].references[best.reference].name if best else None
        records.append(logo.scene_record(sc.name, det, reference, truth, ref_names))
        if best is not None:
            io.save_npz(out / f"{sc.name}.npz", pairs=best.pairs, H=best.H, gallery_xy=best.reference_xy,
                        scene_xy=scene_xy)
    if not records:
        raise InputError(f"{root / 'scenes'}: no scene could be verified")
    brands = sorted(inputs.gallery)
    io.save_json(out / "decisions.json", {"detector": a.detector, "brands": brands, "scenes": records})
    io.save_json(out / "dropped.json", [x for d in detectors for x in io.load_json(folder[d][1] / "dropped.json")]
                 + st.dropped)
    st.save_metrics(a.metrics, logo.metrics_of(records, brands, a.detector, vp.score_threshold))
    st.save_plot(a.pr, logo.pr_rows(records, a.detector, vp.score_threshold))
    found = sum(r["brand"] is not None for r in records)
    st.made(f"{found} of {len(records)} scenes given a brand ({sum(r['labelled'] for r in records)} with ground "
            f"truth) -> {out}")


if __name__ == "__main__":
    run(logo_verify, section=["logo.verify", "logo.match"], item="detector",
        args={"images": "the logo.data folder",
              "features": "logo_features@det output (fused: their parent folder)",
              "matches": "logo_match@det output (fused: their parent folder)",
              "out": "folder for decisions.json, <scene>.npz, dropped.json",
              "metrics": "metrics JSON (git-tracked)", "pr": "precision-recall rows for dvc plots"},
        options={"detector": {"required": True, "choices": sorted(logo.METHODS),
                              "help": "a detector, or fused: --features and --matches then hold one folder per "
                                      "detector"}})

"""Stage `logo_verify@det`: homography verification and the brand decision per scene; metrics (git-tracked) and the
precision-recall curve over the scenes with ground truth (an empty curve when none has it).

Writes `decisions.json` (one record per scene, see `cvpipe.logo.scene_record`), `<scene>.npz` with the inliers of
the best plausible hypothesis, and `dropped.json` (what `logo_match` and this stage did not process, and why).
"""

from pathlib import Path

from cvpipe import datasets, io, logo
from cvpipe.errors import CvpipeError, InputError
from cvpipe.features import DETECTORS, Features
from stages._runner import Stage, run
from stages.logo_match import load_gallery


def logo_verify(st: Stage) -> None:
    a, mp, vp = st.args, st.sections["logo.match"], st.sections["logo.verify"]
    root, out = Path(a.images), Path(a.out)
    inputs, _ = datasets.find_logo(root)  # what it drops, logo_match has listed
    gallery, _ = load_gallery(inputs, root, Path(a.features), mp)
    index = io.load_json(Path(a.matches) / "index.json")
    if index["references"] != [r.name for r in gallery.references]:
        raise InputError(f"{a.matches}: matched against another gallery than {root / 'gallery'}; rerun logo_match")
    scenes = {sc.name: sc for sc in inputs.scenes}
    records = []
    for name in st.progress(index["scenes"], f"verify {a.detector}"):
        sc = scenes.get(name)
        if sc is None:
            st.drop(name, "matched, but no longer in the scenes folder; rerun logo_match")
            continue
        rel = sc.path.relative_to(root).with_suffix(".npz")
        try:
            arrays = io.load_npz(Path(a.features) / rel)
            scene, size = Features.from_arrays(arrays), tuple(int(v) for v in arrays["image_size"])
            matches = logo.Matches.from_arrays(io.load_npz(Path(a.matches) / f"{name}.npz"))
            with st.timer("verify"):
                det = logo.decide(logo.verify(gallery, matches, scene, size, vp, rng=0), vp)
        except CvpipeError as exc:
            st.drop(sc.path.relative_to(root).as_posix(), str(exc))
            continue
        best = det.best
        truth = (sc.brand, sc.quad) if sc.labelled else None
        records.append(logo.scene_record(name, det, gallery.references[best.reference].name if best else None,
                                          truth))
        if best is not None:
            io.save_npz(out / f"{name}.npz", pairs=best.pairs, H=best.H, gallery_xy=best.reference_xy,
                        scene_xy=scene.xy[best.pairs[:, 1]])
    if not records:
        raise InputError(f"{root / 'scenes'}: no scene could be verified")
    brands = sorted(inputs.gallery)
    io.save_json(out / "decisions.json", {"detector": a.detector, "brands": brands, "scenes": records})
    io.save_json(out / "dropped.json", io.load_json(Path(a.matches) / "dropped.json") + st.dropped)
    io.save_json(a.metrics, logo.metrics_of(records, brands, a.detector, vp.score_threshold))
    io.save_json(a.pr, logo.pr_rows(records, a.detector, vp.score_threshold))
    found = sum(r["brand"] is not None for r in records)
    st.made(f"{found} of {len(records)} scenes given a brand ({sum(r['labelled'] for r in records)} with ground "
            f"truth) -> {out}")


if __name__ == "__main__":
    run(logo_verify, section=["logo.verify", "logo.match"], item="detector",
        args={"images": "the logo.data folder", "features": "logo_features@det output",
              "matches": "logo_match@det output", "out": "folder for decisions.json, <scene>.npz, dropped.json",
              "metrics": "metrics JSON (git-tracked)", "pr": "precision-recall rows for dvc plots"},
        options={"detector": {"required": True, "choices": sorted(DETECTORS)}})

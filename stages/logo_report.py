"""Stage `logo_report`: per-detector and per-scene tables, confusion matrices (scenes with ground truth), overlays of
the found outlines and inliers, the "found per brand" plot and summary.json."""

from pathlib import Path

import numpy as np

from cvpipe import datasets, io, logo
from ._runner import Stage, run

#: overlays of found logos drawn (plus up to MAX_WRONG wrong answers on scenes with ground truth)
MAX_FOUND = 6
MAX_WRONG = 2
#: missed scenes (labelled with a brand, answered otherwise) in the strip of their best rejected fits
MAX_MISSED = 8


def logo_report(st: Stage) -> None:
    a, vp = st.args, st.sections["logo.verify"]
    root, out = Path(a.images), Path(a.out)
    inputs, _ = datasets.find_logo(root)
    decisions = {m: io.load_json(Path(a.verify) / m / "decisions.json")["scenes"] for m in a.methods}
    brands = sorted(inputs.gallery)
    pictures = []
    for m, recs in decisions.items():
        lab = [r for r in recs if r["labelled"]]
        if not lab:
            continue
        img = logo.draw_confusion(logo.confusion([r["truth"] for r in lab], [r["brand"] for r in lab], brands),
                                   brands, f"{m}: truth (rows) vs decision")
        io.save_picture(out / f"confusion_{m}.png", img)
        pictures.append({"path": (out / f"confusion_{m}.png").as_posix(), "caption": f"{m}: confusion matrix on "
                         f"the {len(lab)} scenes with ground truth (rows = truth, columns = decision, last = none)"})
    best = logo.pick_method(decisions, vp.score_threshold, st.sections["logo.report"].method)
    recs = decisions[best]
    shown = [r for r in recs if r["brand"]][:MAX_FOUND]
    shown += [r for r in recs if r["labelled"] and r["best_brand"] and r["truth"] != r["brand"]
              and r not in shown][:MAX_WRONG]
    scenes = {sc.name: sc for sc in inputs.scenes}
    for r in st.progress(shown, "logo overlays"):
        pairs = io.load_npz(Path(a.verify) / best / f"{r['scene']}.npz", ("gallery_xy", "scene_xy"))
        truth = f" (truth {r['truth'] or 'none'})" if r["labelled"] else ""
        caption = (f"{best}: {r['scene']} -> {r['brand'] or 'none'}{truth}, best {r['best_brand']} with "
                   f"{r['inliers']} inliers")
        pic = logo.draw_detection(io.read_image(scenes[r["scene"]].path, "color"),
                                   io.read_image(root / r["reference"], "color"),
                                   None if r["quad"] is None else np.array(r["quad"]), pairs["gallery_xy"],
                                   pairs["scene_xy"], None if r.get("truth_quad") is None else
                                   np.array(r["truth_quad"]), caption)
        path = out / f"overlay_{best}_{r['scene']}.png"
        io.save_picture(path, pic)
        blue = "blue = true outline, " if r["labelled"] else ""
        pictures.append({"path": path.as_posix(), "caption": f"{caption}; green = found outline, {blue}orange = "
                         "inlier matches"})
    missed = [r for r in recs if r["labelled"] and r["truth"] is not None and r["brand"] != r["truth"]][:MAX_MISSED]
    if missed:
        strip = logo.draw_missed([io.read_image(scenes[r["scene"]].path, "color") for r in missed], missed)
        io.save_picture(out / f"missed_{best}.png", strip)
        pictures.append({"path": (out / f"missed_{best}.png").as_posix(),
                         "caption": f"{best}: scenes whose logo was missed (first {len(missed)}), blue = true "
                                    "outline, red = the true brand's best rejected fit, and why it was rejected"})
    dropped = logo.merge_dropped({m: io.load_json(Path(a.verify) / m / "dropped.json") for m in a.methods})
    references = sum(len(files) for files in inputs.gallery.values())
    io.save_json(a.summary, logo.report_summary(decisions, brands, references, vp.score_threshold, pictures,
                                                 dropped))
    st.save_plot(a.found, logo.found_plot(decisions, brands))
    st.made(f"{len(decisions[best])} scenes, detectors {', '.join(a.methods)}, {len(pictures)} pictures -> {out}")
    for d in dropped:
        st.drop(d["item"], f"{', '.join(d['methods'])}: {d['reason']}")


if __name__ == "__main__":
    run(logo_report, section=["logo.verify", "logo.report"],
        args={"images": "the logo.data folder", "verify": "folder of the logo_verify@det outputs",
              "methods": "+detectors, one logo_verify output folder each", "out": "folder for the pictures",
              "summary": "summary JSON for the report page", "found": "found-per-brand rows for dvc plots"})

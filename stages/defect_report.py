"""Stage `defect_report`: overlays (found regions red, true boxes green), heat maps, metrics (git-tracked), the
confusion and score plots and the report page's summary, from the stage outputs only (no inspection is rerun;
times are in the stages' uncached timings). Truth (truth.json in `defect.data`) is optional."""

from pathlib import Path

from cvpipe import datasets, io
from cvpipe.defect import report as rep
from cvpipe.errors import InputError
from ._runner import Stage, run

#: tiles per row of the two montages
COLS = 5


def defect_report(st: Stage) -> None:
    a, out = st.args, Path(st.args.out)
    inputs, _ = datasets.find_defect(a.images)
    truth = {p.path.name: {"verdict": p.verdict, "boxes": p.boxes, "H": p.H} for p in inputs.probes
             if p.verdict is not None}
    records = io.load_json(a.results)
    registration = io.load_json(a.registration)
    h, w = registration["reference_shape"]
    evaluated = rep.evaluate_records(records, truth, (w, h))
    paths = {p.path.name: p.path for p in inputs.probes}
    overlays, heats = [], []
    for r in st.progress(records, "defect report"):
        name = Path(r["probe"]).name
        try:
            over = rep.overlay(io.read_image(paths[name], "color"), r, truth.get(name))
        except (InputError, KeyError):  # unreadable or gone: already listed as not inspected
            continue
        io.save_image(out / "overlays" / f"{Path(name).stem}.png", over)
        overlays.append(over)
        if r["verdict"] is not None:
            key = "alt_diff" if r["registration"] == "alternative" else "diff"
            z = io.load_npz(Path(a.diff) / f"{Path(name).stem}.npz", (key,))
            heat = rep.heat_map(z[key], r["threshold"])
            heats.append(rep.caption(heat, f"{name}: score {r['score']:.0f}"))
    pictures = []
    for key, images, caption in (
            ("overlays", overlays, "probes with found regions (red) and true boxes (green)"),
            ("heatmaps", heats, "tolerant difference in the reference frame (the colour scale saturates at twice "
                                "the threshold)")):
        if images:
            io.save_picture(out / f"{key}.png", rep.montage(images, COLS))
            pictures.append({"path": (out / f"{key}.png").as_posix(), "caption": caption})
    dropped = [{"item": r["probe"], "reason": r["error"]} for r in records if r["verdict"] is None]
    st.save_metrics(out / "metrics.json", rep.metrics_of(records, evaluated))
    st.save_plot(out / "plots" / "confusion.json", rep.confusion_rows(records, truth))
    st.save_plot(out / "plots" / "scores.json", rep.score_rows(records))
    io.save_json(out / "summary.json", rep.report_summary(records, registration["probes"], evaluated, pictures,
                                                          dropped))
    for d in dropped:
        st.drop(d["item"], d["reason"])
    acc = evaluated.get("overall", {}).get("accuracy")
    st.made(f"{evaluated['inspected']} of {evaluated['probes']} probes inspected, "
            + (f"accuracy {acc:.3f} on {evaluated['truth_probes']} with truth" if acc is not None else
               "no ground truth") + f", {len(overlays)} overlays")


if __name__ == "__main__":
    run(defect_report, args={"images": "the defect.data folder", "results": "defect_regions results JSON",
                             "registration": "defect_register's registration.json", "diff": "defect_diff output",
                             "out": "outputs/defect (overlays/, *.png, summary.json, metrics.json, plots/)"})

"""Stage `defect_diff`: gain/bias-corrected, misregistration-tolerant difference of every registered probe (and of
its direct alternative, when `defect_register` made one), in the reference frame; one .npz per probe and
differences.json (photometric fit per probe, probes dropped so far)."""

from pathlib import Path

from cvpipe import datasets, defect, io
from cvpipe.errors import EstimationError
from ._runner import Stage, run


def defect_diff(st: Stage) -> None:
    p, reg_dir, out = st.params, Path(st.args.registered), Path(st.args.out)
    inputs, _ = datasets.find_defect(st.args.images)
    ref = io.read_image(inputs.reference, "gray")
    registration = io.load_json(reg_dir / "registration.json")
    fits = {}
    probes = sorted(registration["probes"].items())
    name_of = {rec["file"]: name for name, rec in probes}  # a dropped probe is named by its file

    def probe_data():
        # read here, lazily: each probe's warped image(s) travel with its task
        for name, _ in probes:
            z = io.load_npz(reg_dir / f"{name}.npz", ("warped", "valid"))
            yield z["warped"], z["valid"], (z["alt_warped"], z["alt_valid"]) if "alt_H" in z else None

    for file, (arrays, fit, seconds) in st.map(defect.difference_item, probe_data(), shared=(ref, p),
                                               desc="defect diff", names=list(name_of)):
        st.timings["difference"] = st.timings.get("difference", 0.0) + seconds
        io.save_npz(out / f"{name_of[file]}.npz", **arrays)
        fits[name_of[file]] = {"file": file, **fit}
    if not fits:
        raise EstimationError("no registered probe could be compared with the reference: "
                              + "; ".join(f"{d['item']}: {d['reason']}" for d in st.dropped))
    io.save_json(out / "differences.json", {"probes": fits, "dropped": registration["dropped"] + st.dropped})
    st.made(f"{len(fits)} difference maps -> {out}")


if __name__ == "__main__":
    run(defect_diff, section="defect.diff",
        args={"images": "the defect.data folder (its reference)", "registered": "defect_register output",
              "out": "folder for <probe>.npz and differences.json"})

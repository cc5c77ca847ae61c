"""Stage `defect_diff`: gain/bias-corrected, misregistration-tolerant difference of every registered probe (and of
its direct alternative, when `defect_register` made one), in the reference frame; one .npz per probe and
differences.json (photometric fit per probe, probes dropped so far)."""

from pathlib import Path

from cvpipe import datasets, defects, io
from cvpipe.errors import EstimationError
from stages._runner import Stage, run


def defect_diff(st: Stage) -> None:
    p, reg_dir, out = st.params, Path(st.args.registered), Path(st.args.out)
    inputs, _ = datasets.find_defect(st.args.images)
    ref = io.read_image(inputs.reference, "gray")
    registration = io.load_json(reg_dir / "registration.json")
    fits = {}
    for name, rec in st.progress(sorted(registration["probes"].items()), "defect diff"):
        z = io.load_npz(reg_dir / f"{name}.npz")
        try:
            with st.timer("difference"):
                d = defects.difference(ref, z["warped"], z["valid"], p)
        except EstimationError as exc:
            st.drop(rec["file"], str(exc))
            continue
        arrays, fit = d.to_arrays(), {"file": rec["file"], "primary": d.photometry()}
        if "alt_H" in z:
            try:
                with st.timer("difference"):
                    alt = defects.difference(ref, z["alt_warped"], z["alt_valid"], p)
            except EstimationError as exc:  # only a second opinion: the probe goes on without it
                fit["alternative_error"] = str(exc)
            else:
                arrays.update(alt.to_arrays("alt_"))
                fit["alternative"] = alt.photometry()
        io.save_npz(out / f"{name}.npz", **arrays)
        fits[name] = fit
    if not fits:
        raise EstimationError("no registered probe could be compared with the reference: "
                              + "; ".join(f"{d['item']}: {d['reason']}" for d in st.dropped))
    io.save_json(out / "differences.json", {"probes": fits, "dropped": registration["dropped"] + st.dropped})
    st.made(f"{len(fits)} difference maps -> {out}")


if __name__ == "__main__":
    run(defect_diff, section="defect.diff",
        args={"images": "the defect.data folder (its reference)", "registered": "defect_register output",
              "out": "folder for <probe>.npz and differences.json"})

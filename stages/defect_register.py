"""Stage `defect_register`: the homography reference -> probe of every probe, the probe warped onto the reference
and the registration's quality (method, matches, inliers, ECC correlation); no difference, no verdict.

When the registration came from keypoints (and `direct_fallback` is on), the direct alignment (phase correlation +
ECC) is registered too: `defect_regions` keeps it instead when the keypoint one makes the probe faulty and the
direct one leaves a lower score (``defects.choose``, as `cvpipe inspect` does). A probe that cannot be registered
is dropped with its reason (registration.json, `dropped`) and reported "not inspected".
"""

from dataclasses import asdict
from pathlib import Path

from cvpipe import datasets, defects, io
from cvpipe.errors import CvpipeError, EstimationError
from cvpipe.features import Features
from stages._runner import Stage, run


def defect_register(st: Stage) -> None:
    p, a, out = st.params, st.args, Path(st.args.out)
    inputs, _ = datasets.find_defect(a.images)
    matched = io.load_json(Path(a.matches) / "matches.json")
    ref = io.read_image(inputs.reference, "gray")
    ref_feats = Features.from_arrays(io.load_npz(Path(a.features) / f"{inputs.reference.stem}.npz"))
    records = {}
    for probe in st.progress([q for q in inputs.probes if q.name in matched["matches"]], "defect register"):
        try:
            prb = io.read_image(probe.path, "gray")
            feats = Features.from_arrays(io.load_npz(Path(a.features) / "probes" / f"{probe.name}.npz"))
            with st.timer("register"):
                reg = defects.register(ref, prb, p, reference_features=ref_feats, probe_features=feats,
                                       matches=io.load_npz(Path(a.matches) / f"{probe.name}.npz")["index"])
        except CvpipeError as exc:
            st.drop(probe.path.name, str(exc))
            continue
        rec = {"file": probe.path.name, "probe_shape": prb.shape, "primary": asdict(reg), "alternative": None}
        warped, valid = defects.warp_probe(prb, reg.H, ref.shape)
        arrays = {"H": reg.H, "warped": warped, "valid": valid}
        if defects.wants_alternative(reg, p):
            try:
                with st.timer("direct_alternative"):
                    alt = defects.register_direct(ref, prb, p, matches=reg.matches, inliers=reg.inliers)
            except EstimationError as exc:
                rec["alternative_error"] = str(exc)
            else:
                rec["alternative"] = asdict(alt)
                warped, valid = defects.warp_probe(prb, alt.H, ref.shape)
                arrays.update(alt_H=alt.H, alt_warped=warped, alt_valid=valid)
        io.save_npz(out / f"{probe.name}.npz", probe_shape=prb.shape, **arrays)
        records[probe.name] = rec
    if not records:
        raise EstimationError(f"no probe could be registered to {inputs.reference}: "
                              + "; ".join(f"{d['item']}: {d['reason']}" for d in st.dropped))
    io.save_json(out / "registration.json", {"reference": inputs.reference.name, "reference_shape": ref.shape,
                                             "probes": records, "dropped": matched["dropped"] + st.dropped})
    direct = sum(r["primary"]["method"] == "direct" for r in records.values())
    alts = sum(r["alternative"] is not None for r in records.values())
    st.made(f"{len(records)} probes registered ({direct} directly, {alts} with a direct alternative) -> {out}")


if __name__ == "__main__":
    run(defect_register, section="defect.register",
        args={"images": "the defect.data folder", "features": "defect_features output",
              "matches": "defect_match output", "out": "folder for <probe>.npz and registration.json"})

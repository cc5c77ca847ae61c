"""Stage `defect_register`: the homography reference -> probe of every probe, the probe warped onto the reference
and the registration's quality (method, matches, inliers, ECC correlation); no difference, no verdict.

When the registration came from keypoints (and `direct_fallback` is on), the direct alignment (phase correlation +
ECC) is registered too: `defect_regions` keeps it instead when the keypoint one makes the probe faulty and the
direct one leaves a lower score (``defect.choose``, as `cvpipe inspect` does). A probe that cannot be registered
is dropped with its reason (registration.json, `dropped`) and reported "not inspected".
"""

from dataclasses import asdict
from pathlib import Path

from cvpipe import datasets, defect, io
from cvpipe.errors import CvpipeError, EstimationError
from cvpipe.features import Features
from ._runner import Stage, run


def defect_register(st: Stage) -> None:
    p, a, out = st.params, st.args, Path(st.args.out)
    inputs, _ = datasets.find_defect(a.images)
    matched = io.load_json(Path(a.matches) / "matches.json")
    ref = io.read_image(inputs.reference, "gray")
    ref_feats = Features.from_arrays(io.load_npz(Path(a.features) / f"{inputs.reference.stem}.npz", Features.ARRAYS))
    records = {}
    probes = [q for q in inputs.probes if q.name in matched["matches"]]

    def probe_data():
        # read here, lazily: each probe's image, features and matches travel with its task (a worker need not see
        # this folder); a probe that cannot be read is dropped with the reason, in input order
        for probe in probes:
            try:
                yield (io.read_image(probe.path, "gray"),
                       Features.from_arrays(io.load_npz(Path(a.features) / "probes" / f"{probe.name}.npz",
                                                        Features.ARRAYS)),
                       io.load_npz(Path(a.matches) / f"{probe.name}.npz", ("index",))["index"])
            except CvpipeError as exc:
                yield exc

    by_name = {q.path.name: q for q in probes}
    for name, r in st.map(defect.register_item, probe_data(), shared=(ref, ref_feats, p), desc="defect register",
                          names=list(by_name)):
        probe = by_name[name]
        for key, sec in r["seconds"].items():
            st.timings[key] = st.timings.get(key, 0.0) + sec
        rec = {"file": probe.path.name, "probe_shape": r["probe_shape"], "primary": asdict(r["primary"]),
               "alternative": None if r["alternative"] is None else asdict(r["alternative"])}
        if r["alternative_error"] is not None:
            rec["alternative_error"] = r["alternative_error"]
        io.save_npz(out / f"{probe.name}.npz", probe_shape=r["probe_shape"], **r["arrays"])
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

"""Stage `defect_regions`: threshold, morphology and components of every difference map -> regions and a verdict
per probe; where `defect_register` made a direct alternative, the one ``defects.choose`` keeps (as `cvpipe inspect`).

results.json holds one record per probe, as `cvpipe inspect --json` prints them (``probe``, ``verdict``, ``score``,
``regions`` in probe pixels, ``H``) plus the regions in reference pixels, the threshold and the registration used;
a probe dropped by an earlier stage has ``verdict: null`` and its reason in ``error``.
"""

from pathlib import Path

from cvpipe import defects, io
from cvpipe.defects import Difference
from stages._runner import Stage, run


def defect_regions(st: Stage) -> None:
    p, a = st.params, st.args
    registration = io.load_json(a.registration)["probes"]
    differences = io.load_json(Path(a.diff) / "differences.json")
    results = []
    for name in st.progress(sorted(differences["probes"]), "defect regions"):
        reg = registration[name]
        z = io.load_npz(Path(a.diff) / f"{name}.npz")
        with st.timer("regions"):
            first = defects.find_regions(Difference.from_arrays(z), reg["primary"]["H"], reg["probe_shape"], p)
            alt = (defects.find_regions(Difference.from_arrays(z, "alt_"), reg["alternative"]["H"],
                                        reg["probe_shape"], p) if "alt_diff" in z else None)
        chosen = "alternative" if defects.choose(first, alt) is alt else "primary"
        r = alt if chosen == "alternative" else first
        results.append({"probe": reg["file"], "verdict": r.verdict, "score": r.score, "regions": r.probe_regions,
                        "reference_regions": r.regions, "region_scores": r.region_scores, "threshold": r.threshold,
                        "H": reg[chosen]["H"], "registration": chosen, "method": reg[chosen]["method"]})
    for d in differences["dropped"]:
        results.append({"probe": d["item"], "verdict": None, "score": None, "regions": [], "H": None,
                        "error": d["reason"]})
    io.save_json(a.out, sorted(results, key=lambda r: r["probe"]))
    faulty = sum(r["verdict"] == "faulty" for r in results)
    st.made(f"{faulty} faulty, {len(differences['probes']) - faulty} perfect, {len(differences['dropped'])} not "
            f"inspected -> {a.out}")


if __name__ == "__main__":
    run(defect_regions, section="defect.regions",
        args={"diff": "defect_diff output", "registration": "defect_register's registration.json",
              "out": "results JSON (one record per probe)"})

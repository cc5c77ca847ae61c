"""Digests of the robust estimators' results on fixed seeds, to show that a change of the robust core or of a
recipe leaves the estimates as they were (or to list the cases it changed).

    python tests/estimate_digests.py before.json        # on the old code
    python tests/estimate_digests.py after.json         # on the new code
    python tests/estimate_digests.py --compare before.json after.json

Each case is one call with a fixed seed: ``find_homography`` on the SIFT matches of the samples' pairs and of the
Oxford/CMP pairs (``$CVPIPE_DATA``, when present) with two seeds and with local optimization and refinement off, on
synthetic scenes with 10, 50 and 90 % outliers and on random points; ``find_fundamental`` on the stereo pairs of
``$CVPIPE_DATA`` with the right view turned as in ``cvpipe bench guard``; ``affine_ransac`` with and without poses on
synthetic matches; the logo's ``significance`` on a grid. A digest is a hash of the result's bytes (model, inlier
mask, iterations, rms, NFA), or the start of the error message.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(np.asarray(a)).tobytes())
    return h.hexdigest()[:16]


def _call(fn, digest):
    from cvpipe.errors import EstimationError

    try:
        return digest(fn())
    except EstimationError as exc:
        return "error: " + str(exc)[:60]


def digests() -> dict[str, str]:
    """case name -> digest of its result."""
    import cv2

    from cvpipe import io, stereo
    from cvpipe.bench.homography import real_pairs, synthetic_scene
    from cvpipe.homography import correspondences, find_homography
    from cvpipe.logo import affine_ransac
    from cvpipe.logo.verify import significance

    out: dict[str, str] = {}

    def fit(f):
        return _digest(f.H, f.inliers, f.iterations, f.rms, f.log10_nfa)

    samples = ROOT / "data" / "samples" / "homography"
    truth = io.load_json(samples / "truth.json")
    pairs = [(t["name"], samples / t["a"], samples / t["b"]) for t in truth["pairs"]]
    data = Path(os.environ["CVPIPE_DATA"]) if os.environ.get("CVPIPE_DATA") else None
    if data is not None:
        pairs += [(p["name"], p["a"], p["b"]) for p in real_pairs(data)]
    for name, a, b in pairs:
        cv2.setRNGSeed(0)
        s, d = correspondences(io.read_image(a, "gray"), io.read_image(b, "gray"))
        for seed in (0, 1):
            out[f"homography/{name}/seed{seed}"] = _call(lambda: find_homography(s, d, rng=seed), fit)
        out[f"homography/{name}/plain"] = _call(
            lambda: find_homography(s, d, rng=3, local_optimization=False, refine=False), fit)
    for seed in range(3):
        for share in (0.1, 0.5, 0.9):
            _, s, d = synthetic_scene(np.random.default_rng(seed), 1000, share)
            out[f"homography/synthetic{seed}/{share}"] = _call(
                lambda: find_homography(s, d, 3.0, 0.999, 100_000, rng=0), fit)
    rng = np.random.default_rng(5)
    for k in range(20):
        s = rng.uniform(0, 500, (int(rng.integers(5, 60)), 2))
        d = rng.uniform(0, 500, s.shape)
        out[f"homography/random{k}"] = _call(lambda: find_homography(s, d, rng=k), fit)

    if data is not None and (data / "middlebury_stereo").is_dir():
        from cvpipe.bench.stereo_pairs import load_pairs
        from cvpipe.bench.stereo_rectify import THRESHOLD, unrectifying_homography

        stereo_pairs = load_pairs(data)
        for seq, (name, (left, right, _)) in zip(np.random.SeedSequence(0).spawn(len(stereo_pairs)),
                                                 stereo_pairs.items()):
            h, w = left.shape[:2]
            H_u, _ = unrectifying_homography(np.random.default_rng(seq), (w, h))
            right_u = cv2.warpPerspective(right, H_u, (w, h), flags=cv2.INTER_LINEAR)
            cv2.setRNGSeed(0)
            p1, p2 = correspondences(io.to_gray(left), io.to_gray(right_u))
            for seed in (0, 1):
                out[f"fundamental/{name}/seed{seed}"] = _call(
                    lambda: stereo.find_fundamental(p1, p2, THRESHOLD, rng=seed),
                    lambda f: _digest(f.F, f.inliers, f.iterations, f.rms))

    rng = np.random.default_rng(7)
    A = np.array([[1.2, 0.1, 30.0], [-0.05, 0.9, 10.0]])
    for k in range(30):
        n = int(rng.integers(3, 80))
        src = rng.uniform(0, 300, (n, 2))
        dst = src @ A[:, :2].T + A[:, 2] + rng.normal(0, 0.5, (n, 2))
        bad = rng.random(n) < 0.4
        dst[bad] = rng.uniform(0, 300, (int(bad.sum()), 2))
        pose = np.c_[rng.uniform(-180, 180, n), rng.normal(0, 0.3, n)]
        out[f"affine/{k}"] = _call(lambda: affine_ransac(src, dst, 4.0, 500, rng=k), lambda r: _digest(*r))
        out[f"affine/{k}/poses"] = _call(
            lambda: affine_ransac(src, dst, 4.0, 500, rng=k, src_pose=pose, dst_pose=pose, angle_tolerance=30,
                                  scale_tolerance=1.5), lambda r: _digest(*r))
    grid = [significance(k, m, t, a, r, p) for k in (4, 5, 8, 12, 40, 200) for m in (5, 40, 300, 5000)
            for t in (2.0, 4.0) for a in (1e4, 3e5) for r in (1, 10) for p in (1.0, 0.05)]
    out["logo/significance"] = _digest(np.round(grid, 9))  # to 1e-9: the NFA's last bits depend on its formula
    return out


def compare(before: dict[str, str], after: dict[str, str]) -> list[str]:
    """The cases whose digest differs or that only one side has."""
    return sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))


def main(argv: list[str]) -> int:
    if len(argv) == 3 and argv[0] == "--compare":
        before, after = (json.loads(Path(p).read_text(encoding="utf-8")) for p in argv[1:])
        changed = compare(before, after)
        print(f"{len(before)} cases before, {len(after)} after, {len(changed)} changed")
        for k in changed:
            print(f"  {k}: {before.get(k)} -> {after.get(k)}")
        return 1 if changed else 0
    if len(argv) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    sys.path.insert(0, str(ROOT))
    result = digests()
    Path(argv[0]).write_text(json.dumps(result, indent=0, sort_keys=True) + "\n", encoding="utf-8")
    print(f"{len(result)} cases -> {argv[0]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

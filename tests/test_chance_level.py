"""The test against chance in cvpipe.homography: real benchmark pairs stay accepted, unrelated pairs are refused.

Needs the real data (``$CVPIPE_DATA`` with ``oxford_affine/`` and ``cmp_homogr/``); skips without it. Run as a
script (``python tests/test_chance_level.py``) to print the counts recorded in docs/notes/homography.md.
"""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from cvpipe import homography, io
from cvpipe.errors import EstimationError
from cvpipe.metrics import corner_error
from cvpipe.params import FeaturesParams, HomographyEstimateParams, MatchParams

#: a pair is a success within this corner error, px (the homography benchmark's --success-px default)
SUCCESS_PX = 3.0
#: number of random pairs of images of different scenes (at least 50)
N_UNRELATED = 60


def _features_cache():
    cache = {}
    f = FeaturesParams()

    def get(path):
        if path not in cache:
            from cvpipe.features import detect

            gray = io.read_image(path, "gray")
            cache[path] = (detect(gray, f.detector, f.max_features), gray.shape)
        return cache[path]

    return get


def _matches(fa, fb):
    from cvpipe.matching import match

    m = MatchParams()
    idx = match(fa.descriptors, fb.descriptors, m.ratio, False, fa.binary)
    return fa.xy[idx[:, 0]].astype(np.float64), fb.xy[idx[:, 1]].astype(np.float64)


def measure(root: Path, n_unrelated: int = N_UNRELATED, seed: int = 0) -> dict:
    """Counts per method: real pairs that succeed without the test and are lost with it, and unrelated pairs
    accepted (the same detector, matcher and estimator settings as ``cvpipe homography`` and the benchmark)."""
    from cvpipe.bench.homography import real_pairs

    pairs = real_pairs(root)
    e = HomographyEstimateParams()
    kw = dict(threshold=e.threshold, confidence=e.confidence, max_iters=e.max_iters)
    feats = _features_cache()
    out = {m: {"real": len(pairs), "real_success_without_test": 0, "real_lost": 0, "real_accepted": 0,
               "unrelated": 0, "unrelated_accepted": 0, "lost_names": [], "accepted_unrelated": []}
           for m in homography.METHODS}
    raw = {}
    # find_homography and the OpenCV methods look the test up in their own module
    est = importlib.import_module("cvpipe.homography.estimate")
    orig = est._significant
    for p in pairs:
        (fa, sa), (fb, _) = feats(p["a"]), feats(p["b"])
        src, dst = _matches(fa, fb)
        for m in homography.METHODS:
            # the same fit without the test (it is applied after the estimate, so the model is identical)
            est._significant = lambda fit, *a, **k: fit
            try:
                fit = homography.METHODS[m](src, dst, rng=e.seed, **kw) if len(src) >= 4 else None
            except EstimationError:
                fit = None
            finally:
                est._significant = orig
            ok = fit is not None and corner_error(fit.H, p["H"], sa[1], sa[0]) <= SUCCESS_PX
            try:
                homography.estimate(m, src, dst, rng=e.seed, **kw)
                accepted = True
            except (EstimationError, ValueError):
                accepted = False
            rec = out[m]
            rec["real_success_without_test"] += ok
            rec["real_accepted"] += accepted
            if ok and not accepted:
                rec["real_lost"] += 1
                rec["lost_names"].append(p["name"])
            raw[(m, p["name"])] = (ok, accepted)
    # unrelated: images of different scenes (an Oxford sequence or a CMP pair is one scene)
    # the scene key: the first 5 letters of the sequence or pair name, lower case, so that CMP's LePoint1/2/3,
    # Boston/BostonLib, BruggeSquare/BruggeTower and the boat/graf pairs that CMP shares with Oxford count as one
    images = sorted({(p["name"].split("_1to")[0][:5].lower(), str(p[k])) for p in pairs for k in ("a", "b")})
    rng = np.random.default_rng(seed)
    chosen = set()
    while len(chosen) < n_unrelated:
        i, j = rng.choice(len(images), 2, replace=False)
        if images[i][0] != images[j][0]:
            chosen.add((int(i), int(j)))
    for i, j in sorted(chosen):
        (fa, _), (fb, _) = feats(images[i][1]), feats(images[j][1])
        src, dst = _matches(fa, fb)
        for m in homography.METHODS:
            out[m]["unrelated"] += 1
            try:
                fit = homography.estimate(m, src, dst, rng=e.seed, **kw)
            except (EstimationError, ValueError):
                continue
            out[m]["unrelated_accepted"] += 1
            out[m]["accepted_unrelated"].append(
                f"{images[i][1]} -> {images[j][1]}: {fit.num_inliers}/{len(src)} log10 NFA {fit.log10_nfa:.2f}")
    return out


@pytest.mark.slow
def test_no_real_pair_lost_and_no_unrelated_pair_accepted(data_root):
    if not (data_root / "oxford_affine").is_dir() or not (data_root / "cmp_homogr").is_dir():
        pytest.skip("oxford_affine/ or cmp_homogr/ missing under CVPIPE_DATA")
    res = measure(data_root)
    for m, r in res.items():
        assert r["unrelated"] >= 50
        # every pair that a method solves without the test keeps its result with it
        assert r["real_lost"] == 0, (m, r["lost_names"])
        # and no pair of photos of different scenes gives a model (the test's purpose)
        assert r["unrelated_accepted"] == 0, (m, r)


if __name__ == "__main__":  # pragma: no cover - prints the counts for docs/notes/homography.md
    import json

    root = Path(sys.argv[1] if len(sys.argv) > 1 else os.environ.get("CVPIPE_DATA", "../shared/data"))
    print(json.dumps(measure(root), indent=1, sort_keys=True))

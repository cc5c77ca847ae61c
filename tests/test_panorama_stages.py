"""The panorama DVC stages (stages/panorama_*.py) on a user-style folder and the optional per-set truth of
cvpipe.datasets.find_panorama."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from cvpipe.errors import InputError

from test_panorama import distractor, views  # noqa: F401 - fixtures used below
from conftest import default_params_path


# ---- the DVC stages (stages/panorama_*.py) on a user-style folder: truth optional, nothing skipped silently ----


def _run_stage(module: str, monkeypatch, **paths) -> None:
    """Run ``python -m stages.<module> --key value ...`` in this process (the runner exits; 0 = success)."""
    import runpy
    import sys

    argv = [module] + [a for k, v in paths.items() for a in (f"--{k}", str(v))]
    monkeypatch.setattr(sys, "argv", argv)
    with pytest.raises(SystemExit) as done:
        runpy.run_module(f"stages.{module}", run_name="__main__")
    assert done.value.code == 0, f"{module} failed"


def _leaves(d: dict, path: str = ""):
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _leaves(v, f"{path}{k}.")
        else:
            yield f"{path}{k}", v


def test_stages_on_a_folder_with_partial_truth(tmp_path, views, distractor, monkeypatch, repo_root):
    from cvpipe import io, panorama

    imgs, T = views
    data, out = tmp_path / "in", tmp_path / "out"
    for k, img in enumerate(imgs):
        io.save_image(data / "room" / f"view_{k}.png", img)
    io.save_image(data / "room" / "zz_other.png", distractor)  # shares nothing with the views
    io.save_image(data / "hall.v2" / "b.png", imgs[2])  # a set the truth does not know, a dot in its name
    io.save_image(data / "hall.v2" / "a.png", imgs[1])
    io.save_image(data / "loose.png", imgs[0])  # not in a set folder
    io.save_image(data / "mixed" / "p.png", imgs[0])  # two unrelated photos: the whole set fails, the rest goes on
    io.save_image(data / "mixed" / "q.png", distractor)
    # truth: view k -> view 0 (photo -> view k is T[k]); the distractor is not listed
    io.save_json(data / "truth.json", {"sets": [{"name": "room", "images": [f"room/view_{k}.png" for k in range(3)],
                                                 "H": [T[0] @ np.linalg.inv(T[k]) for k in range(3)]}]})
    monkeypatch.chdir(tmp_path)  # the runner writes its timings to ./outputs/timings
    params = default_params_path()
    _run_stage("panorama_features", monkeypatch, images=data, out=out / "features", params=params)
    _run_stage("panorama_match", monkeypatch, features=out / "features", out=out / "matches", params=params)
    _run_stage("panorama_homographies", monkeypatch, matches=out / "matches", out=out / "homographies",
               params=params)
    _run_stage("panorama_warp", monkeypatch, images=data, homographies=out / "homographies", out=out / "warp",
               params=params)
    _run_stage("panorama_blend", monkeypatch, warp=out / "warp", out=out / "blend", params=params)
    # a block compensator: its record shows each image's mean gain per channel
    blocks = tmp_path / "params_blocks.yaml"
    values = yaml.safe_load(params.read_text())
    values["panorama"]["blend"]["gain_compensation"] = "channel_blocks"
    blocks.write_text(yaml.safe_dump(values))
    _run_stage("panorama_blend", monkeypatch, warp=out / "warp", out=out / "blend_blocks", params=blocks)
    gains = np.array(io.load_json(out / "blend_blocks" / "room.json")["gains"])
    assert gains.shape == (3, 3) and np.all(np.abs(gains - 1) < 0.3)
    assert np.array(io.load_json(out / "blend" / "room.json")["gains"]).shape == (3,)
    _run_stage("panorama_crop", monkeypatch, blend=out / "blend", out=out / "pano", params=params)
    _run_stage("panorama_opencv_stitcher", monkeypatch, images=data, out=out / "opencv", params=params)
    report = dict(images=data, features=out / "features", homographies=out / "homographies", blend=out / "blend",
                  crop=out / "pano", opencv=out / "opencv", pictures=out / "report", metrics=out / "metrics.json",
                  summary=out / "summary.json", plots=out / "plots")
    _run_stage("panorama_report", monkeypatch, **report)
    metrics = io.load_json(out / "details.json")
    ours = metrics["panorama"]["ours"]
    # the median over the three view pairs is one of the two overlapping pairs: within 1.5 px (see
    # test_recovered_homographies_match_truth in test_panorama.py)
    assert ours["room"]["corner_error_px"] < 1.5
    assert ours["room"]["used_images"] == 3 and ours["room"]["dropped_images"] == 1 and ours["room"]["ok"] == 1
    assert ours["hall_v2"]["ok"] == 1 and "corner_error_px" not in ours["hall_v2"]  # no truth -> no error key
    # cv2.Stitcher's error by our measure (median over pairs p < q of used views, at p's size), from the homographies
    # its cameras imply: the record's figure equals one computed here from a fresh seeded run on the same photos
    from cvpipe.metrics import corner_error
    from cvpipe.params import PanoramaFeaturesParams, PanoramaMatchParams, PanoramaWarpParams

    cv_room = metrics["panorama"]["opencv_stitcher"]["room"]
    values = yaml.safe_load(params.read_text())["panorama"]
    sections = [cls(**values[k]) for cls, k in ((PanoramaFeaturesParams, "features"),
                                                 (PanoramaMatchParams, "match"), (PanoramaWarpParams, "warp"))]
    photos = [io.read_image(f, "color") for f in sorted((data / "room").glob("*.png"))]  # view_0..2, zz_other
    G = panorama.opencv_stitch_with(photos, *sections).homographies
    true = [T[0] @ np.linalg.inv(T[k]) for k in range(3)]
    errs = [corner_error(np.linalg.inv(G[q]) @ G[p], np.linalg.inv(true[q]) @ true[p], 320, 240)
            for p in range(3) for q in range(p + 1, 3)]
    want = float(np.median(errs))
    assert cv_room["used_images"] == 3 and abs(cv_room["corner_error_px"] - want) < 1e-3, (cv_room, want)
    assert set(metrics["panorama"]) == {"ours", "opencv_stitcher"}
    for key, value in _leaves(metrics):  # DVC-displayable: numbers only, no dotted keys
        assert isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value), key
    pano = io.read_image(out / "pano" / "room.png")
    assert [ours["room"]["width"], ours["room"]["height"]] == [pano.shape[1], pano.shape[0]]
    summary = io.load_json(out / "summary.json")
    assert "timings" not in summary
    (missing,) = [t for t in summary["tables"] if t["title"] == "Not processed"]
    reasons = {item: why for item, why in missing["rows"] if not why.startswith("cv2.Stitcher")}
    assert set(reasons) == {"loose.png", "room/zz_other.png", "mixed"}
    assert reasons["mixed"].startswith("ours (panorama_homographies): no two images")
    assert ours["mixed"] == {"ok": 0, "used_images": 0, "dropped_images": 2}
    assert not (out / "pano" / "mixed.png").exists() and io.load_json(out / "pano" / "mixed.json")["ok"] is False
    assert reasons["room/zz_other.png"].startswith("ours: ") and "view_" in reasons["room/zz_other.png"]
    assert summary["pictures"] and all(Path(p["path"]).is_file() for p in summary["pictures"])
    # a rerun on the same inputs gives the same bytes (DVC sees no change, the stages after stay up to date)
    before = {p: p.read_bytes() for p in (out / "metrics.json", out / "summary.json", out / "plots" / "sets.json",
                                          out / "features" / "dropped.json", out / "homographies" / "room.json")}
    _run_stage("panorama_features", monkeypatch, images=data, out=out / "features", params=params)
    _run_stage("panorama_homographies", monkeypatch, matches=out / "matches", out=out / "homographies",
               params=params)
    _run_stage("panorama_report", monkeypatch, **report)
    assert {p: p.read_bytes() for p in before} == before


def test_find_panorama_truth_is_optional_per_set_and_image(tmp_path, views):
    from cvpipe import datasets, io

    imgs, T = views
    for k in range(2):
        io.save_image(tmp_path / "a" / f"v{k}.jpg", imgs[k])
        io.save_image(tmp_path / "b" / f"v{k}.JPG", imgs[k])
    io.save_json(tmp_path / "truth.json", {"sets": [{"name": "a", "images": ["a/v0.jpg"], "H": [np.eye(3)]}]})
    sets, dropped = datasets.find_panorama(tmp_path)
    assert [s.name for s in sets] == ["a", "b"] and dropped == []
    assert sets[0].H[0] is not None and sets[0].H[1] is None  # only v0 is in the truth
    assert sets[1].H is None  # a set the truth does not name is still a set
    io.save_json(tmp_path / "truth.json", {"sets": [{"name": "a", "images": ["v0.jpg"], "H": [[1, 2]]}]})
    with pytest.raises(InputError, match=r"truth.json: field `sets\[0\].H\[0\]` must be"):
        datasets.find_panorama(tmp_path)


def test_fast_preset_values_run_in_the_stages_as_in_stitch(tmp_path, views, monkeypatch):
    # `panorama.match.pair_refine: lk` tracks in the grey work images, which panorama_features stores with the
    # features: the stages give the match graph that stitch(..., preset "fast") builds from the same seed
    from cvpipe import io, panorama
    from cvpipe.panorama.presets import PRESETS

    imgs, _ = views
    data, out = tmp_path / "in", tmp_path / "out"
    for k, img in enumerate(imgs):
        io.save_image(data / "room" / f"view_{k}.png", img)
    values = yaml.safe_load(default_params_path().read_text())
    for section, fields in PRESETS["fast"].items():
        values["panorama"][{"matching": "match"}.get(section, section)].update(fields)
    params = tmp_path / "params_fast.yaml"
    params.write_text(yaml.safe_dump(values))
    monkeypatch.chdir(tmp_path)
    _run_stage("panorama_features", monkeypatch, images=data, out=out / "features", params=params)
    _run_stage("panorama_match", monkeypatch, features=out / "features", out=out / "matches", params=params)
    graph = panorama.MatchGraph.from_arrays(io.load_npz(out / "matches" / "room.npz"))
    seed = values["panorama"]["match"]["seed"]
    grey = [io.read_image(data / "room" / f"view_{k}.png", "gray") for k in range(len(imgs))]
    want = panorama.stitch(grey, **panorama.preset_sections("fast"), rng=seed).graph
    assert graph.edges.keys() == want.edges.keys() and len(want.edges) >= 2
    for ij, e in want.edges.items():
        np.testing.assert_allclose(graph.edges[ij].H, e.H, rtol=1e-9, atol=1e-9)

"""The pipeline's stages write the same bytes whatever CPU-dependent code paths the machine would choose.

A second machine is emulated through the variables that select those paths (OpenCV's dispatched instruction sets and
IPP code paths, numpy's loops, OpenBLAS's kernels): the stages pin them on start (``stages.PINNED_ENV``), so a feature stage and an estimate stage
must write byte-identical outputs with and without the emulation. (cvpipe's own kernels are compiled for one fixed
instruction set, see ``meson.build``.) Without the pin, OpenCV's SIFT on the emulated machine (no AVX2 dispatch)
gives other keypoints, and this test fails.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

from cvpipe import io
from cvpipe.samples import fit, photo

ROOT = Path(__file__).resolve().parents[1]

#: another x86-64 machine, as far as the libraries can tell: fewer OpenCV dispatch levels and IPP code paths, numpy
#: loops without AVX2, other OpenBLAS kernels
OTHER_CPU = {"OPENCV_CPU_DISABLE": "AVX2,FP16,AVX512F,AVX512-SKX", "OPENCV_IPP": "SSE42",
             "NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR", "OPENBLAS_CORETYPE": "Zen"}


def _pair_folder(folder: Path) -> None:
    """Two views of two photos, related by known homographies (the estimate stage needs NAME_a / NAME_b pairs)."""
    folder.mkdir(parents=True)
    H = np.array([[1.02, 0.03, -12.0], [-0.02, 0.98, 9.0], [1e-5, -2e-5, 1.0]])
    for name in ("astronaut", "coffee"):
        img = fit(photo(name), 400, 300)
        io.save_image(folder / f"{name}_a.png", img)
        io.save_image(folder / f"{name}_b.png", cv2.warpPerspective(img, H, (400, 300)))


def _run_stages(work: Path, extra_env: dict) -> dict[str, bytes]:
    """features -> match -> estimate@ours in ``work`` with ``extra_env``; every output file's bytes by path."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), **extra_env}
    for args in (["stages.features", "--images", "images", "--out", "feats", "--section", "homography.features"],
                 ["stages.homography_match", "--images", "images", "--features", "feats", "--out", "matches"],
                 ["stages.homography_estimate", "--matches", "matches", "--method", "ours", "--out", "est"]):
        subprocess.run([sys.executable, "-m", *args], cwd=work, env=env, capture_output=True, text=True, check=True)
    return {p.relative_to(work).as_posix(): p.read_bytes()
            for d in ("feats", "matches", "est") for p in sorted((work / d).rglob("*")) if p.is_file()}


def test_feature_and_estimate_stages_write_the_same_bytes_on_another_cpu(tmp_path):
    runs = {}
    for name, extra in (("this", {}), ("other", OTHER_CPU)):
        work = tmp_path / name
        _pair_folder(work / "images")
        (work / "params.yaml").write_text((ROOT / "params.yaml").read_text())
        runs[name] = _run_stages(work, extra)
    assert sorted(runs["this"]) == sorted(runs["other"])
    assert any(k.startswith("feats/") for k in runs["this"]) and any(k.startswith("est/") for k in runs["this"])
    differ = [k for k in runs["this"] if runs["this"][k] != runs["other"][k]]
    assert not differ, f"outputs that depend on the CPU: {differ}"


def test_the_pinned_variables_reach_the_stage_before_the_libraries_load(tmp_path):
    # the stage package sets them on import, before numpy or OpenCV are imported by the stage module
    code = ("import stages, sys; print(stages.PINNED_ENV); "
            "print('numpy' in sys.modules, 'cv2' in sys.modules)")
    env = {**os.environ, "PYTHONPATH": str(ROOT), **OTHER_CPU}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.splitlines()[1] == "False False"
    import stages

    for key, value in stages.PINNED_ENV.items():
        got = subprocess.run([sys.executable, "-c", f"import stages, os; print(os.environ[{key!r}])"], env=env,
                             capture_output=True, text=True, check=True).stdout.strip()
        assert got == value, key


def test_a_stage_runs_opencv_without_ipp():
    # IPP chooses its code per CPU (and takes other paths on non-Intel CPUs): with it, SIFT's bytes depend on the
    # machine; the stages turn it off before OpenCV loads, whatever the environment asked for
    code = "import stages, cv2; print(cv2.ipp.useIPP())"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENCV_IPP": "AVX2"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
    plain = subprocess.run([sys.executable, "-c", "import cv2; print(cv2.ipp.useIPP())"], env=env,
                           capture_output=True, text=True, check=True).stdout
    assert plain.strip() == "True"  # the check above can fail: without the pin OpenCV uses IPP here


def test_the_kernels_are_built_for_one_instruction_set_without_fast_math():
    # the same bytes on every x86-64-v3 CPU: a fixed -march (never native), no contraction of a * b + c into an FMA
    # (its rounding differs), no fast-math (reassociation, flush-to-zero)
    build = "\n".join(line.split("#", 1)[0] for line in (ROOT / "meson.build").read_text().splitlines())
    flags = build[build.index("arch_args = ["):].split("]", 1)[0]
    assert "'-march=x86-64-v3'" in flags and "'-ffp-contract=off'" in flags
    for banned in ("native", "fast-math", "Ofast", "funsafe-math", "fassociative-math"):
        assert banned not in build, banned

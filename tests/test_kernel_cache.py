"""The test session's kernel cache is emptied when a module that uses numba changed (tests/compile_kernels.py)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _compile_kernels():
    spec = importlib.util.spec_from_file_location("compile_kernels", ROOT / "tests" / "compile_kernels.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_cached_kernels_are_dropped_when_a_numba_module_changed(tmp_path, monkeypatch):
    from cvpipe.commands import kernel_cache_folder

    ck = _compile_kernels()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    # a fake cache entry in the folder numba uses for cvpipe/homography, and one for a folder outside the package
    ours = Path(kernel_cache_folder(str(ROOT / "cvpipe" / "homography")))
    other = tmp_path / "elsewhere_0"
    for folder in (ours, other):
        folder.mkdir(parents=True)
        (folder / "_kernels._lsq-1.py311.nbi").write_bytes(b"index")
        (folder / "_kernels._lsq-1.py311.1.nbc").write_bytes(b"code")
    digest = ck.sources_digest()
    ck.write_stamp(digest)
    assert ck.drop_stale_kernels(digest) == 0  # compiled from these sources: kept
    assert len(list(ours.iterdir())) == 2
    assert ck.drop_stale_kernels("0" * 40) == 2  # from other sources: the package's entries go, nothing else
    assert list(ours.iterdir()) == [] and len(list(other.iterdir())) == 2


def test_the_digest_covers_the_modules_that_mention_numba():
    ck = _compile_kernels()
    a = ck.sources_digest()
    assert a == ck.sources_digest() and len(a) == 40
    numba_modules = [p for p in (ROOT / "cvpipe").rglob("*.py") if b"numba" in p.read_bytes()]
    assert ROOT / "cvpipe" / "homography" / "_kernels.py" in numba_modules
    assert ROOT / "cvpipe" / "io.py" not in numba_modules  # an edit there cannot change a compiled kernel

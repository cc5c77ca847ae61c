"""The stereo pairs of ``cvpipe bench stereo`` and of its rectification benchmark (``--rectify``,
:mod:`cvpipe.bench.stereo_rectify`): the five Middlebury pairs under ``DIR/middlebury_stereo`` and scikit-image's
motorcycle pair, with their true disparity, and the disparity range a pair is searched over.
"""

from __future__ import annotations

import typing
from pathlib import Path

from ..errors import InputError

if typing.TYPE_CHECKING:  # annotations only: numpy is imported inside the functions that use it
    import numpy as np

#: pair -> (folder, left, right, truth of the left image, truth value -> pixels); from middlebury_stereo/SOURCE.txt
MIDDLEBURY = {
    "tsukuba": ("tsukuba", "im3.png", "im4.png", "disp3.pgm", 1 / 16),
    "venus": ("venus", "im2.png", "im6.png", "disp2.pgm", 1 / 8),
    "cones": ("cones", "im2.png", "im6.png", "disp2.png", 1 / 4),
    "teddy": ("teddy", "im2.png", "im6.png", "disp2.png", 1 / 4),
    "adirondack": ("adirondack_2014_quarter", "Adirondack_left.png", "Adirondack_right.png", "Adirondack_gt.png",
                   1.0),
}


def load_pairs(root: Path) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """name -> (left BGR, right BGR, true disparity of the left image in pixels, NaN = unknown)."""
    import numpy as np
    from .. import io

    base = root / "middlebury_stereo"
    if not base.is_dir():
        raise InputError(f"{base}: no such folder (expected the Middlebury pairs, see ../shared/data/README.md)")
    pairs = {}
    for name, (folder, left, right, truth, scale) in MIDDLEBURY.items():
        d = base / folder
        raw = io.read_image(d / truth, "unchanged")
        if raw.ndim != 2:
            raise InputError(f"{d / truth}: expected a single-channel disparity image, got shape {raw.shape}")
        gt = raw.astype(np.float32) * np.float32(scale)
        gt[raw == 0] = np.nan
        pairs[name] = (io.read_image(d / left), io.read_image(d / right), gt)
    import skimage.data

    left, right, disp = skimage.data.stereo_motorcycle()
    pairs["motorcycle"] = (np.ascontiguousarray(left[..., ::-1]), np.ascontiguousarray(right[..., ::-1]),
                           np.where(np.isfinite(disp), disp, np.nan).astype(np.float32))
    return pairs


def disparity_range(truth: np.ndarray) -> int:
    """Smallest multiple of 16 that exceeds the largest true disparity (OpenCV needs multiples of 16)."""
    import numpy as np

    return int(np.ceil((np.nanmax(truth) + 1) / 16) * 16)

"""Named settings of :func:`cvpipe.panorama.stitch`: the fields of the ``panorama.*`` sections a preset changes
(``cvpipe stitch --preset``, ``cvpipe bench panorama --preset``, the guard's rows).

* ``default``: the sections' own defaults (``params.yaml``): SIFT features, each pair refitted on its inliers.
  The lowest pairwise error; 0.3-1.4x cv2.Stitcher's time (SIFT is half of it on large photos).
* ``fast``: ORB features (1500 per image, binary, about 10x cheaper to find than SIFT; with 1000, two of
  halfdome-14's views lost their link to the others), each accepted pair's homography fitted again to Lucas-Kanade
  tracks of corners in its overlap (:mod:`cvpipe.panorama.track`), which gives back most of the accuracy that ORB's
  coarse keypoints lose. 0.2-0.7x cv2.Stitcher's time, and a lower ground-truth error than cv2.Stitcher on every
  set with ground truth measured; ORB finds fewer of the weak pairs (little overlap) than SIFT.

Measurements: docs/notes/panorama.md.
"""

from __future__ import annotations

from ..params import (PanoramaBlendParams, PanoramaFeaturesParams, PanoramaHomographiesParams, PanoramaMatchParams,
                      PanoramaWarpParams, replace)

#: preset name -> section (``stitch`` keyword) -> the fields it sets
PRESETS: dict[str, dict[str, dict]] = {
    "default": {},
    "fast": {"features": {"detector": "orb", "max_features": 1500}, "matching": {"pair_refine": "lk"}},
}
PRESET_CHOICES = tuple(PRESETS)
DEFAULT_PRESET = "default"
#: ``stitch`` keyword -> its section's class
_SECTIONS = {"features": PanoramaFeaturesParams, "matching": PanoramaMatchParams,
             "homographies": PanoramaHomographiesParams, "warp": PanoramaWarpParams, "blend": PanoramaBlendParams}


def preset_sections(preset: str = DEFAULT_PRESET, **sections) -> dict:
    """The ``stitch`` keyword sections of ``preset``: each given section (default: the section's defaults) with the
    preset's fields set.

    Examples
    --------
    >>> s = preset_sections("fast")
    >>> s["features"].detector, s["features"].max_features, s["matching"].pair_refine
    ('orb', 1500, 'lk')
    >>> preset_sections()["features"].detector
    'sift'
    """
    if preset not in PRESETS:
        raise ValueError(f"`preset` must be one of {list(PRESET_CHOICES)}, got {preset!r}")
    unknown = set(sections) - set(_SECTIONS)
    if unknown:
        raise ValueError(f"unknown sections {sorted(unknown)}; choices: {sorted(_SECTIONS)}")
    out = {}
    for key, cls in _SECTIONS.items():
        base = sections.get(key) or cls()
        fields = PRESETS[preset].get(key)
        out[key] = replace(base, **fields) if fields else base
    return out

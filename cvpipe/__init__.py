"""cvpipe: reproducible classical computer-vision pipelines.

The library has one package per task. Its entry points take images as ``cv2.imread`` returns them (uint8, BGR or
grayscale; :func:`cvpipe.io.read_image` reads a file with checks) and the task's ``params.yaml`` sections as
parameter objects (:mod:`cvpipe.params`; a section left out takes its defaults,
``cvpipe.params.load_section(cls, "task.section")`` reads one from a ``params.yaml``). They return arrays or small
frozen dataclasses, and raise :class:`cvpipe.errors.InputError` for bad input or
:class:`cvpipe.errors.EstimationError` when the algorithm cannot give a result. The ``cvpipe`` command and the
pipeline's stages are built on them. Each task's reference, with a runnable example on the bundled samples
(``data/samples/<task>``), is ``docs/<task>.md`` in the repository, section "Python API".

Entry points
------------
hough: which straight lines are in an image (docs/hough.md)
    cvpipe.hough.edges_of(gray, HoughEdgesParams) -> uint8 Canny edge map
    cvpipe.hough.detect_lines(edges, HoughLinesParams, method) -> (N, 3) [rho, theta, votes]
    cvpipe.hough.hough_lines(edges, rho, theta, threshold) -> the same, like cv2.HoughLines
    cvpipe.hough.hough_lines_probabilistic(edges, threshold, min_line_length, max_line_gap) -> (K, 4) segments
homography: the 3x3 homography between two views (docs/homography.md)
    cvpipe.homography.correspondences(gray_a, gray_b, detector, max_features, ratio) -> (src, dst) matches
    cvpipe.homography.estimate_with(src, dst, HomographyEstimateParams, method) -> HomographyFit (H, inliers)
    cvpipe.homography.find_homography(src, dst, threshold) -> HomographyFit, like cv2.findHomography
defect: is a probe faulty or perfect against its reference, and where (docs/defect.md; command ``inspect``)
    cvpipe.defect.inspect(reference, probe, InspectParams) -> Inspection (verdict, score, probe_regions, H)
    cvpipe.defect.load_inspect_params(path) -> InspectParams from a params.yaml
logo: which gallery brand is in a scene photo, and where (docs/logo.md)
    cvpipe.logo.Reference(brand, name, features, size) -> one gallery image's keypoints
    cvpipe.logo.build_gallery(references, min_features, max_features) -> Gallery, the index of every brand
    cvpipe.logo.recognize(gallery, scene_features, scene_size, LogoMatchParams, LogoVerifyParams) -> Detection
    cvpipe.logo.every_logo(detection, score_threshold) -> every brand found, best first
stereo: disparity and depth of a pair, rectified first if needed (docs/stereo.md)
    cvpipe.stereo.disparity_with(left, right, max_disp, StereoSgmParams, method) -> float32 disparity, NaN = none
    cvpipe.stereo.disparity_sgm(left, right, max_disp) -> the same by our semi-global matching
    cvpipe.stereo.feature_matches(left, right) -> (pts_left, pts_right) matches
    cvpipe.stereo.rectify_uncalibrated(pts_left, pts_right, size) -> Rectification (H_left, H_right, max_disp)
    cvpipe.stereo.warp_pair(left, right, rectification) -> the rectified pair
    cvpipe.stereo.depth_from_disparity(disp, focal, baseline, doffs) -> float32 depth
    cvpipe.stereo.parse_calibration(text, source) -> Calibration from calib.txt or an OpenCV YAML
panorama: one seamless panorama from overlapping photos (docs/panorama.md; command ``stitch``)
    cvpipe.panorama.stitch(images, features=, matching=, homographies=, warp=, blend=) -> Panorama (image, ...)
shared
    cvpipe.io.read_image(path, mode) -> uint8 image, BGR or gray
    cvpipe.features.detect_with(gray, FeaturesParams) -> Features (keypoints and descriptors)
    cvpipe.params.load_section(cls, section, path) -> one params.yaml section

Importing :mod:`cvpipe` loads none of them (nor numpy or OpenCV); ``from cvpipe import hough`` loads that task.
"""

import os as _os

__version__ = "0.1.0"

# The compiled kernels' parallel loops run on OpenMP (GNU libgomp), whose threads sleep as soon as a parallel region
# ends (OMP_WAIT_POLICY=PASSIVE): libgomp's default spins for a while after every region, and on a 2-core machine that
# also runs other work the spinning thread competes with the one still working (and slows the OpenCV call that follows
# ours; docs/notes/threads.md). A default only: OMP_WAIT_POLICY set by the user wins, and it has no effect if another
# OpenMP program was loaded before cvpipe.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
# numpy's OpenBLAS on one thread: cvpipe runs its own work in parallel (OpenMP, OpenCV, thread pools, Dask), and an
# OpenBLAS thread spins for a while after every call, taking a core from that work (in-process stitch on the
# samples' motorcycle set 132 -> 100 ms, its features 89 -> 62 ms; docs/notes/threads.md). Like the lines above, a
# default that the user's setting overrides and that has no effect if numpy was imported before cvpipe.
_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

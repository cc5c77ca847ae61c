"""cvpipe.stereo.rectify: uncalibrated rectification of synthetic unrectified pairs (known cameras), calibrated
rectification of a known rig, and the Middlebury / OpenCV calibration parsers with their error messages."""

import cv2
import numpy as np
import pytest

from cvpipe import geometry
from cvpipe.stereo import calibration, rectify
from cvpipe.errors import EstimationError, InputError

from cameras import project, rotation

W, H = 640, 480
K = np.array([[600.0, 0.0, 319.5], [0.0, 600.0, 239.5], [0.0, 0.0, 1.0]])


def points(n, seed):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-2.5, 2.5, n), rng.uniform(-1.8, 1.8, n), rng.uniform(4, 12, n)])


def unrectified_pair(n=400, seed=0, noise=0.2, angles=(0.03, -0.04, 0.035), K2=None):
    """A left camera K[I|0] and a right camera 0.4 m to the right, turned by ``angles`` (rad) and with its own
    intrinsics: noisy matches for the estimation and a separate noise-free set for checking."""
    R = rotation(*angles)
    t = -R @ np.array([0.4, 0.0, 0.0])
    K2 = K if K2 is None else K2
    X, Xc = points(n, seed), points(300, seed + 100)
    rng = np.random.default_rng(seed + 1)
    p1, p2 = project(X, K), project(X, K2, R, t)
    return (p1 + rng.normal(0, noise, p1.shape), p2 + rng.normal(0, noise, p2.shape),
            project(Xc, K), project(Xc, K2, R, t))


class TestUncalibrated:
    @pytest.mark.parametrize("seed", [0, 1, 2])
    def test_vertical_error_and_disparity_range(self, seed):
        K2 = K.copy()
        K2[0, 0] = K2[1, 1] = 612.0  # a 2 % zoom of the right camera
        K2[1, 2] += 6.0  # and a shifted principal point
        p1, p2, c1, c2 = unrectified_pair(seed=seed, K2=K2)
        rect = rectify.rectify_uncalibrated(p1, p2, (W, H), rng=seed)
        yl, yr = geometry.apply_homography(rect.H_left, c1)[:, 1], geometry.apply_homography(rect.H_right, c2)[:, 1]
        err = np.abs(yl - yr)
        # 0.2 px matching noise on 400 matches: the epipolar geometry is known to a few hundredths of a pixel near
        # the matches (the benchmark measures ~0.05-0.1 px on real pairs); 0.15 / 0.5 px leave room for seeds
        assert np.median(err) < 0.15 and np.percentile(err, 95) < 0.5
        assert rect.vertical_error_median < 0.5  # the inlier matches carry the 0.2 px noise of both views
        d = geometry.apply_homography(rect.H_left, c1)[:, 0] - geometry.apply_homography(rect.H_right, c2)[:, 0]
        # the robust smallest disparity sits at the 1 px margin (the noise-free check points are another sample of
        # the same depth range, so allow 1 px), and the search range covers every point
        assert -0.5 <= d.min() and abs(np.percentile(d, 0.5) - 1.0) < 1.0
        assert d.max() < rect.max_disp and rect.max_disp % 16 == 0

    def test_low_distortion_of_the_left_image(self):
        p1, p2, _, _ = unrectified_pair(seed=3)
        rect = rectify.rectify_uncalibrated(p1, p2, (W, H), rng=0)
        # the left camera is the reference here, its epipole is at infinity up to the estimation noise: its
        # homography must be close to a similarity (Loop & Zhang's measures; OpenCV's reaches several degrees)
        dl = rectify.distortion(rect.H_left, (W, H))
        assert dl["aspect_change"] < 0.01 and dl["skew_deg"] < 0.5
        dr = rectify.distortion(rect.H_right, (W, H))  # the shear makes the right mid-lines exactly orthogonal
        assert dr["aspect_change"] < 1e-6 and dr["skew_deg"] < 1e-6

    def test_rectified_pair_stays_nearly_unchanged(self):
        X = points(400, 5)
        rng = np.random.default_rng(0)
        p1 = project(X, K) + rng.normal(0, 0.2, (400, 2))
        p2 = project(X, K, np.eye(3), np.array([-0.4, 0.0, 0.0])) + rng.normal(0, 0.2, (400, 2))
        rect = rectify.rectify_uncalibrated(p1, p2, (W, H), rng=0)
        grid = np.array([[0, 0], [W - 1, 0], [0, H - 1], [W - 1, H - 1], [W / 2, H / 2]], float)
        # an already rectified pair: both maps are the identity up to the disparity shift of the right image and
        # the estimation noise. 0.2 px noise leaves the epipole's direction uncertain by ~0.2 degrees, which turns
        # both images by that much: ~1.5 px at the corners, 400 px from the centre; 3 px bounds it
        assert np.abs(geometry.apply_homography(rect.H_left, grid) - grid).max() < 3.0
        moved = geometry.apply_homography(rect.H_right, grid) - grid
        assert np.abs(moved[:, 1]).max() < 3.0 and np.abs(moved[:, 0] - rect.shift).max() < 3.0

    def test_forward_motion_cannot_be_rectified(self):
        X = points(300, 6)
        p1, p2 = project(X, K), project(X, K, np.eye(3), np.array([0.0, 0.0, -0.5]))
        with pytest.raises(EstimationError, match="epipole"):
            rectify.rectify_uncalibrated(p1, p2, (W, H), rng=0)

    def test_validation(self):
        with pytest.raises(InputError, match="`size`"):
            rectify.rectifying_homographies(np.eye(3), np.zeros((3, 2)), np.zeros((3, 2)), (0, 5))
        with pytest.raises(InputError, match="`margin`"):
            rectify.rectifying_homographies(np.eye(3), np.zeros((3, 2)), np.zeros((3, 2)), (W, H), margin=-1)

    def test_opencv_baseline_runs_on_the_same_matches(self):
        p1, p2, c1, c2 = unrectified_pair(seed=4)
        H1, H2, F, inl = rectify.opencv_uncalibrated(p1, p2, (W, H))
        err = np.abs(geometry.apply_homography(H1, c1)[:, 1] - geometry.apply_homography(H2, c2)[:, 1])
        assert np.median(err) < 0.5 and inl.mean() > 0.9  # a sanity bound: the baseline works on this pair


# ------------------------------------------------------------------------------------------- calibration

MIDDLEBURY = """cam0=[994.978 0 311.193; 0 994.978 254.877; 0 0 1]
cam1=[994.978 0 342.279; 0 994.978 254.877; 0 0 1]
doffs=31.086
baseline=193.001
width=741
height=500
ndisp=64
isint=0
"""


class TestMiddleburyCalib:
    def test_parse(self, tmp_path):
        f = tmp_path / "calib.txt"
        f.write_text(MIDDLEBURY)
        c = calibration.parse_calibration(f.read_text(), str(f))
        assert c.rectified and c.unit == "mm" and c.size == (741, 500) and c.ndisp == 64
        assert c.K1[0, 0] == 994.978 and c.K2[0, 2] == 342.279 and c.doffs == 31.086
        assert c.baseline == pytest.approx(193.001) and np.array_equal(c.R, np.eye(3))
        g = rectify.rectified_depth_geometry(c)
        assert (g.focal, g.cx, g.cy, g.doffs) == (994.978, 311.193, 254.877, 31.086)

    @pytest.mark.parametrize("key", ["cam0", "cam1", "doffs", "baseline", "width", "height"])
    def test_missing_key(self, tmp_path, key):
        f = tmp_path / "calib.txt"
        f.write_text("".join(line + "\n" for line in MIDDLEBURY.splitlines() if not line.startswith(key + "=")))
        with pytest.raises(InputError, match=rf"calib\.txt: missing key `{key}`"):
            calibration.parse_calibration(f.read_text(), str(f))

    def test_bad_values(self):
        with pytest.raises(InputError, match="`cam0` must be a 3x3 matrix"):
            calibration.parse_middlebury_calib(MIDDLEBURY.replace("0 0 1]\ncam1", "0 1]\ncam1"), "c.txt")
        with pytest.raises(InputError, match="`baseline` must be a number"):
            calibration.parse_middlebury_calib(MIDDLEBURY.replace("193.001", "abc"), "c.txt")

    def test_size_mismatch_names_the_key(self):
        c = calibration.parse_middlebury_calib(MIDDLEBURY, "calib.txt")
        with pytest.raises(InputError, match=r"calib\.txt: `width` says 741x500 but the images are 740x500"):
            c.check_size((740, 500))
        with pytest.raises(InputError, match="`height`"):
            c.check_size((741, 400))


def write_opencv_yaml(path, skip=(), size=(640, 480)):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    values = {"K1": K, "D1": np.zeros((1, 5)), "K2": K, "D2": np.zeros((1, 5)), "R": rotation(0.01, 0.02, 0.0),
              "T": np.array([[-0.1], [0.0], [0.0]])}
    if size is not None:
        fs.write("image_width", size[0])
        fs.write("image_height", size[1])
    for k, v in values.items():
        if k not in skip:
            fs.write(k, v)
    fs.release()
    return values


class TestOpenCVCalib:
    def test_parse_file_written_by_filestorage(self, tmp_path):
        f = tmp_path / "stereo.yml"
        values = write_opencv_yaml(f)
        text = f.read_text()
        assert text.startswith("%YAML") and "!!opencv-matrix" in text
        c = calibration.parse_calibration(text, str(f))
        assert not c.rectified and c.size == (640, 480)
        for k in ("K1", "K2", "R"):
            assert np.allclose(getattr(c, k), values[k])
        assert np.allclose(c.T, [-0.1, 0, 0]) and c.baseline == pytest.approx(0.1)

    def test_parse_hand_written_yaml_1_0(self, tmp_path):
        f = tmp_path / "rig.yaml"
        m = "!!opencv-matrix\n   rows: {r}\n   cols: {c}\n   dt: d\n   data: [ {d} ]\n"
        f.write_text("%YAML:1.0\n---\nimage_size: [ 320, 240 ]\n"
                     + "K1: " + m.format(r=3, c=3, d="500., 0., 160., 0., 500., 120., 0., 0., 1.")
                     + "D1: " + m.format(r=1, c=5, d="0.1, -0.05, 0., 0., 0.")
                     + "K2: " + m.format(r=3, c=3, d="505., 0., 158., 0., 505., 121., 0., 0., 1.")
                     + "D2: " + m.format(r=1, c=4, d="0.09, -0.04, 0., 0.")
                     + "R: " + m.format(r=3, c=3, d="1., 0., 0., 0., 1., 0., 0., 0., 1.")
                     + "T: " + m.format(r=3, c=1, d="-60., 0.5, 0."))
        c = calibration.parse_calibration(f.read_text(), str(f))
        assert c.size == (320, 240) and c.K2[0, 0] == 505.0 and c.D1.shape == (5,) and c.D2.shape == (4,)
        assert c.baseline == pytest.approx(np.hypot(60.0, 0.5))

    @pytest.mark.parametrize("key", ["K1", "D1", "K2", "D2", "R", "T"])
    def test_missing_key(self, tmp_path, key):
        f = tmp_path / "stereo.yml"
        write_opencv_yaml(f, skip=(key,))
        with pytest.raises(InputError, match=rf"stereo\.yml: missing key `{key}`"):
            calibration.parse_calibration(f.read_text(), str(f))

    def test_size_mismatch_and_garbage(self, tmp_path):
        f = tmp_path / "stereo.yml"
        write_opencv_yaml(f)
        c = calibration.parse_calibration(f.read_text(), str(f))
        with pytest.raises(InputError, match=r"stereo\.yml: `image_size \(or K1/K2\)` says 640x480"):
            c.check_size((320, 240))
        with pytest.raises(InputError, match="bad.yml: not a readable OpenCV"):
            calibration.parse_opencv_calib("%YAML:1.0\nK1: [unclosed\n", "bad.yml")


def _yaml_matrix(rows, cols, data):
    return f"!!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: [ {data} ]\n"


def _opencv_text(**change):
    """A valid OpenCV stereo YAML of a 640x480 rig with some keys' values replaced (text after ``key: ``)."""
    values = {"image_width": "640\n", "image_height": "480\n",
              "K1": _yaml_matrix(3, 3, "600., 0., 319.5, 0., 600., 239.5, 0., 0., 1."),
              "D1": _yaml_matrix(1, 5, "0., 0., 0., 0., 0."),
              "K2": _yaml_matrix(3, 3, "600., 0., 319.5, 0., 600., 239.5, 0., 0., 1."),
              "D2": _yaml_matrix(1, 5, "0., 0., 0., 0., 0."),
              "R": _yaml_matrix(3, 3, "1., 0., 0., 0., 1., 0., 0., 0., 1."),
              "T": _yaml_matrix(3, 1, "-0.1, 0., 0.")}
    values.update(change)
    return "%YAML:1.0\n---\n" + "".join(f"{k}: {v}" for k, v in values.items() if v is not None)


class TestCalibrationLimits:
    """Every value of a calibration file is checked for finiteness and range; the message names file and key."""

    @pytest.mark.parametrize("old, new, match", [
        ("width=741", "width=1e400", r"c\.txt: `width` must be an integer in \[2, 1000000\], got '1e400'"),
        ("width=741", "width=384.7", r"`width` must be an integer in \[2, 1000000\], got '384\.7'"),
        ("height=500", "height=-5", r"`height` must be an integer in \[2, 1000000\], got '-5'"),
        ("ndisp=64", "ndisp=1e400", r"`ndisp` must be an integer in \[1, 741\], got '1e400'"),
        ("ndisp=64", "ndisp=0", r"`ndisp` must be an integer in \[1, 741\], got '0'"),
        ("ndisp=64", "ndisp=5000", r"`ndisp` must be an integer in \[1, 741\]"),
        ("baseline=193.001", "baseline=inf", r"`baseline` must be finite, got 'inf'"),
        ("baseline=193.001", "baseline=0", r"`baseline` must be > 0, got 0"),
        ("doffs=31.086", "doffs=nan", r"`doffs` must be finite"),
        ("doffs=31.086", "doffs=-1e9", r"`doffs` must be in \[-1482, 1482\] \(twice the width\), got -1e\+09"),
        ("[994.978 0 311.193;", "[994.978 0 1e300;", r"`cam0` principal point cx = 1e\+300 must be in "
                                                      r"\[-370\.5, 1111\.5\]"),
        ("0 994.978 254.877; 0 0 1]\ncam1", "0 994.978 -1e5; 0 0 1]\ncam1", r"`cam0` principal point cy"),
        ("0 994.978 254.877; 0 0 1]\ncam1", "0 -994.978 254.877; 0 0 1]\ncam1",
         r"`cam0` focal length fy = -994\.978 must be > 0"),
        ("[994.978 0 342.279;", "[0 0 342.279;", r"`cam1` focal length fx = 0 must be > 0"),
        ("0 0 1]\ncam1", "0 0 0]\ncam1", r"`cam0`\[2, 2\] must be 1 .*got 0"),
        ("0 0 1]\ncam1", "0.5 0 1]\ncam1", r"`cam0` must have zeros below the diagonal"),
        ("0 0 1]\ncam1", "0 0 nan]\ncam1", r"`cam0` contains NaN or inf"),
    ])
    def test_middlebury_values(self, old, new, match):
        assert old in MIDDLEBURY
        with pytest.raises(InputError, match=match) as info:
            calibration.parse_calibration(MIDDLEBURY.replace(old, new), "c.txt")
        assert info.value.file == "c.txt"

    @pytest.mark.parametrize("change, match", [
        ({"K1": "[1, 2, 3]\n"}, r"`K1` must be a 3x3 matrix \(!!opencv-matrix .*\), got a list of 3 values"),
        ({"K2": "5\n"}, r"`K2` must be a 3x3 matrix .*got a single value"),
        ({"K1": _yaml_matrix(1, 3, "1., 2., 3.")}, r"`K1` must have 9 entries"),
        ({"K1": _yaml_matrix(3, 3, "0., 0., 0., 0., 0., 0., 0., 0., 0.")}, r"`K1` focal length fx = 0 must be > 0"),
        ({"K2": _yaml_matrix(3, 3, "600., 0., 319.5, 0., -600., 239.5, 0., 0., 1.")}, r"`K2` focal length fy"),
        ({"K1": _yaml_matrix(3, 3, "600., 0., 319.5, 0., 600., 239.5, 0., 0., 0.")}, r"`K1`\[2, 2\] must be 1"),
        ({"K1": _yaml_matrix(3, 3, "600., 0., 1e300, 0., 600., 239.5, 0., 0., 1.")},
         r"`K1` principal point cx = 1e\+300 must be in \[-320, 960\]"),
        ({"image_width": ".inf\n"}, r"`image_width` must be an integer in \[2, 1000000\], got inf"),
        ({"image_height": "480.5\n"}, r"`image_height` must be an integer in \[2, 1000000\], got 480\.5"),
        ({"image_width": "wide\n"}, r"`image_width` must be an integer in \[2, 1000000\], got 'wide'"),
        ({"R": _yaml_matrix(3, 3, "-1., 0., 0., 0., 1., 0., 0., 0., 1.")}, r"`R` is not a rotation matrix"),
        ({"T": _yaml_matrix(3, 1, "0., 0., 0.")}, r"`T` is zero"),
        ({"D1": _yaml_matrix(1, 5, "0., .nan, 0., 0., 0.")}, r"`D1` contains NaN or inf"),
    ])
    def test_opencv_values(self, change, match):
        with pytest.raises(InputError, match=match) as info:
            calibration.parse_calibration(_opencv_text(**change), "rig.yml")
        assert info.value.file == "rig.yml"

    def test_valid_files_pass(self):
        assert calibration.parse_calibration(_opencv_text(), "rig.yml").size == (640, 480)
        assert calibration.parse_calibration(MIDDLEBURY.replace("width=741", "width=741.0"), "c.txt").size == \
            (741, 500)

    def test_principal_point_checked_against_the_images_when_the_file_gives_no_size(self):
        text = _opencv_text(image_width=None, image_height=None,
                            K2=_yaml_matrix(3, 3, "600., 0., 2000., 0., 600., 239.5, 0., 0., 1."))
        c = calibration.parse_calibration(text, "rig.yml")  # no size in the file: nothing to check cx against yet
        with pytest.raises(InputError, match=r"rig\.yml: `K2` principal point cx = 2000 must be in \[-320, 960\]"):
            c.check_size((640, 480))

    def test_nesting_bound_of_real_files_is_small(self, tmp_path):
        f = tmp_path / "stereo.yml"
        write_opencv_yaml(f)
        fs = cv2.FileStorage("x.xml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
        fs.write("K1", K)
        # written by OpenCV: two or three levels; a bound of at most 10 leaves the limit (64) far away
        for text in (f.read_text(), fs.releaseAndGetString(), MIDDLEBURY, _opencv_text()):
            assert calibration.nesting_bound(text) <= 10

    @pytest.mark.parametrize("text", [
        "%YAML:1.0\nK1: " + "[" * 100 + "]" * 100 + "\n",
        "%YAML:1.0\nK1: " + "{a: " * 100 + "1" + "}" * 100 + "\n",
        "%YAML:1.0\nK1:\n  " + "- " * 100 + "1\n",
        "%YAML:1.0\n" + "".join(" " * i + "a:\n" for i in range(100)),
        '<?xml version="1.0"?>\n<opencv_storage>' + "<a>" * 100 + "</a>" * 100 + "</opencv_storage>\n",
        "]]]]" + "[" * 100,  # surplus closing brackets first do not hide the nesting that follows
    ])
    def test_deep_nesting_refused_before_parsing(self, text):
        # 100 levels: deep enough to be refused, far too shallow to crash a parser if it were reached
        assert calibration.nesting_bound(text) >= 100
        with pytest.raises(InputError, match=r"deep\.yml: brackets, elements or blocks nested about \d+ levels "
                                             r"deep, over the limit of 64"):
            calibration.parse_calibration(text, "deep.yml")

    def test_text_over_the_limit(self):
        with pytest.raises(InputError, match=r"big\.txt: the calibration is \d+ characters long, over the limit of "
                                             r"1000000"):
            calibration.parse_calibration("#" * 1_000_001, "big.txt")

    def test_absurd_magnitudes_give_no_rectification(self):
        huge = _yaml_matrix(3, 3, "1e300, 0., 319.5, 0., 1e300, 239.5, 0., 0., 1.")
        c = calibration.parse_calibration(_opencv_text(K1=huge, K2=huge, R=_yaml_matrix(
            3, 3, "0.9998, 0., 0.0175, 0., 1., 0., -0.0175, 0., 0.9998")), "rig.yml")
        with pytest.raises(InputError, match=r"rig\.yml: `K1`, `K2`, `R` and `T` give no finite rectification"):
            rectify.rectify_calibrated(c, (640, 480))

    def test_baseline_of_extreme_translations_does_not_overflow(self):
        import warnings

        c = calibration.parse_calibration(MIDDLEBURY.replace("baseline=193.001", "baseline=1e300"), "c.txt")
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert c.baseline == 1e300
            assert calibration.parse_calibration(MIDDLEBURY.replace("baseline=193.001", "baseline=1e-300"),
                                                 "c.txt").baseline == 1e-300


class TestRectifiedGeometry:
    def test_opencv_rig_must_be_rectified_to_be_used_as_is(self, tmp_path):
        f = tmp_path / "stereo.yml"
        write_opencv_yaml(f)  # R is a small rotation: not a rectified rig
        c = calibration.parse_calibration(f.read_text(), str(f))
        with pytest.raises(InputError, match=r"stereo\.yml: the calibration describes cameras that are not "
                                             r"rectified .*add --rectify"):
            rectify.rectified_depth_geometry(c)
        fs = cv2.FileStorage("r.yml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
        K2 = K.copy()
        K2[0, 2] += 12.0
        for k, v in {"K1": K, "D1": np.zeros(5), "K2": K2, "D2": np.zeros(5), "R": np.eye(3),
                     "T": np.array([[-0.2], [0.0], [0.0]])}.items():
            fs.write(k, v)
        g = rectify.rectified_depth_geometry(calibration.parse_opencv_calib(fs.releaseAndGetString(), "r.yml"))
        # a rectified rig: doffs is the difference of the principal columns, the baseline |T|
        assert g.doffs == pytest.approx(12.0) and g.baseline == pytest.approx(0.2) and g.focal == 600.0


class TestCalibrated:
    def test_known_rig_is_rectified_and_gives_metric_depth(self):
        R = rotation(0.01, -0.02, 0.015)
        t = -R @ np.array([0.12, 0.005, 0.0])  # a 12 cm baseline, slightly off the x axis
        K2 = K.copy()
        K2[0, 2] += 8.0
        fs = cv2.FileStorage("x.yml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
        for k, v in {"K1": K, "D1": np.zeros(5), "K2": K2, "D2": np.zeros(5), "R": R, "T": t.reshape(3, 1)}.items():
            fs.write(k, v)
        calib = calibration.parse_opencv_calib(fs.releaseAndGetString(), "rig.yml")
        X = points(500, 9)
        p1, p2 = project(X, K), project(X, K2, R, t)
        rect = rectify.rectify_calibrated(calib, (W, H), p1, p2)
        q1, q2 = geometry.apply_homography(rect.H_left, p1), geometry.apply_homography(rect.H_right, p2)
        # exact data and no lens distortion: the rows agree to rounding, and depth from the disparity with the
        # reported geometry equals the depth along the rectified optical axis
        assert np.abs(q1[:, 1] - q2[:, 1]).max() < 1e-6
        d = q1[:, 0] - q2[:, 0]
        assert rectify.robust_disparity_range(d)[0] == pytest.approx(1.0, abs=1e-6) and d.max() < rect.max_disp
        g = rect.depth
        z = g.focal * g.baseline / (d + g.doffs)
        lx, ly, _, _ = rect.maps
        assert lx.shape == (H, W)
        # the rectified left camera is the left camera turned: depth is the z of the turned point
        Kr = np.array([[g.focal, 0, g.cx], [0, g.focal, g.cy], [0, 0, 1.0]])
        Rr = np.linalg.inv(Kr) @ rect.H_left @ K
        Rr /= np.cbrt(np.linalg.det(Rr))
        assert np.allclose(z, (X @ Rr.T)[:, 2], rtol=1e-6)


def test_max_disp_from_matches_refuses_an_unrectified_pair():
    rng = np.random.default_rng(0)
    p1 = rng.uniform(0, 600, (50, 2))
    p2 = p1 + np.array([-12.0, 0.0])
    assert rectify.max_disp_from_matches(p1, p2) == 16  # 12 px + 4 px headroom, rounded up to a multiple of 16
    with pytest.raises(EstimationError, match="does not look rectified"):
        rectify.max_disp_from_matches(p1, p1 + rng.normal(0, 20, p1.shape))


def test_unrectified_sample_is_rectified_against_its_truth():
    """The motorcycle sample with its right view turned: true correspondences from the true disparity of the
    original pair land on the same rows after our rectification of SIFT matches."""
    from cvpipe import io, samples
    from cvpipe.homography import correspondences

    ss, _ = samples.make_stereo_unrectified(np.random.default_rng(3))
    left, right = ss.images["motorcycle_unrectified/left.png"], ss.images["motorcycle_unrectified/right.png"]
    truth = ss.arrays["motorcycle_unrectified/truth.npz"]
    h, w = left.shape[:2]
    p1, p2 = correspondences(io.to_gray(left), io.to_gray(right))
    rect = rectify.rectify_uncalibrated(p1, p2, (w, h), rng=0)
    yy, xx = np.mgrid[0:h:4, 0:w:4]
    d = truth["disparity"][::4, ::4]
    ok = np.isfinite(d)
    pl = np.column_stack([xx[ok], yy[ok]]).astype(float)
    pr = geometry.apply_homography(truth["H_unrectify"], pl - np.column_stack([d[ok], np.zeros(ok.sum())]))
    err = np.abs(geometry.apply_homography(rect.H_left, pl)[:, 1] - geometry.apply_homography(rect.H_right, pr)[:, 1])
    # the rectification's targets (median 0.3 px, p95 1 px); measured ~0.1 / 0.3 px on this pair
    assert np.median(err) < 0.3 and np.percentile(err, 95) < 1.0
    disp = geometry.apply_homography(rect.H_left, pl)[:, 0] - geometry.apply_homography(rect.H_right, pr)[:, 0]
    # the search range 0 .. max_disp - 1 covers the scene (all but stray truth pixels)
    assert np.mean((disp >= -0.5) & (disp < rect.max_disp)) > 0.995


def test_looks_rectified():
    rng = np.random.default_rng(1)
    p1 = rng.uniform(0, 600, (200, 2))
    p2 = p1 - np.column_stack([rng.uniform(0, 40, 200), rng.normal(0, 0.2, 200)])
    assert rectify.looks_rectified(p1, p2)
    p2[:40, 1] += 30  # 20 % strays: the ratio test never leaves that many on a rectified pair
    assert not rectify.looks_rectified(p1, p2)
    _, _, c1, c2 = unrectified_pair(seed=0)
    assert not rectify.looks_rectified(c1, c2)
    with pytest.raises(InputError, match="`share`"):
        rectify.looks_rectified(p1, p2, share=0)


def test_robust_disparity_range_ignores_strays():
    rng = np.random.default_rng(2)
    d = np.concatenate([rng.uniform(5, 48, 330), [437.2, 437.2, -200.0]])
    lo, hi = rectify.robust_disparity_range(d)
    # the strays (two duplicate keypoints matched 400 px away, one far negative) are dropped: the range is the
    # scene's, within the nearest-rank 0.5 / 99.5 % trimming of 330 points (at most 2 points per end)
    assert 5 <= lo < 6 and 47 < hi <= 48
    with pytest.raises(EstimationError, match="no inlier matches"):
        rectify.robust_disparity_range([])


def test_robust_disparity_range_drops_a_group_of_strays():
    # an unrectified Tsukuba draw: three false matches at -6.5, -1.7 and 4.7 px, each within 8 px of the next, below
    # a scene at 20.6-31.7 px; dropping strays one gap at a time stopped at the first (4.8 px) gap and shifted the
    # disparities by 20 px
    rng = np.random.default_rng(5)
    scene = rng.uniform(20.6, 31.7, 355)
    lo, hi = rectify.robust_disparity_range(np.concatenate([scene, [-6.5, -1.7, 4.7]]))
    assert 20.6 <= lo < 21.0 and 31.3 < hi <= 31.7
    # a scene with a real gap (two surfaces 10 px apart, the nearer one 40 % of the points) keeps both: the cut is
    # only ever among the outermost 2 %
    two = np.concatenate([rng.uniform(0, 10, 200), rng.uniform(20, 30, 150)])
    lo, hi = rectify.robust_disparity_range(two)
    assert lo < 0.5 and hi > 29.5


def test_benchmark_truth_fundamental_and_noise_floor_reference():
    """`bench stereo --rectify`'s references: the true F of an unrectified pair satisfies the epipolar constraint
    of its true correspondences exactly, and the least-squares F of noise-free inliers is that F."""
    from cvpipe import stereo
    from cvpipe.bench import stereo_rectify as br
    from cvpipe.stereo import sampson_distance

    rng = np.random.default_rng(7)
    H_u, _ = br.unrectifying_homography(rng, (W, H))
    truth = rng.uniform(5.0, 60.0, (H, W)).astype(np.float32)  # any disparity field: a rectified original pair
    pl, pr = br.true_correspondences(truth, H_u, (W, H))
    F = br.true_fundamental(H_u)
    # exact up to rounding of pixel coordinates of a few hundred (float64): 1e-9 px
    assert np.abs(sampson_distance(F, pl, pr)).max() < 1e-9
    sample = rng.choice(len(pl), 300, replace=False)
    F_ls = stereo.sampson_least_squares(pl[sample], pr[sample])
    # the same matrix up to scale and sign (both unit Frobenius after normalization)
    Fa, Fb = F / np.linalg.norm(F), F_ls / np.linalg.norm(F_ls)
    assert min(np.abs(Fa - Fb).max(), np.abs(Fa + Fb).max()) < 1e-6

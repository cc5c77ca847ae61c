"""cvpipe.io: every validation branch names the file and says what was expected; writers are atomic."""

import errno
import json
import os
import pathlib
import re

import cv2
import numpy as np
import pytest

from cvpipe import io
from cvpipe.errors import InputError


@pytest.fixture
def png(tmp_path):
    img = (np.arange(40 * 30 * 3) % 251).astype(np.uint8).reshape(30, 40, 3)
    path = tmp_path / "img.png"
    cv2.imwrite(str(path), img)
    return path, img


def test_read_color_and_gray_roundtrip(png):
    path, img = png
    assert np.array_equal(io.read_image(path), img)
    gray = io.read_image(path, "gray")
    assert gray.shape == (30, 40) and gray.dtype == np.uint8


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"nope\.png: no such file"):
        io.read_image(tmp_path / "nope.png")


def test_folder_instead_of_file(tmp_path):
    with pytest.raises(InputError, match="is a folder"):
        io.read_image(tmp_path)


def test_empty_file(tmp_path):
    p = tmp_path / "empty.png"
    p.write_bytes(b"")
    with pytest.raises(InputError, match=r"empty\.png: file is empty"):
        io.read_image(p)


def test_not_an_image(tmp_path):
    p = tmp_path / "notes.jpg"
    p.write_text("this is not a picture")
    with pytest.raises(InputError, match=r"notes\.jpg: not a readable image"):
        io.read_image(p)


@pytest.mark.parametrize("suffix", [".png", ".jpg"])
def test_truncated_file(tmp_path, png, suffix):
    _, img = png
    ok, buf = cv2.imencode(suffix, np.tile(img, (8, 8, 1)))
    p = tmp_path / f"cut{suffix}"
    p.write_bytes(buf.tobytes()[: len(buf) // 2])
    with pytest.raises(InputError, match=rf"cut\{suffix}: truncated"):
        io.read_image(p)


def test_too_many_pixels_refused_before_decoding(png):
    path, _ = png
    with pytest.raises(InputError, match=r"40x30 = 1200 pixels exceeds the limit of 1000"):
        io.read_image(path, max_pixels=1000)


def test_too_small(tmp_path):
    p = tmp_path / "tiny.png"
    cv2.imwrite(str(p), np.zeros((4, 5), np.uint8))
    with pytest.raises(InputError, match=r"tiny\.png: 5x4 is too small"):
        io.read_image(p)


def test_bad_mode_and_limit(png):
    path, _ = png
    with pytest.raises(ValueError, match="`mode` must be one of"):
        io.read_image(path, "rgb")
    with pytest.raises(ValueError, match="`max_pixels` must be an integer >= 1"):
        io.read_image(path, max_pixels=0)


def test_sixteen_bit_is_scaled_to_uint8(tmp_path):
    p = tmp_path / "deep.png"
    cv2.imwrite(str(p), np.full((10, 10), 65535, np.uint16))
    img = io.read_image(p, "gray")
    assert img.dtype == np.uint8 and img.max() == 255
    assert io.read_image(p, "unchanged").dtype == np.uint16


def test_read_text_roundtrip_and_byte_order_mark(tmp_path):
    f = tmp_path / "calib.txt"
    f.write_bytes(b"\xef\xbb\xbfwidth=320\n")
    assert io.read_text(f, "calibration") == "width=320\n"


def test_read_text_refusals_name_the_file(tmp_path):
    with pytest.raises(InputError, match=r"nope\.txt: no such file") as info:
        io.read_text(tmp_path / "nope.txt")
    assert info.value.file == str(tmp_path / "nope.txt")
    with pytest.raises(InputError, match="is a folder, expected a calibration file"):
        io.read_text(tmp_path, "calibration")
    big = tmp_path / "big.txt"
    big.write_text("x" * 101)
    with pytest.raises(InputError, match=r"big\.txt: the calibration file is larger than the limit of 100 bytes"):
        io.read_text(big, "calibration", max_bytes=100)
    (tmp_path / "nul.txt").write_bytes(b"a=1\0")
    with pytest.raises(InputError, match="holds NUL bytes"):
        io.read_text(tmp_path / "nul.txt")
    (tmp_path / "latin.txt").write_bytes(b"caf\xe9=1\n")
    with pytest.raises(InputError, match=r"latin\.txt: not a UTF-8 text file \(byte 3 is 0xe9\)"):
        io.read_text(tmp_path / "latin.txt")
    with pytest.raises(ValueError, match="`max_bytes` must be an integer >= 1"):
        io.read_text(big, max_bytes=0)


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="no /dev/zero")
def test_read_text_stops_after_the_limit_on_an_endless_file():
    # /dev/zero never ends: only max_bytes + 1 bytes are read, then the file is refused
    with pytest.raises(InputError, match="/dev/zero: the calibration file is larger than the limit of 1000 bytes"):
        io.read_text("/dev/zero", "calibration", max_bytes=1000)


@pytest.mark.parametrize("orientation", range(1, 9))
def test_orient_agrees_with_pillow(orientation):
    from PIL import Image, ImageOps

    img = (np.arange(5 * 7 * 3) % 251).astype(np.uint8).reshape(5, 7, 3)
    pil = Image.fromarray(img)
    exif = pil.getexif()
    exif[io.EXIF_ORIENTATION] = orientation
    pil.info["exif"] = exif.tobytes()
    assert np.array_equal(io.orient(img, orientation), np.asarray(ImageOps.exif_transpose(pil)))


@pytest.mark.parametrize("suffix, fmt", [(".jpg", "JPEG"), (".png", "PNG"), (".webp", "WEBP")])
@pytest.mark.parametrize("orientation", [3, 6, 8])
def test_exif_orientation_is_applied_in_every_mode(tmp_path, suffix, fmt, orientation):
    from PIL import Image

    # a smooth picture with one bright corner block: JPEG keeps it within a few grey levels
    yy, xx = np.mgrid[0:48, 0:64]
    img = np.dstack([xx * 3, yy * 4, (xx + yy) * 2]).astype(np.uint8)
    img[:12, :16] = 255
    exif = Image.Exif()
    exif[io.EXIF_ORIENTATION] = orientation
    path = tmp_path / f"turned{suffix}"
    Image.fromarray(img[:, :, ::-1]).save(path, fmt, exif=exif.tobytes(),
                                          **({"lossless": True} if fmt == "WEBP" else {"quality": 95} if fmt == "JPEG"
                                             else {}))
    upright = io.orient(img, orientation)
    for mode in ("color", "unchanged", "gray"):
        got = io.read_image(path, mode)
        assert got.shape[:2] == upright.shape[:2], mode
        want = upright if mode != "gray" else cv2.cvtColor(upright, cv2.COLOR_BGR2GRAY)
        # lossless formats give the pixels back; JPEG's block coding is within a few levels on average
        assert np.abs(got.astype(int) - want).mean() < (4 if fmt == "JPEG" else 1), mode


def test_gray_and_bgr_conversion():
    # pure blue, green and red pixels and a mixed one: a swap of the B and R channels changes the grey of every pixel
    # whose blue and red differ (BT.601 weights 0.114, 0.587, 0.299); the alphas vary, and never enter the grey
    bgr = np.array([[[255, 0, 0], [0, 255, 0], [0, 0, 255], [30, 120, 210]]], np.uint8)
    bgra = np.dstack([bgr, np.array([[0, 80, 160, 255]], np.uint8)])
    np.testing.assert_array_equal(io.to_gray(bgr), cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY))
    np.testing.assert_array_equal(io.to_gray(bgra), cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY))
    assert io.to_gray(bgr).tolist() == [[29, 150, 76, 137]]  # round(0.114 B + 0.587 G + 0.299 R)
    np.testing.assert_array_equal(io.to_bgr(bgra), bgr)
    assert io.to_bgr(bgr) is bgr
    g = np.array([[0, 7, 128, 255]], np.uint8)
    np.testing.assert_array_equal(io.to_bgr(g), np.repeat(g[..., None], 3, axis=2))
    assert io.to_gray(g) is g
    with pytest.raises(ValueError, match="`img` must be"):
        io.to_gray(np.zeros((5, 6, 2), np.uint8))
    with pytest.raises(ValueError, match="`img` must be"):
        io.to_bgr(np.zeros((2, 5, 6, 3), np.uint8))


def test_list_images(tmp_path, png):
    (tmp_path / "readme.txt").write_text("x")
    assert [p.name for p in io.list_images(tmp_path)] == ["img.png"]
    with pytest.raises(InputError, match="no such folder"):
        io.list_images(tmp_path / "missing")


def test_npz_roundtrip_and_no_pickle(tmp_path):
    io.save_npz(tmp_path / "a.npz", xy=np.eye(3), name=np.array("sift"))
    back = io.load_npz(tmp_path / "a.npz")
    assert np.array_equal(back["xy"], np.eye(3)) and str(back["name"]) == "sift"
    with pytest.raises(ValueError, match="dtype object"):
        io.save_npz(tmp_path / "b.npz", bad=np.array([{"a": 1}], dtype=object))
    np.savez(tmp_path / "pickled.npz", obj=np.array([{"a": 1}], dtype=object))
    with pytest.raises(InputError, match=r"pickled\.npz: not a readable \.npz"):
        io.load_npz(tmp_path / "pickled.npz")
    with pytest.raises(InputError, match="no such file"):
        io.load_npz(tmp_path / "missing.npz")


def _damaged_npz(tmp_path, how):
    """An .npz written by save_npz (arrays `xy` and `detector`), then damaged as ``how`` says."""
    path = tmp_path / "x.npz"
    io.save_npz(path, xy=np.arange(4000, dtype=np.float32).reshape(-1, 2), detector=np.array("sift"))
    data = path.read_bytes()
    if how == "cut in half":
        path.write_bytes(data[:len(data) // 2])
    elif how == "last bytes cut":
        path.write_bytes(data[:-10])
    elif how == "empty":
        path.write_bytes(b"")
    elif how == "corrupted member":
        path.write_bytes(data[:100] + bytes(b ^ 0xFF for b in data[100:120]) + data[120:])
    elif how == "a bare .npy":
        np.save(tmp_path / "y.npy", np.eye(2))
        path.write_bytes((tmp_path / "y.npy").read_bytes())
    elif how == "text":
        path.write_text("xy,detector\n1,sift\n")
    return path


@pytest.mark.parametrize("how", ["cut in half", "last bytes cut", "empty", "corrupted member", "a bare .npy", "text"])
def test_damaged_npz_is_one_line_naming_the_file_and_the_expected_arrays(tmp_path, how):
    path = _damaged_npz(tmp_path, how)
    with pytest.raises(InputError, match=r"x\.npz: .*; expected an \.npz holding `xy`, `detector`$") as exc:
        io.load_npz(path, ("xy", "detector"))
    assert "\n" not in str(exc.value) and exc.value.file == str(path)


def test_npz_without_an_expected_array_names_the_missing_ones(tmp_path):
    io.save_npz(tmp_path / "x.npz", xy=np.eye(2))
    with pytest.raises(InputError, match=r"x\.npz: missing array\(s\) `detector`, `size`; expected an \.npz "
                                         r"holding `xy`, `detector`, `size`$"):
        io.load_npz(tmp_path / "x.npz", ("xy", "detector", "size"))
    assert set(io.load_npz(tmp_path / "x.npz", ("xy",))) == {"xy"}
    with pytest.raises(InputError, match=r"x\.npz: file is empty \(0 bytes\), expected an \.npz archive$"):
        io.load_npz(_damaged_npz(tmp_path, "empty"))


@pytest.mark.parametrize("damage, message", [
    (lambda d: d[:len(d) // 2], r"d\.npy: not a readable \.npy disparity array \("),
    (lambda d: b"", r"d\.npy: not a readable \.npy disparity array \("),
    (lambda d: b"x" + d[1:], r"d\.npy: not a readable \.npy disparity array \("),
])
def test_damaged_npy_is_one_line_naming_the_file(tmp_path, damage, message):
    path = tmp_path / "d.npy"
    np.save(path, np.ones((30, 40), np.float32))
    assert io.load_npy(path, "disparity").shape == (30, 40)
    path.write_bytes(damage(path.read_bytes()))
    with pytest.raises(InputError, match=message):
        io.load_npy(path, "disparity")
    io.save_npz(tmp_path / "z.npz", disparity=np.ones(3))
    with pytest.raises(InputError, match=r"z\.npz: an \.npz archive, expected a single \.npy disparity array$"):
        io.load_npy(tmp_path / "z.npz", "disparity")


def test_json_size_limit_and_nesting_name_the_file(tmp_path):
    path = tmp_path / "t.json"
    path.write_text(json.dumps({"a": list(range(100))}))
    with pytest.raises(InputError, match=r"t\.json: the truth JSON file is larger than the limit of 100 bytes$"):
        io.load_json(path, 100, "truth JSON")
    path.write_text("[" * 100_000 + "]" * 100_000)  # deeper than Python's parser recursion
    with pytest.raises(InputError, match=r"t\.json: not a usable JSON file \(lists or objects nested too deeply\)$"):
        io.load_json(path)
    path.write_bytes(b'{"a": "\xff"}')
    with pytest.raises(InputError, match=r"t\.json: not a UTF-8 JSON file \(byte 7 is 0xff\)$"):
        io.load_json(path)


def test_json_sorted_numpy_safe_and_errors(tmp_path):
    io.save_json(tmp_path / "m.json", {"b": np.float32(1.5), "a": np.arange(2), "c": float("nan")})
    text = (tmp_path / "m.json").read_text()
    assert text.index('"a"') < text.index('"b"')
    assert json.loads(text) == {"a": [0, 1], "b": 1.5, "c": None}
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(InputError, match=r"bad\.json: not valid JSON"):
        io.load_json(tmp_path / "bad.json")
    with pytest.raises(InputError, match="no such file"):
        io.load_json(tmp_path / "none.json")


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    dest = tmp_path / "out.json"
    dest.write_text("old")
    with pytest.raises(RuntimeError):
        with io.atomic_path(dest) as tmp:
            tmp.write_text("half")
            raise RuntimeError("interrupted")
    assert dest.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_save_image_roundtrip_and_bad_suffix(tmp_path, png):
    _, img = png
    io.save_image(tmp_path / "x.png", img)
    assert np.array_equal(io.read_image(tmp_path / "x.png"), img)
    bad = tmp_path / "x.unknownformat"
    message = f"image output must end in one of {', '.join(io.IMAGE_WRITE_SUFFIXES)}, got {bad} (.unknownformat)"
    with pytest.raises(InputError, match=re.escape(message)) as info:
        io.save_image(bad, img)
    assert info.value.file == str(bad)
    assert not (tmp_path / "x.unknownformat").exists()


# the overlay of a 9900 x 9900 input: two panels side by side, 196 megapixels, twice the read limit
OVERLAY = (9900, 19800)


def test_a_picture_of_the_pipeline_reads_back_under_the_read_limit(tmp_path):
    big = np.zeros(OVERLAY, np.uint8)
    big[4950, :] = 255  # one horizontal line across both panels
    assert big.size > io.DEFAULT_MAX_PIXELS
    io.save_picture(tmp_path / "overlay.png", big)
    back = io.read_image(tmp_path / "overlay.png", "unchanged")  # the report reads pictures so, at the default limit
    h, w = back.shape
    assert w * h <= io.PICTURE_MAX_PIXELS < io.DEFAULT_MAX_PIXELS
    assert abs(w / h - 2.0) < 2 / h  # the aspect ratio kept within a pixel's rounding
    # area averaging: the 1-pixel line becomes a faint row near the middle, not lost
    assert abs(int(back[:, w // 4].argmax()) - h // 2) <= 1 and back[:, w // 4].max() > 0


def test_fit_picture_leaves_a_small_picture_alone_and_never_exceeds_the_limit():
    small = np.zeros((30, 40, 3), np.uint8)
    assert io.fit_picture(small) is small
    for shape, limit in (((30, 40), 1200), ((30, 40), 1199), ((1, 50), 10), ((50, 1), 10), ((997, 13), 101)):
        got = io.fit_picture(np.zeros(shape, np.uint8), limit)
        assert got.shape[0] * got.shape[1] <= limit and min(got.shape) >= 1, (shape, limit, got.shape)
    assert io.picture_scale(200, 100, 5000) == pytest.approx(0.5)
    with pytest.raises(InputError, match=r"`max_pixels` must be an integer >= 1, got 0"):
        io.fit_picture(small, 0)


# ------------------------------------------------------------------------------------------- float and wide TIFFs


@pytest.fixture
def opencv_warnings():
    """OpenCV logging at its WARNING level, as a `cvpipe` command runs (the stages and this suite set ERROR)."""
    log = cv2.utils.logging
    before = log.getLogLevel()
    log.setLogLevel(log.LOG_LEVEL_WARNING)
    yield log.LOG_LEVEL_WARNING
    log.setLogLevel(before)


def test_a_float_tiff_in_0_1_reads_as_8_bit_with_nothing_on_stderr(tmp_path, opencv_warnings, capfd):
    rng = np.random.default_rng(0)
    gray32 = rng.random((24, 32)).astype(np.float32)
    bgr64 = rng.random((24, 32, 3))
    assert cv2.imwrite(str(tmp_path / "g.tif"), gray32) and cv2.imwrite(str(tmp_path / "c.tif"), bgr64)
    gray = io.read_image(tmp_path / "g.tif", "gray")
    # 0..1 maps to 0..255 rounded to the nearest level: half a level apart at most (and a float32 rounding)
    assert gray.dtype == np.uint8 and gray.shape == (24, 32)
    assert np.abs(gray - gray32 * 255.0).max() <= 0.5 + 1e-4
    assert np.array_equal(io.read_image(tmp_path / "g.tif", "color"), cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR))
    color = io.read_image(tmp_path / "c.tif", "color")
    assert color.dtype == np.uint8 and np.abs(color - bgr64 * 255.0).max() <= 0.5 + 1e-9
    assert np.array_equal(io.read_image(tmp_path / "c.tif", "gray"), cv2.cvtColor(color, cv2.COLOR_BGR2GRAY))
    assert io.read_image(tmp_path / "g.tif", "unchanged").dtype == np.float32  # unchanged keeps the samples
    assert capfd.readouterr().err == ""
    assert cv2.utils.logging.getLogLevel() == opencv_warnings  # the level in force before the read is back


@pytest.mark.parametrize("pixels, message", [
    (np.linspace(0, 255, 24 * 32, dtype=np.float32).reshape(24, 32),
     r"32-bit float TIFF with values in \[0, 255\]: expected 8- or 16-bit samples, or floats in \[0, 1\]"),
    (np.where(np.eye(24, 32) > 0, np.nan, 0.5),
     r"64-bit float TIFF holding NaN or infinity: expected 8- or 16-bit samples, or floats in \[0, 1\]"),
    (np.full((24, 32), 70000, np.int32), r"32-bit integer TIFF: expected 8- or 16-bit samples"),
    (np.full((24, 32), 7, np.uint32), r"32-bit integer TIFF: expected 8- or 16-bit samples"),
], ids=["float32 0..255", "float64 NaN", "int32", "uint32"])
def test_tiff_samples_that_are_not_scaled_are_one_line_naming_the_file(tmp_path, opencv_warnings, capfd, pixels,
                                                                        message):
    p = tmp_path / "wide.tif"
    assert cv2.imwrite(str(p), pixels)
    for mode in ("color", "gray"):
        with pytest.raises(InputError, match=rf"^{re.escape(str(p))}: {message}$") as info:
            io.read_image(p, mode)
        assert info.value.file == str(p)
    assert capfd.readouterr().err == ""  # no `[ WARN ] ... TIFFRGBAImageOK` line of OpenCV's
    assert cv2.utils.logging.getLogLevel() == opencv_warnings


def test_opencv_stays_quiet_until_the_last_of_concurrent_reads_ends(opencv_warnings):
    log = cv2.utils.logging
    with io.opencv_quiet():
        with io.opencv_quiet():  # another thread's read, begun while the first one runs
            assert log.getLogLevel() == log.LOG_LEVEL_SILENT
        assert log.getLogLevel() == log.LOG_LEVEL_SILENT
    assert log.getLogLevel() == opencv_warnings


# ------------------------------------------------------------------------------------------------- a full disk


def _full_disk(code):
    def write(*args, **kwargs):
        raise OSError(code, os.strerror(code))

    return write


NO_SPACE = [(errno.ENOSPC, "no space left on device"), (errno.EDQUOT, "disk quota exceeded")]
# each writer with the low-level call that puts its bytes on the disk
WRITERS = {
    "json": ("out.json", lambda p: io.save_json(p, {"a": 1}), (pathlib.Path, "write_text")),
    "image": ("out.png", lambda p: io.save_image(p, np.zeros((8, 8), np.uint8)), (pathlib.Path, "write_bytes")),
    "npz": ("out.npz", lambda p: io.save_npz(p, a=np.arange(3)), (np.lib.format, "write_array")),
}


@pytest.mark.parametrize("code, says", NO_SPACE, ids=["ENOSPC", "EDQUOT"])
@pytest.mark.parametrize("writer", sorted(WRITERS))
def test_a_full_disk_is_one_line_naming_the_file_being_written(tmp_path, monkeypatch, writer, code, says):
    name, write, (owner, low) = WRITERS[writer]
    dest = tmp_path / name
    dest.write_bytes(b"old")
    monkeypatch.setattr(owner, low, _full_disk(code))
    with pytest.raises(InputError, match=rf"^{re.escape(str(dest))}: {says} while writing$") as info:
        write(dest)
    assert info.value.file == str(dest)
    assert dest.read_bytes() == b"old" and [p.name for p in tmp_path.iterdir()] == [name]  # no temporary left


def test_a_full_disk_in_an_output_set_names_the_file_not_its_temporary(tmp_path, monkeypatch):
    old = tmp_path / "a.json"
    old.write_text("old")
    monkeypatch.setattr(pathlib.Path, "write_bytes", _full_disk(errno.ENOSPC))
    for name, write in (("b.png", lambda outs, p: io.save_image(outs.path(p), np.zeros((8, 8), np.uint8))),
                        ("c.ply", lambda outs, p: outs.path(p).write_bytes(b"ply"))):
        dest = tmp_path / name
        with pytest.raises(InputError, match=rf"^{re.escape(str(dest))}: no space left on device while writing$"):
            with io.all_or_none() as outs:
                io.save_json(outs.path(old), {"a": 1})
                write(outs, dest)
        assert old.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["a.json"]

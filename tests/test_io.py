"""cvpipe.io: every validation branch names the file and says what was expected; writers are atomic."""

import json
import os

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
    g = np.zeros((5, 6), np.uint8)
    assert io.to_bgr(g).shape == (5, 6, 3)
    assert io.to_gray(io.to_bgr(g)).shape == (5, 6)
    assert io.to_gray(np.zeros((5, 6, 4), np.uint8)).shape == (5, 6)
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
    with pytest.raises(Exception):
        io.save_image(tmp_path / "x.unknownformat", img)
    assert not (tmp_path / "x.unknownformat").exists()

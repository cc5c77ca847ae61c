"""Input classes of the bad-input sweep (tests/test_sweep.py): each writes one file (or folder) from a good image.

Kept apart from the test so that new commands and new classes join the table in one place each.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np


def texture(h: int, w: int, seed: int = 0) -> np.ndarray:
    """A (h, w, 3) uint8 photo-like texture: smooth noise at several scales plus a few shapes (keypoints, edges)."""
    rng = np.random.default_rng(seed)
    img = np.zeros((h, w), np.float32)
    for cell, amp in ((64, 0.5), (16, 0.3), (4, 0.2)):
        small = rng.random((max(2, h // cell), max(2, w // cell))).astype(np.float32)
        img += amp * cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    img = np.clip(img * 255.0, 0, 255).astype(np.uint8)
    for k in range(12):  # straight edges for the Hough transform
        x0, y0 = int(rng.integers(0, w)), int(rng.integers(0, h))
        cv2.rectangle(img, (x0, y0), (x0 + w // 6, y0 + h // 8), int(rng.integers(0, 256)), 3)
    return cv2.merge([img, np.roll(img, 7, axis=1), np.roll(img, 13, axis=0)])


def png_header_only(path: Path, width: int, height: int) -> None:
    """A PNG whose header declares ``width`` x ``height`` but which holds (almost) no pixels: cheap over-limit."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\x00" * 16))
                     + chunk(b"IEND", b""))


def make(kind: str, good: np.ndarray, folder: Path, name: str) -> Path:
    """Write input class ``kind`` derived from the good BGR image ``good`` as ``folder/name.<ext>``."""
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / f"{name}.png"
    if kind == "good":
        cv2.imwrite(str(p), good)
    elif kind == "missing":
        p = folder / f"{name}_missing.png"
    elif kind == "folder":
        p = folder / f"{name}_dir.png"
        p.mkdir()
    elif kind == "empty":
        p.write_bytes(b"")
    elif kind == "not_an_image":
        p = folder / f"{name}.jpg"
        p.write_text("this is a text file, not a JPEG\n")
    elif kind == "truncated":
        ok, buf = cv2.imencode(".png", good)
        p.write_bytes(buf.tobytes()[: len(buf) // 2])
    elif kind == "1x1":
        cv2.imwrite(str(p), good[:1, :1])
    elif kind == "blank":
        cv2.imwrite(str(p), np.full(good.shape, 128, np.uint8))
    elif kind == "16bit":
        cv2.imwrite(str(p), good.astype(np.uint16) * 257)
    elif kind == "alpha":
        cv2.imwrite(str(p), np.dstack([good, np.full(good.shape[:2], 255, np.uint8)]))
    elif kind == "grey":
        cv2.imwrite(str(p), cv2.cvtColor(good, cv2.COLOR_BGR2GRAY))
    elif kind == "exif_rotated":
        # stored turned 90 degrees counter-clockwise, with the EXIF orientation 6 that says "turn it clockwise to
        # view": read upright, it is the good image again (as a camera held sideways writes its JPEGs)
        from PIL import Image

        p = folder / f"{name}.jpg"
        exif = Image.Exif()
        exif[0x0112] = 6
        stored = np.ascontiguousarray(np.rot90(good, 1)[:, :, ::-1])
        Image.fromarray(stored).save(p, "JPEG", quality=95, exif=exif.tobytes())
    elif kind == "over_limit":
        png_header_only(p, 20_000, 10_000)  # 200 MP declared, a few bytes on disk
    else:
        raise KeyError(kind)
    return p

"""Stage `hough_edges`: Canny edge map (PNG, 255 = edge) of every sample image, input of both Hough implementations."""

import argparse
from pathlib import Path

from tqdm import tqdm

from cvpipe import hough, io
from cvpipe.params import HoughEdgesParams, load_section


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--images", required=True, help="folder of images (data/samples/hough)")
    ap.add_argument("--out", required=True, help="folder for <name>.png edge maps")
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(HoughEdgesParams, "hough.edges", args.params)
    files = io.list_images(args.images)
    for f in tqdm(files, desc="hough edges", disable=None):
        gray = io.read_image(f, "gray")
        edges = hough.canny_edges(gray, p.canny_low, p.canny_high, aperture=p.aperture, l2_gradient=p.l2_gradient,
                                  blur_sigma=p.blur_sigma)
        io.save_image(Path(args.out) / f"{f.stem}.png", edges)


if __name__ == "__main__":
    main()

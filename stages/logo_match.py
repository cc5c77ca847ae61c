"""Stage `logo_match@det`: match every scene's cached features against the indexed gallery, one .npz per scene."""

import argparse
import time
from pathlib import Path

from tqdm import tqdm

from cvpipe import io, logos
from cvpipe.features import Features
from cvpipe.params import LogoMatchParams, load_section


def load_gallery_features(folder: Path, params: LogoMatchParams) -> logos.Gallery:
    """Gallery from cached feature files laid out like the images: <brand>.npz or <brand>/*.npz."""
    refs = []
    for f in sorted(folder.rglob("*.npz")):
        brand = f.stem if f.parent == folder else f.relative_to(folder).parts[0]
        arrays = io.load_npz(f)
        w, h = (int(v) for v in arrays["image_size"])
        refs.append(logos.Reference(brand, str(f), Features.from_arrays(arrays), (w, h)))
    return logos.build_gallery(refs, params.min_features, params.reference_features, params.register_references)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--gallery", required=True, help="folder of gallery feature .npz files")
    ap.add_argument("--scenes", required=True, help="folder of scene feature .npz files")
    ap.add_argument("--out", required=True)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = load_section(LogoMatchParams, "logo.match", args.params)
    gallery = load_gallery_features(Path(args.gallery), p)
    out, times = Path(args.out), {}
    for f in tqdm(sorted(Path(args.scenes).glob("*.npz")), desc=f"match {gallery.detector}", disable=None):
        scene = Features.from_arrays(io.load_npz(f))
        t0 = time.perf_counter()
        m = logos.match_scene(gallery, scene, p)
        times[f.stem] = time.perf_counter() - t0
        io.save_npz(out / f.name, **m.to_arrays())
    io.save_json(out / "timings.json", {"match_s": times, "references": len(gallery.references),
                                        "dropped": list(gallery.dropped)})


if __name__ == "__main__":
    main()

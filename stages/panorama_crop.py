"""Stage `panorama_crop`: per set, the largest axis-aligned rectangle of the blended panorama with no empty pixel
(`<out>/<set>.png`, `<set>.json`; a failed set is recorded in its JSON)."""

from pathlib import Path

from cvpipe import blending, io
from stages._runner import Stage, run


def panorama_crop(st: Stage) -> None:
    src, out = Path(st.args.blend), Path(st.args.out)
    made = upstream = 0
    for f in st.progress(sorted(src.glob("*.json")), "panorama crop"):
        meta = io.load_json(f)
        result = {"ok": False, "error": meta.get("error"), "failed_in": meta.get("failed_in")}
        if not meta["ok"]:
            upstream += 1
        else:
            pano = io.read_image(src / f"{f.stem}.png", "color")
            mask = io.read_image(src / f"{f.stem}_mask.png", "gray") > 0
            with st.timer("crop"):
                x, y, w, h = blending.largest_rectangle(mask)
            if w * h == 0:
                result.update(error="no pixel of the panorama is covered by an image", failed_in="panorama_crop")
                st.drop(f.stem, result["error"])
            else:
                result = {"ok": True, "crop": [x, y, w, h], "size": [w, h],
                          "empty_share": float(1.0 - mask[y:y + h, x:x + w].mean()),
                          "empty_share_uncropped": float(1.0 - mask.mean())}
                io.save_image(out / f"{f.stem}.png", pano[y:y + h, x:x + w])
                made += 1
        io.save_json(out / f"{f.stem}.json", result)
    out.mkdir(parents=True, exist_ok=True)
    st.made(f"{made} cropped panoramas in {out}" + (f" ({upstream} sets failed earlier)" if upstream else ""))


if __name__ == "__main__":
    run(panorama_crop, args={"blend": "panorama_blend output", "out": "folder for <set>.png and <set>.json"})

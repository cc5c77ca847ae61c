"""Stage `panorama_crop`: per set, the largest axis-aligned rectangle of the blended panorama with no empty pixel
(`<out>/<set>.png`, `<set>.json`; a failed set is recorded in its JSON)."""

from pathlib import Path

from cvpipe import io, panorama
from cvpipe.errors import EstimationError
from ._runner import Stage, run


def _crop(st: Stage, src: Path, name: str, out: Path) -> dict:
    pano = io.read_image(src / f"{name}.png", "color")
    mask = io.read_image(src / f"{name}_mask.png", "gray") > 0
    with st.timer("crop"):
        x, y, w, h = panorama.largest_rectangle(mask)
    if w * h == 0:
        raise EstimationError("no pixel of the panorama is covered by an image")
    io.save_image(out / f"{name}.png", pano[y:y + h, x:x + w])
    return {"ok": True, "crop": [x, y, w, h], "size": [w, h], "empty_share": float(1.0 - mask[y:y + h, x:x + w].mean()),
            "empty_share_uncropped": float(1.0 - mask.mean())}


def panorama_crop(st: Stage) -> None:
    src, out, records = Path(st.args.blend), Path(st.args.out), []
    for f in st.progress(sorted(src.glob("*.json")), "panorama crop"):
        rec = st.step_record(io.load_json(f), f.stem, lambda: _crop(st, src, f.stem, out))
        io.save_json(out / f"{f.stem}.json", rec)
        records.append(rec)
    out.mkdir(parents=True, exist_ok=True)
    st.made(st.step_summary(records, f"cropped panoramas in {out}"))


if __name__ == "__main__":
    run(panorama_crop, args={"blend": "panorama_blend output", "out": "folder for <set>.png and <set>.json"})

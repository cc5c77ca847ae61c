"""Stage `samples`: build the bundled sample data set into data/samples/<task>/ (images, truth.json and the
further truth / calibration files).

This folder is this stage's output: it is replaced whenever the stage reruns. Your own images go elsewhere
(data/mine/..., see the README's "Your own images")."""

import shutil
from pathlib import Path

from cvpipe import io, samples
from ._runner import Stage, run


def build_samples(st: Stage) -> None:
    sets = samples.build(st.params)
    out = Path(st.args.out)
    tmp = out.with_name(f".{out.name}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    for task, s in st.progress(sets.items(), "samples"):
        for name, img in s.images.items():
            io.save_image(tmp / task / name, img)
        for name, arrays in s.arrays.items():
            io.save_npz(tmp / task / name, **arrays)
        for name, text in s.texts.items():
            (tmp / task / name).parent.mkdir(parents=True, exist_ok=True)
            (tmp / task / name).write_text(text, encoding="utf-8")
        for name, doc in s.docs.items():
            io.save_json(tmp / task / name, doc)
        if s.truth:
            io.save_json(tmp / task / "truth.json", s.truth)
    (tmp / "README.md").write_text(samples.README, encoding="utf-8")
    shutil.rmtree(out, ignore_errors=True)
    tmp.rename(out)  # the finished folder appears in one step
    st.made(f"{sum(len(s.images) for s in sets.values())} images in {out}")


if __name__ == "__main__":
    run(build_samples, name="samples", section="samples", args={"out": "the sample folder (data/samples)"})

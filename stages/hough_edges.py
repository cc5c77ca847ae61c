"""Stage `hough_edges`: Canny edge map (PNG, 255 = edge) of every image of `hough.data`, input of both Hough
implementations. Layout: the images directly in the folder (truth.json optional)."""

from pathlib import Path

from cvpipe import datasets, hough, io
from cvpipe.errors import InputError
from ._runner import Stage, run


def hough_edges(st: Stage) -> None:
    p, out = st.params, Path(st.args.out)
    items, _ = datasets.find_hough(st.args.images)
    made = 0
    for it in st.progress(items, "hough edges"):
        try:
            gray = io.read_image(it.path, "gray")
        except InputError as exc:
            st.drop(it.path.name, str(exc))
            continue
        edges = hough.edges_of(gray, p)
        io.save_image(out / f"{it.name}.png", edges)
        made += 1
    st.finish(out, made, f"edge maps in {out}", f"{st.args.images}: no readable image")


if __name__ == "__main__":
    run(hough_edges, section="hough.edges", args={"images": "the hough.data folder", "out": "folder for <name>.png"})

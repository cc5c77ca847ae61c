"""Stage `stereo_depth`: for every pair with a calibration, depth from the `stereo.depth.method` disparity,
``Z = f * baseline / (d + doffs)`` in the calibration's unit: ``<pair>/depth.npy`` (float32, NaN = invalid),
``<pair>/depth.png`` (colour-mapped, colour bar with the unit) and ``<pair>/cloud.ply`` (binary PLY, x y z and the
left image's colours of the valid pixels; camera frame: x right, y down, z forward); ``run.json`` lists them and the
pairs without a calibration ("disparity only"); plus the metrics file."""

from pathlib import Path

import numpy as np

from cvpipe import io, stereo
from cvpipe.stereo import depth
from cvpipe.errors import InputError
from ._runner import Stage, run


def stereo_depth(st: Stage) -> None:
    a = st.args
    if (a.disparities is None) == (a.disparities_root is None):
        raise InputError("give one of --disparities FOLDER or --disparities-root FOLDER")
    # the method is read from the validated section, never from the command line, so it is one of its choices
    disparities = Path(a.disparities) if a.disparities is not None else Path(a.disparities_root) / st.params.method
    rectified, out = Path(a.rectified), Path(a.out)
    rects = io.load_json(rectified / "run.json")["pairs"]
    disp_run = io.load_json(disparities / "run.json")
    results, units, only = {}, {}, []
    for name in st.progress(sorted(disp_run["pairs"]), "depth"):
        geo = rects[name].get("depth")
        if geo is None:
            only.append(name)
            continue
        disp = io.load_npy(disparities / name / "disparity.npy", "disparity")
        try:
            z = depth.depth_from_disparity(disp, geo["focal"], geo["baseline"], geo["doffs"])
            left = io.read_image(rectified / name / "left.png")
            xyz, rgb = depth.point_cloud(z, left, geo["focal"], geo["cx"], geo["cy"])
        except InputError as exc:
            calib = rects[name].get("calib")
            st.drop(name, f"no depth: {calib + ': ' if calib else ''}{exc}")
            continue
        with io.atomic_path(out / name / "depth.npy") as tmp:
            with open(tmp, "wb") as fh:
                np.save(fh, z, allow_pickle=False)
        io.save_image(out / name / "depth.png", depth.colorize(z, unit=geo["unit"], label="depth"))
        comment = f"units {geo['unit']}; camera frame of the rectified left image: x right, y down, z forward"
        with io.atomic_path(out / name / "cloud.ply") as tmp:
            tmp.write_bytes(depth.ply_bytes(xyz, rgb, comment=comment))
        results[name], units[name] = stereo.depth_result(z, len(xyz), geo), geo["unit"]
    io.save_json(out / "run.json", {"method": disp_run["method"], "pairs": results, "units": units,
                                    "disparity_only": only, "dropped": st.dropped})
    st.save_metrics(a.metrics, stereo.depth_metrics(results))
    st.made(f"{len(results)} depth maps and point clouds in {out}" +
            (f"; disparity only (no calibration): {', '.join(only)}" if only else ""))


if __name__ == "__main__":
    run(stereo_depth, section="stereo.depth",
        args={"rectified": "stereo_rectify's output folder",
              "out": "folder for <pair>/depth.npy|png, cloud.ply and run.json", "metrics": "metrics JSON"},
        options={"disparities": {"help": "a stereo_disparity output folder"},
                 "disparities-root": {"help": "the folder of the stereo_disparity output folders, one per method: "
                                              "the stage reads <folder>/<stereo.depth.method>"}})

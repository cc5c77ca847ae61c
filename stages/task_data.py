"""Stage `<task>_data`: the task's input folder (``<task>.data``), checked before any stage reads it.

It runs first in each task and whenever ``<task>.data`` changes, and it depends on no file of the folder, so that
it runs even where the folder is missing: in DVC's temporary copy of the repository for a queued experiment, a folder
that neither git nor DVC tracks is absent, and this stage says so in one line, with how to track it (every later
stage would otherwise stop at DVC's own "No such file or directory"). In the workspace, a folder that neither tracks
gets a note, since queued experiments will not see it. Its output names the folder; the stages that read the folder
depend on it, which orders them after this one.
"""

import subprocess
from pathlib import Path

from cvpipe import io
from ._runner import Stage, run


def stage_outputs(dvc_yaml: str = "dvc.yaml") -> set[Path]:
    """The outputs that the stages of ``dvc_yaml`` name literally (``data/samples``): DVC restores them in every
    copy of the repository from its cache."""
    import yaml

    try:
        stages = (yaml.safe_load(Path(dvc_yaml).read_text(encoding="utf-8")) or {}).get("stages", {})
    except (OSError, yaml.YAMLError):
        return set()
    return {Path(o) for st in stages.values() if isinstance(st, dict) for o in st.get("outs", [])
            if isinstance(o, str) and "$" not in o}


def tracked_by(folder: str) -> str | None:
    """How a copy of the repository gets ``folder``: ``"dvc"`` when it or a folder above it has a ``.dvc`` file
    beside it or is a stage's output, ``"git"`` when git tracks a file in it, else None (also outside git)."""
    p = Path(folder)
    outs = stage_outputs()
    for up in (p, *p.parents):
        if up != Path(".") and (up.with_name(up.name + ".dvc").is_file() or up in outs):
            return "dvc"
    try:
        listed = subprocess.run(["git", "ls-files", "--", folder], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.SubprocessError):
        return None
    return "git" if listed.returncode == 0 and listed.stdout.strip() else None


def task_data(st: Stage) -> None:
    folder = st.args.images
    io.save_json(st.args.out, {"data": folder})
    st.made(f"{folder} -> {st.args.out}")
    if tracked_by(folder) is None:
        st.made(f"note: {folder} is tracked by neither git nor DVC, so queued experiments will not see it "
                f"(`dvc add {folder}`, then commit {folder}.dvc)")


if __name__ == "__main__":
    run(task_data, args={"images": "the task's input folder", "out": "JSON file naming it"})

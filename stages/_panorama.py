"""What the panorama stages after the registration share: a set's record carried through a step.

Each of ``panorama_warp``, ``panorama_blend`` and ``panorama_crop`` writes one record per set; a set that failed
earlier keeps its reason and the stage that gave it, so the report can say which set failed, where and why.
"""

from __future__ import annotations

from typing import Callable, Sequence

from cvpipe.errors import EstimationError


def step_record(prev: dict, stage: str, name: str, step: Callable[[], dict],
                drop: Callable[[str, str], None]) -> dict:
    """One set's record at ``stage``: the earlier failure carried on, else ``step()``'s record, else (``step``
    raised :class:`~cvpipe.errors.EstimationError`) this stage's failure, also passed to ``drop(name, reason)``
    so that the stage's summary line names it.

    Returns
    -------
    dict
        ``{"ok": True, ...}`` or ``{"ok": False, "error", "failed_in"}`` (the stage that failed).
    """
    if not prev.get("ok"):
        return {"ok": False, "error": prev.get("error"), "failed_in": prev.get("failed_in")}
    try:
        return step()
    except EstimationError as exc:
        drop(name, str(exc))
        return {"ok": False, "error": str(exc), "failed_in": stage}


def step_summary(records: Sequence[dict], stage: str, what: str) -> str:
    """``"2 sets warped ... (1 failed in an earlier stage)"`` for the summary line of ``stage`` (its own failures
    are in the line's dropped list)."""
    ok = sum(1 for r in records if r["ok"])
    earlier = sum(1 for r in records if not r["ok"] and r.get("failed_in") != stage)
    return f"{ok} {what}" + (f" ({earlier} failed in an earlier stage)" if earlier else "")

"""What the panorama stages after the registration share: a set's record carried through a step.

Each of ``panorama_warp``, ``panorama_blend`` and ``panorama_crop`` writes one record per set; a set that failed
earlier keeps its reason and the stage that gave it, so the report can say which set failed, where and why.
"""

from __future__ import annotations

from typing import Any, Callable, Iterator, Sequence

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


def map_sets(st, stage: str, sets: Sequence[tuple[str, dict]], fn: Callable, data: Callable[[str, dict], Any],
             shared: Any, desc: str) -> Iterator[tuple[str, dict | None, Any]]:
    """Run ``fn`` on every set that has not failed earlier through ``st.map`` (in process or on a cluster) and
    yield ``(name, failure record or None, fn's value or None)`` for every set, in order.

    ``sets`` are ``(name, record of the earlier step)``; a record without ``ok`` counts as ok. ``data(name,
    prev)`` reads a set's item (lazily, here). A set that failed earlier is carried (:func:`step_record`); one
    whose ``fn`` raised is this stage's failure, already dropped with its reason by ``st.map``.
    """
    todo = [(n, prev) for n, prev in sets if prev.get("ok", True)]
    results = st.map(fn, (data(n, prev) for n, prev in todo), shared=shared, desc=desc, names=[n for n, _ in todo])
    pending = None
    for name, prev in sets:
        if not prev.get("ok", True):
            yield name, step_record(prev, stage, name, dict, st.drop), None
            continue
        if pending is None:
            pending = next(results, None)
        if pending is not None and pending[0] == name:
            yield name, None, pending[1]
            pending = None
        else:
            reason = next(d["reason"] for d in reversed(st.dropped) if d["item"] == name)
            yield name, {"ok": False, "error": reason, "failed_in": stage}, None

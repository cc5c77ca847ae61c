"""Small SVG charts for BENCHMARKS.md, written as plain text (no plotting library, a few kilobytes each).

The output depends only on the data given (no dates, no random ids), so the same JSON results always give the same
bytes. Two shapes: :func:`xy_chart` (lines and/or points per series, optional log x) and :func:`bar_chart` (grouped
bars per category).
"""

from __future__ import annotations

import math
from html import escape

WIDTH, HEIGHT = 520, 300
LEFT, RIGHT, TOP, BOTTOM = 58, 150, 30, 46
#: series colours, in order (colour-blind safe: Okabe-Ito)
COLOURS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000")


def _num(v: float) -> str:
    return f"{v:.1f}".rstrip("0").rstrip(".")


def _label(v: float) -> str:
    if v == 0:
        return "0"
    if abs(v) >= 1000 or abs(v) < 0.01:
        return f"{v:.0e}".replace("e+0", "e").replace("e-0", "e-")
    return f"{v:.3g}"


def _ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    """About ``n`` round tick values covering [lo, hi]."""
    if hi <= lo:
        hi = lo + 1.0
    raw = (hi - lo) / n
    step = 10 ** math.floor(math.log10(raw))
    step *= next(m for m in (1, 2, 2.5, 5, 10) if raw <= m * step)
    first, last = math.floor(lo / step + 1e-9), math.ceil(hi / step - 1e-9)
    return [round(k * step, 12) for k in range(first, last + 1)]


def _frame(title: str, xlabel: str, ylabel: str) -> list[str]:
    return [f'<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" '
            f'viewBox="0 0 {WIDTH} {HEIGHT}" font-family="sans-serif" font-size="11">',
            f'<rect width="{WIDTH}" height="{HEIGHT}" fill="white"/>',
            f'<text x="{LEFT}" y="18" font-size="12" font-weight="bold">{escape(title)}</text>',
            f'<text x="{(LEFT + WIDTH - RIGHT) / 2:.0f}" y="{HEIGHT - 8}" text-anchor="middle">{escape(xlabel)}</text>',
            f'<text transform="translate(14 {(TOP + HEIGHT - BOTTOM) / 2:.0f}) rotate(-90)" '
            f'text-anchor="middle">{escape(ylabel)}</text>']


def _legend(names: list[str]) -> list[str]:
    x = WIDTH - RIGHT + 12
    out = []
    for i, name in enumerate(names):
        y = TOP + 8 + 16 * i
        out.append(f'<rect x="{x}" y="{y - 8}" width="10" height="10" fill="{COLOURS[i % len(COLOURS)]}"/>')
        out.append(f'<text x="{x + 15}" y="{y + 1}">{escape(name)}</text>')
    return out


def _axes(xt: list[tuple[float, str]], yt: list[tuple[float, str]], x_font: int = 11) -> list[str]:
    x0, x1, y0, y1 = LEFT, WIDTH - RIGHT, HEIGHT - BOTTOM, TOP
    out = [f'<path d="M{x0} {y1}V{y0}H{x1}" fill="none" stroke="#444"/>']
    size = "" if x_font == 11 else f' font-size="{x_font}"'
    for px, text in xt:
        out.append(f'<path d="M{_num(px)} {y0}v4" stroke="#444"/>')
        out.append(f'<text x="{_num(px)}" y="{y0 + 16}" text-anchor="middle"{size}>{escape(text)}</text>')
    for py, text in yt:
        out.append(f'<path d="M{x0 - 4} {_num(py)}H{x1}" stroke="#ddd"/>')
        out.append(f'<text x="{x0 - 7}" y="{_num(py + 4)}" text-anchor="end">{escape(text)}</text>')
    return out


def xy_chart(series: dict[str, list[tuple[float, float]]], title: str, xlabel: str, ylabel: str, *,
             lines: bool = True, log_x: bool = False, x_range: tuple[float, float] | None = None,
             y_range: tuple[float, float] | None = None) -> str:
    """An SVG of each series' (x, y) points, joined by lines (``lines``) or as dots; non-finite points are left out.

    Parameters
    ----------
    series : dict
        Legend name -> list of (x, y), in drawing order.
    log_x : bool
        Logarithmic x axis (every x must then be > 0).
    x_range, y_range : (float, float), optional
        Axis ranges; by default from the data (y from 0 when all y >= 0).
    """
    pts = {k: [(float(x), float(y)) for x, y in v if x is not None and y is not None
               and math.isfinite(x) and math.isfinite(y) and (not log_x or x > 0)] for k, v in series.items()}
    xs = [x for v in pts.values() for x, _ in v] or [0.0, 1.0]
    ys = [y for v in pts.values() for _, y in v] or [0.0, 1.0]
    fx = (lambda x: math.log10(x)) if log_x else (lambda x: x)
    if x_range:
        xlo, xhi = fx(x_range[0]), fx(x_range[1])
    else:
        xlo, xhi = fx(min(xs)), fx(max(xs))
        if xhi == xlo:
            xlo, xhi = xlo - 0.5, xhi + 0.5
    yt_vals = _ticks(min(0.0, min(ys)) if y_range is None else y_range[0], max(ys) if y_range is None else y_range[1])
    ylo, yhi = (yt_vals[0], yt_vals[-1]) if y_range is None else y_range
    if log_x:
        xt_vals = [10.0 ** k for k in range(math.floor(xlo), math.ceil(xhi) + 1)]
        xlo, xhi = math.log10(xt_vals[0]), math.log10(xt_vals[-1])
    else:
        xt_vals = _ticks(xlo, xhi)
        if not x_range:
            xlo, xhi = xt_vals[0], xt_vals[-1]
    px = (lambda x: LEFT + (fx(x) - xlo) / (xhi - xlo) * (WIDTH - RIGHT - LEFT))
    py = (lambda y: HEIGHT - BOTTOM - (y - ylo) / (yhi - ylo) * (HEIGHT - BOTTOM - TOP))
    out = _frame(title, xlabel, ylabel)
    out += _axes([(px(v), _label(v)) for v in xt_vals if xlo - 1e-9 <= fx(v) <= xhi + 1e-9],
                 [(py(v), _label(v)) for v in yt_vals if ylo - 1e-9 <= v <= yhi + 1e-9])
    for i, (name, v) in enumerate(pts.items()):
        colour = COLOURS[i % len(COLOURS)]
        if lines and len(v) > 1:
            d = "M" + "L".join(f"{_num(px(x))} {_num(py(y))}" for x, y in v)
            out.append(f'<path d="{d}" fill="none" stroke="{colour}" stroke-width="1.8"/>')
        if not lines or len(v) <= 12:
            out += [f'<circle cx="{_num(px(x))}" cy="{_num(py(y))}" r="3" fill="{colour}"/>' for x, y in v]
    out += _legend(list(pts)) + ["</svg>"]
    return "\n".join(out) + "\n"


def bar_chart(categories: list[str], series: dict[str, list[float | None]], title: str, ylabel: str) -> str:
    """An SVG of grouped bars: one group per category, one bar per series (None: no bar)."""
    ys = [v for vals in series.values() for v in vals if v is not None and math.isfinite(v)] or [1.0]
    yt_vals = _ticks(0.0, max(ys))
    yhi = yt_vals[-1]
    span = (WIDTH - RIGHT - LEFT) / max(len(categories), 1)
    bar = span * 0.8 / max(len(series), 1)
    py = (lambda y: HEIGHT - BOTTOM - y / yhi * (HEIGHT - BOTTOM - TOP))
    out = _frame(title, "", ylabel)
    # category names in a smaller type when a group is narrow (about 5.5 px per character at size 9)
    x_font = 11 if max((len(c) for c in categories), default=0) * 6.5 < span else 9
    out += _axes([(LEFT + span * (i + 0.5), c) for i, c in enumerate(categories)],
                 [(py(v), _label(v)) for v in yt_vals], x_font)
    for j, (name, vals) in enumerate(series.items()):
        colour = COLOURS[j % len(COLOURS)]
        for i, v in enumerate(vals):
            if v is None or not math.isfinite(v):
                continue
            x = LEFT + span * i + span * 0.1 + bar * j
            out.append(f'<rect x="{_num(x)}" y="{_num(py(v))}" width="{_num(bar)}" '
                       f'height="{_num(py(0) - py(v))}" fill="{colour}"/>')
    out += _legend(list(series)) + ["</svg>"]
    return "\n".join(out) + "\n"

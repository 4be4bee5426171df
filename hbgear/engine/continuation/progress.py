"""The continuation's progress bar on stderr; tqdm is imported only when a bar is shown."""

from __future__ import annotations

import sys


def _progress_bar(progress, p0, p_end):
    """A tqdm bar in % of ``[p0, p_end]`` on stderr, or ``None``: `progress` False, or ``None``
    and stderr not a terminal, or tqdm not installed."""
    if progress is False:
        return None
    if progress is None and not (hasattr(sys.stderr, "isatty") and sys.stderr.isatty()):
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover
        return None
    return tqdm(total=100, desc=f"continuation {p0:.6g} -> {p_end:.6g}", unit="%", leave=False, file=sys.stderr,
                bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}{postfix}]")


def _advance_bar(bar, y, scale, p0, p_end, points, ds):
    """Show the progress at the scaled point `y` (``p = y[-1] p_ref``), the points stored and ``ds``."""
    bar.n = round(100 * min(1.0, max(0.0, (y[-1] * scale - p0) / (p_end - p0))), 1)
    bar.set_postfix(p=f"{y[-1] * scale:.6g}", points=points, ds=f"{ds:.2g}", refresh=False)
    bar.refresh()


"""The lines under the pair actions at the top of the control panel: the live solve's figures in one line, and
guided picking's status (which proposal, what to click, why nothing is proposed).

In the by-eye walkthrough (issue 20) both sat far down the scrolling panel: "Next pair" with 2 pairs changed
nothing in view, and the errors were wheel-scrolls away.  No maths here: the figures are the ones the live solve
published (:class:`app.ui_common.SolveBundle`), the guided text is the Guide panel's own.
"""

from __future__ import annotations

import threading
from typing import Any

from calib_core.solve.quality import NO_ERROR_ESTIMATE, error_estimate_reason, pairs_in_fit

from .ui_common import _fmt


def live_summary(live: Any) -> str:
    """``"N pairs · mean X px · left out Y px · Quality: ok"`` (markdown) of the solve ``live.bundle`` shows, or ""
    before the first solve.  N is the pairs in the fit; with too few for an error figure the mean says so."""
    bundle = getattr(live, "bundle", None)
    r = getattr(bundle, "result", None)
    if r is None:
        return ""
    n_fit = pairs_in_fit(r)
    quality = getattr(r, "quality", None)
    status = str(getattr(quality, "status", "ok"))
    loo = getattr(quality, "leave_one_out", None)
    loo_mean = float("nan") if loo is None else loo.mean_px
    if error_estimate_reason(n_fit) is None:
        errors = f"mean {_fmt(r.mean_px, 2)} px · left out {_fmt(loo_mean, 2)} px"
    else:
        errors = f"mean: {NO_ERROR_ESTIMATE}"
    shown = "UNRELIABLE" if status == "unreliable" else status
    solving = " · solving…" if getattr(live, "solving", False) else ""
    return f"**{n_fit} pairs · {errors} · Quality: {shown}**{solving}"


class PairBar:
    """The two markdown lines (live solve, guided status) placed at ``order`` in the panel ``gui``.

    Parameters
    ----------
    gui : viser GUI API
    live_order, guide_order : float
        Their positions in the control panel (just under the pair actions).
    """

    def __init__(self, gui: Any, live_order: float, guide_order: float) -> None:
        self._md_live = gui.add_markdown("", order=live_order)
        self._md_guide = gui.add_markdown("", order=guide_order)
        self._lock = threading.Lock()  # the Guide panel updates its line from its own threads

    @property
    def live_line(self) -> str:
        """The live solve's one-line summary (markdown; empty before the first solve)."""
        return str(self._md_live.content)

    @property
    def guide_status(self) -> str:
        """Guided picking's status (markdown; empty while no guided session runs)."""
        return str(self._md_guide.content)

    def show_live(self, live: Any) -> None:
        """Show :func:`live_summary` of the app's live solve ``live``."""
        text = live_summary(live)
        with self._lock:
            if self._md_live.content != text:
                self._md_live.content = text

    def show_guide_status(self, guiding: bool, lines: list[str]) -> None:
        """Show guided picking's status ``lines`` (markdown, already escaped) while a guided session runs
        (``guiding``); clear it otherwise.  Called by the Guide panel from any thread."""
        text = ("**Guided:** " + "  \n".join(lines)) if guiding and lines else ""
        with self._lock:
            if self._md_guide.content != text:
                self._md_guide.content = text

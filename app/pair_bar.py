"""The lines under the pair actions at the top of the control panel: the live solve's figures in one line, and
guided picking's status (which proposal, what to click, why nothing is proposed).

In the by-eye walkthrough (issue 20) both sat far down the scrolling panel: "Next pair" with 2 pairs changed
nothing in view, and the errors were wheel-scrolls away.  No maths here: the figures are the ones the live solve
published (:class:`app.ui_common.SolveBundle`), the guided text is the Guide panel's own.
"""

from __future__ import annotations

import html
import re
import threading
from typing import Any, Callable, Mapping

from calib_core.solve.quality import LOO_NOISY_PX, NO_ERROR_ESTIMATE, error_estimate_reason, pairs_in_fit

from .ui_common import MIN_PAIRS, HeldQuality, _fmt, outlier_change_note

#: Keeps the pair bar (the pair actions, the live line, the pair status, the guided line: the panel's rows above the
#: intro) in view while the control panel scrolls: each scroll shifts those rows down by what scrolled away, over the
#: rows below (in run 4, 15 of 67 actions were panel scrolls back to it).  A shift rather than ``position: sticky``:
#: an ``overflow: hidden`` box between the rows and viser's scroll area defeats sticky.  Also the keys viser does not
#: send to Python: Delete / Backspace press Edit -> Delete (the selected pair, else the newest one the loupes show,
#: :meth:`app.pairs_panel.PairsPanel.on_edit`); Ctrl+Z (Cmd+Z) presses the top
#: Undo and Ctrl+Shift+Z / Ctrl+Y Edit -> Redo, taking the key from whatever widget has the focus (in run 4 Ctrl+Z
#: in the page reset the "Render over photo" slider); not while typing in a text area.  A fixed string: no user text.
PAIR_BAR_JS = """
if (!window.__baCalibPairBar) {
  window.__baCalibPairBar = true;
  const INTRO = "Click a point in any";
  const button = (label, root) => Array.from((root || document).querySelectorAll("button")).find(
    (b) => b.textContent.trim() === label);
  const barRows = () => {
    const cancel = button("Cancel pair");
    if (!cancel) return null;
    let row = cancel;
    while (row.parentElement && !Array.from(row.parentElement.children).some(
      (c) => c !== row && c.textContent.includes(INTRO))) row = row.parentElement;
    if (!row.parentElement) return null;
    const rows = [];
    for (let e = row; e && !e.textContent.includes(INTRO); e = e.nextElementSibling) rows.push(e);
    return rows;
  };
  const pin = () => {
    const rows = barRows();
    if (!rows || !rows.length) return;
    const viewport = rows[0].closest(".mantine-ScrollArea-viewport");
    if (!viewport) return;
    const shift = Math.max(0, viewport.scrollTop);  // the rows head the scrolled content: they stay put
    // A row shown since (the guided actions appear with a proposal) is pinned too.
    if (rows.every((e) => e.dataset.baPinned && e.dataset.baShift === String(shift))) return;
    const paper = rows[0].closest(".mantine-Paper-root");
    const background = paper ? getComputedStyle(paper).backgroundColor : "white";
    rows.forEach((e, i) => {
      e.dataset.baPinned = "1";
      e.dataset.baShift = String(shift);
      e.style.position = "relative";
      e.style.zIndex = "5";
      e.style.background = background;
      e.style.transform = shift > 0 ? `translateY(${shift}px)` : "";
      // The first row also covers the scroll area's top padding, the last one casts a line over what scrolls.
      const shadows = [];
      if (shift > 0 && i === 0) shadows.push(`0 -12px 0 0 ${background}`);
      if (shift > 0 && i === rows.length - 1) shadows.push("0 4px 4px -3px rgba(0,0,0,0.25)");
      e.style.boxShadow = shadows.join(", ");
    });
  };
  document.addEventListener("scroll", pin, true);
  setInterval(pin, 250);
  document.addEventListener("keydown", (event) => {
    const t = event.target;
    if (document.querySelector(".mantine-Modal-content")) return;
    if (t && (t.tagName === "TEXTAREA" || t.isContentEditable)) return;
    const inBox = t && t.tagName === "INPUT";
    const key = event.key.toLowerCase();
    const command = event.ctrlKey || event.metaKey;
    let label = null;
    if (command && !event.altKey && key === "z") label = event.shiftKey ? "Redo" : "Undo";
    else if (command && !event.altKey && key === "y") label = "Redo";
    else if (!command && !inBox && (event.key === "Delete" || event.key === "Backspace")) {
      label = "Delete";  // the selected pair, else the newest one the loupes show (Python decides)
    }
    if (!label) return;
    event.preventDefault();
    event.stopPropagation();
    if (event.repeat) return;
    if (document.activeElement && document.activeElement.blur) document.activeElement.blur();
    const rows = barRows();
    const top = label === "Undo" && rows ? button("Undo", rows[0]) : null;
    const target = top || Array.from(document.querySelectorAll("button")).filter(
      (b) => b.textContent.trim() === label).pop();
    if (target) target.click();
  }, true);
}
"""


def undo_note(before: list, after: list) -> str:
    """What one undo took back, from the pairs ``before`` and ``after`` it (:class:`app.picks.Pick` lists), in
    words: which pair, and which of its ends (in run 4 the top Undo removing only a pair's camera half surprised)."""
    old, new = {p.id: p for p in before}, {p.id: p for p in after}
    gone, back = sorted(old.keys() - new.keys()), sorted(new.keys() - old.keys())
    if len(gone) == 1 and not back:
        return f"Undone: pair {gone[0]} (its last end)."
    if back and not gone:
        return "Undone: the removal of pair" + (f" {back[0]}." if len(back) == 1 else f"s {', '.join(map(str, back))}.")
    changed = [i for i in old.keys() & new.keys() if old[i] != new[i]]
    if len(changed) != 1 or gone or back:
        return "Undone: the last change of the pairs."
    a, b = old[changed[0]], new[changed[0]]
    for name, was, now, other in (("camera point", a.pixel, b.pixel, "laser end"),
                                  ("laser end", a.laser_rc, b.laser_rc, "camera point")):
        if was != now and now is None:
            return (f"Undone: pair {b.id}'s {name}; its {other} waits for a new {name.split()[0]} click "
                    "(Undo again drops it).")
        if was != now:
            return f"Undone: the move of pair {b.id}'s {name}."
    return f"Undone: a change of pair {b.id}."


def pending_hint(pending: Any) -> str:
    """The status line while pair ``pending`` (a half-made :class:`app.picks.Pick`) waits: where its other end is
    clicked, first (the bar shows two lines), in the words the page shows.  After a click on the photo the
    lower loupe shows the laser (render or BA image) at that place, so one click there makes the laser end."""
    if pending.pixel is not None:  # run 15: a second photo click moved the photo point, and nothing said so
        return (f"Pair {pending.id} waits for a BA click → **lower loupe** · a photo click moves its photo point · "
                f"**Cancel pair** or Esc drops it.")
    return (f"Pair {pending.id} waits for a camera click → **photo loupe** (top right) · **Cancel pair** or Esc "
            f"drops it.")


def made_hint(pick_id: int, edge_deg: float | None = None) -> str:
    """The status line once a click in the lower loupe completed pair ``pick_id`` after a rough click on the photo:
    the next click in the photo loupe refines its photo point (a click on the full photo starts the next pair).
    ``edge_deg``: its photo end lies on an edge at that angle (degrees), which the line says."""
    made = f"Pair {pick_id} made" + ("" if edge_deg is None else f" (photo end on an edge at {edge_deg:.0f}°)")
    return f"{made} · exact photo point → **photo loupe** (top right) · or a new pair on the photo."


def live_summary(live: Any, held: HeldQuality | None = None, fitted: bool = False) -> str:
    """``"N pairs · mean X px · left out Y px (warning above L) · Quality: ok"`` (markdown) of the solve
    ``live.bundle`` shows (``live``: a :class:`app.ui_common.SolveShown`).  N is the pairs in the fit; with too few
    for an error figure the mean says so.  With ``held`` the status has hysteresis on the left-out limit
    (:class:`app.ui_common.HeldQuality`; "(held, near the limit)" says so).

    Before the first solve, the pairs so far and how many more the solve needs, e.g. "2 pairs · rough pose turned
    to fit them · 2 more to solve" (``fitted``: the rough pose was turned to fit these pairs; run 7: with 1-3 pairs
    the line showed nothing)."""
    bundle = getattr(live, "bundle", None)
    r = getattr(bundle, "result", None)
    error = getattr(live, "error", None)
    if error and not getattr(live, "solving", False):  # run 16: the line kept the last good solve's figures
        shown = error if len(error) <= REASON_HEAD_CHARS else error[:REASON_HEAD_CHARS - 1] + "…"
        return f"**Solve failed:** {shown}" + (" · the page shows the last good solve" if r is not None else "")
    if r is None:
        if held is not None:
            held.status(None)  # a new start: the next verdict is shown plain
        n = int(getattr(live, "n_complete", 0) or 0)
        parts = [f"{n} pair{'' if n == 1 else 's'}"]
        if fitted and n:
            parts.append("rough pose turned to fit them")
        if n < MIN_PAIRS:
            parts.append(f"{MIN_PAIRS - n} more to solve")
        elif getattr(live, "solving", False):
            parts.append("solving…")
        else:
            parts.append("no solve (see Calibration)")
        return f"**{parts[0]}** · " + " · ".join(parts[1:])
    n_fit = pairs_in_fit(r)
    quality = getattr(r, "quality", None)
    status = str(getattr(quality, "status", "ok"))
    loo = getattr(quality, "leave_one_out", None)
    loo_mean = float("nan") if loo is None else loo.mean_px
    if error_estimate_reason(n_fit) is None:
        # The limit beside the figure: in run 4 Quality flipped between ok and warning on a 1-2 px re-click
        # (left out 5.71 vs 6.06 px), with no hint that the figure sat on the limit.
        errors = (f"mean {_fmt(r.mean_px, 2)} px · left out {_fmt(loo_mean, 2)} px "
                  f"(warning above {LOO_NOISY_PX:g})")
    else:
        errors = f"mean: {NO_ERROR_ESTIMATE}"
    note = ""
    if held is not None:  # hysteresis on the left-out limit (the bar's own memory of what it showed)
        status, note = held.status(quality)
    shown = ("UNRELIABLE" if status == "unreliable" else status) + (" (held, near the limit)" if note else "")
    solving = " · solving…" if getattr(live, "solving", False) else ""
    worst = worst_pair(bundle) if error_estimate_reason(n_fit) is None else ""
    head = reason_head(quality) if status != "ok" else ""
    why = f" · why: {head}" if head else ""
    return f"**{n_fit} pairs · {errors} · Quality: {shown}**{worst}{why}{solving}"


#: The longest reason head the live line shows (characters); the Calibration folder has the whole reason.
REASON_HEAD_CHARS = 60


def reason_head(quality: Any) -> str:
    """The first of ``quality``'s reasons up to its first ``:`` or ``;`` (a parenthesis cut there is dropped; at
    most :data:`REASON_HEAD_CHARS` characters, cut at a word), e.g. "only 5 pairs in the fit"; "" without reasons.
    Run 10: leaving a pair out turned "ok" into "warning" and the live line did not say why."""
    reasons = list(getattr(quality, "reasons", None) or [])
    if not reasons:
        return ""
    head = str(reasons[0])
    for stop in (":", ";"):
        head = head.split(stop, 1)[0]
    if head.count("(") > head.count(")"):  # cut inside a parenthesis: drop it whole
        head = head[: head.rfind("(")]
    head = head.strip()
    if len(head) > REASON_HEAD_CHARS:
        head = head[: REASON_HEAD_CHARS - 1].rsplit(" ", 1)[0] + "…"
    return head


def worst_pair(bundle: Any) -> str:
    """`` · worst: pair N X.X px``: the fitted pair farthest from its click under the solve (its reprojection error,
    the Calibration table's "px" column), where the person looks (run 8: that table was three scrolls away)."""
    r = getattr(bundle, "result", None)
    residuals = getattr(r, "residual_px", None)
    if residuals is None or not len(residuals):
        return ""
    positions = getattr(r, "pair_positions", None) or list(range(len(residuals)))
    k = max(range(len(residuals)), key=lambda i: float(residuals[i]) if residuals[i] == residuals[i] else -1.0)
    return f" · worst: pair {bundle.pick_ids[positions[k]]} {float(residuals[k]):.1f} px"


#: One line of constant height: a block that never wraps, ellipsised when longer than the panel is wide (the
#: whole text in its hover title).  Fixed markup; the text inside is the app's own (no user strings).
_ONE_LINE = ('<span style="display:block;white-space:nowrap;overflow:hidden;text-overflow:ellipsis" '
             'title="{title}">{text}</span>')


#: The pair status and guided lines' height, in lines: one line cut their advice (runs 8, 9 and 11: "then photo
#: lou...", "no proposal's 3-sigma ellipse fits th...").
STATUS_LINES = 2
#: The live line's constant height, in lines (run 11: as it grew from two lines to three, the Pairs folder's buttons
#: below moved 18 px under a click).  Two: a third pushed the Loupes folder out of a 900 px high page; the reason,
#: last, is what a longer line loses (the whole text is in its hover title and the Calibration folder).
LIVE_LINES = 2
_FIXED_LINES = ('<span style="display:-webkit-box;-webkit-box-orient:vertical;-webkit-line-clamp:{n};'
                'overflow:hidden;line-height:1.45em;height:{height:.2f}em" title="{title}">{text}</span>')


def fixed_lines_markdown(text: str, n: int) -> str:
    """``text`` (markdown, app text only) in a block exactly ``n`` lines high: shorter text leaves blank lines,
    longer text is cut with an ellipsis at the end of line ``n`` (the whole text in its hover title)."""
    return _FIXED_LINES.format(n=int(n), height=1.45 * int(n), **_title_and_text(text))


def one_line_markdown(text: str) -> str:
    """``text`` (one line of markdown, app text only) as a line of constant height: blank when ``text`` is empty,
    so that the line keeps its place (run 7: the panel's controls jumped about 18 px as a status line came and
    went, and clicks aimed at them landed on nothing)."""
    return _ONE_LINE.format(**_title_and_text(text))


def _title_and_text(text: str) -> dict[str, str]:
    """The hover ``title`` (plain text) and the shown ``text`` of a status block, both HTML-escaped: a message may
    quote a file name, and no user string goes into raw HTML.  Empty text shows a blank (the block keeps its
    height)."""
    plain = re.sub(r"\\(.)", r"\1", text.replace("**", ""))
    return {"title": html.escape(plain, quote=True), "text": html.escape(text, quote=False) if text else "&nbsp;"}


class FixedLine:
    """A markdown line (or ``lines`` lines) of the pair bar that keeps its height whether it shows something or not
    (:func:`one_line_markdown`, :func:`fixed_lines_markdown`).  Not locked: the owner updates it under its own lock."""

    def __init__(self, gui: Any, order: float, lines: int = 1) -> None:
        self._text = ""
        self._lines = int(lines)
        self._md = gui.add_markdown(self._markup(""), order=order)

    def _markup(self, text: str) -> str:
        return one_line_markdown(text) if self._lines == 1 else fixed_lines_markdown(text, self._lines)

    @property
    def text(self) -> str:
        """The markdown shown ("" when blank)."""
        return self._text

    def show(self, text: str) -> None:
        """Show ``text`` (one line of markdown: no line breaks), or a blank line for ""."""
        text = " ".join(text.split("  \n"))
        if text != self._text:
            self._text = text
            self._md.content = self._markup(text)


#: Guided picking's actions the bar repeats while a proposal is shown (run 6: the person scrolled to the Guided
#: folder for them).  "Next pair" is among the pair actions already.
GUIDED_BAR_ACTIONS = ("Skip", "Not a corner", "Stop")


class PairBar:
    """The two markdown lines (live solve, guided status) placed at ``order`` in the panel ``gui``, and guided
    picking's :data:`GUIDED_BAR_ACTIONS` under them while a proposal is shown.

    The bar does not know the Guide panel: the actions' handlers come with the guided status
    (:meth:`show_guide_status`), a slot the Guide panel fills with its own guarded callbacks.

    Parameters
    ----------
    gui : viser GUI API
    live_order, guide_order : float
        Their positions in the control panel (just under the pair actions); the guided actions go just under the
        guided line.
    """

    def __init__(self, gui: Any, live_order: float, guide_order: float) -> None:
        self._live_text = ""
        self._md_live = gui.add_markdown(fixed_lines_markdown("", LIVE_LINES), order=live_order)
        # What the app did by itself (e.g. a rough pose the person did not make): one line, kept when blank.
        self._notice = FixedLine(gui, order=live_order + 0.05)
        self._notice_pairs: Any = None  # the pairs when the shown notice was made
        self._notice_kind = ""  # what the notice line shows: "pose", "outliers" or "" (blank)
        self._pairs_now: Any = None  # the pairs as last told (pairs_changed)
        self._bundle_seen: Any = None  # the last solve shown, and the pairs it left out as outliers
        self._outliers_seen: list[int] = []
        self._md_guide = gui.add_markdown("", order=guide_order)
        self._guide_text = ""  # the guided line's markdown as shown (without the one-line markup)
        self._bg_guided = gui.add_button_group("Guided", GUIDED_BAR_ACTIONS, order=guide_order + 0.02, visible=False)
        self._guided_actions: dict[str, Callable] = {}
        self.guided_action_callback = self._on_guided_action
        self._bg_guided.on_click(self.guided_action_callback)
        self._lock = threading.Lock()  # the Guide panel updates its line from its own threads
        self._held = HeldQuality()  # the live line's Quality, with hysteresis on the left-out limit

    @property
    def guided_actions_shown(self) -> bool:
        """Whether the bar shows :data:`GUIDED_BAR_ACTIONS` (only while guided picking shows a proposal)."""
        return bool(self._bg_guided.visible)

    async def _on_guided_action(self, event: Any) -> None:
        """A press of one of the bar's guided actions: the handler the Guide panel gave, as its own button would."""
        with self._lock:
            handler = self._guided_actions.get(str(event.target.value)) if self._bg_guided.visible else None
        if handler is not None:
            result = handler(event)
            if hasattr(result, "__await__"):
                await result

    @property
    def live_line(self) -> str:
        """The live solve's one-line summary (markdown; empty before the first solve)."""
        return self._live_text

    @property
    def pose_note(self) -> str:
        """The notice of a rough pose change the person did not make (markdown; empty if none shown)."""
        return self._notice.text if self._notice_kind == "pose" else ""

    @property
    def outlier_note(self) -> str:
        """The notice that the last solve changed which pairs it left out as outliers (markdown; empty if none)."""
        return self._notice.text if self._notice_kind == "outliers" else ""

    def _show_notice(self, kind: str, text: str, pairs: Any) -> None:
        """The notice line (under the lock): ``text`` of ``kind`` ("pose", "outliers"), made for ``pairs``."""
        self._notice.show(text)
        self._notice_kind, self._notice_pairs = (kind if text else ""), pairs

    def show_pose_turn(self, turn: Any, pairs: Any = None) -> None:
        """Show the notice of rough pose change ``turn`` (:class:`app.pose_source.PoseTurn`, or None) under the live
        line, where the person looks while picking (run 6: the render rolled 2.2-3 deg after the 2nd pair with no
        word near it): e.g. "Look again: the render turned 2.6 deg (pose refitted from 2 pairs)", what to do first
        (runs 12 and 13: the line's end, "look again", was cut off).  A step by hand clears it, so does the first
        solve (:meth:`show_live`).  ``pairs``: the pairs when the pose turned (e.g. ``state.all_picks``); the notice
        goes once they change (:meth:`pairs_changed`: run 7, it stayed after later pairs)."""
        text = "" if turn is None or not turn.why else (
            f"⚠ **Look again:** the render turned {turn.degrees:.1f} deg (pose {turn.why})")
        with self._lock:
            self._show_notice("pose", text, pairs)

    def pairs_changed(self, pairs: Any) -> None:
        """The pairs are ``pairs`` now: a rough-pose notice made for other pairs goes (the next pair was started or
        made, or one removed); a refit that follows the change shows its own."""
        with self._lock:
            self._pairs_now = pairs
            if self._notice.text and self._notice_pairs is not None and pairs != self._notice_pairs:
                self._show_notice("", "", None)

    @property
    def guide_status(self) -> str:
        """Guided picking's status (markdown; empty while no guided session runs)."""
        return self._guide_text

    def show_live(self, live: Any, fitted: bool = False) -> None:
        """Show :func:`live_summary` of what the live solve shows (``live``: :class:`app.ui_common.SolveShown`;
        ``fitted``: the rough pose was turned to fit the pairs so far)."""
        with self._lock:
            text = live_summary(live, self._held, fitted)
            if self._live_text != text:
                self._live_text = text
                self._md_live.content = fixed_lines_markdown(text, LIVE_LINES)
            bundle = getattr(live, "bundle", None)
            if bundle is not None and self._notice_kind == "pose":
                self._show_notice("", "", None)  # the page shows the solve now, not the rough pose
            if bundle is not None and bundle is not self._bundle_seen:
                # Run 7: outlier exclusion "flipped between pairs" (pair 2 left out at 6 pairs, back in at 7 with
                # pair 3 out) with no word: say so when the set changes.
                self._bundle_seen = bundle
                now = [int(i) for i in getattr(bundle.result, "outlier_ids", [])]
                note = outlier_change_note(self._outliers_seen, now, [int(i) for i in bundle.pick_ids])
                self._outliers_seen = now
                if note:
                    self._show_notice("outliers", f"⚠ {note}", self._pairs_now)

    def show_guide_status(self, guiding: bool, lines: list[str],
                          actions: Mapping[str, Callable] | None = None) -> None:
        """Show guided picking's status ``lines`` (markdown, already escaped) while a guided session runs
        (``guiding``); clear it otherwise.  The Guide panel sends one short line (its folder keeps the full text:
        in run 6 the whole text here grew the bar to about 300 px).  ``actions``: label -> the Guide panel's
        handler of its button (a viser click callback) for :data:`GUIDED_BAR_ACTIONS`, given while a proposal is
        shown; the bar shows those buttons then and hides them otherwise.  Called by the Guide panel from any
        thread."""
        text = ("**Guided:** " + " ".join(lines)) if guiding and lines else ""
        shown = {k: v for k, v in (actions or {}).items() if k in GUIDED_BAR_ACTIONS} if guiding else {}
        with self._lock:
            if self._guide_text != text:  # one line, ellipsised when long (the whole of it in its hover title)
                self._guide_text = text
                self._md_guide.content = fixed_lines_markdown(text, STATUS_LINES) if text else ""
            self._guided_actions = shown
            if bool(self._bg_guided.visible) != bool(shown):
                self._bg_guided.visible = bool(shown)

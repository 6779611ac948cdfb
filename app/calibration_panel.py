"""The calibration panel: the solve's quality verdict in colour with its reasons, the errors, the pose with its
sigmas (roll/pitch/yaw and the viewing direction) and the per-pair residual table (excluded pairs marked by id).
User text is escaped.  Only printable ASCII and the bullet are shown (:data:`FONT_SAFE`): an emoji or a symbol
the page's font lacks draws as an empty box."""

from __future__ import annotations

from typing import Any

import numpy as np

from calib_core.solve.quality import NEAR_SINGULAR_DEG, NO_ERROR_ESTIMATE, error_estimate_reason, pairs_in_fit
from calib_core.transforms import rpy_deg_from_R, viewing_direction

from .ui_common import MIN_PAIRS, QUALITY_BADGES, HeldQuality, SolveBundle, SolveShown, md_escape, _fmt, outlier_change_note

#: The characters the panel may show besides printable ASCII: ones every sans-serif font of the page's
#: stack has (Arial / Liberation Sans, Roboto, Helvetica, DejaVu Sans).
FONT_SAFE = "\u2022"  # bullet


#: After the rpy line near pitch +-90 deg (run 9: "roll/yaw sigmas of about 12 deg alarm a new user").
GIMBAL_LOCK_HINT = " (near gimbal lock roll and yaw trade off, so each alone is uncertain; the line above is not)"

class CalibrationPanel:
    """The "Calibration" folder: it owns its widgets and shows what :meth:`show` is given (no app state).

    Parameters
    ----------
    gui : viser.GuiApi
        Where the folder goes (created here, after the folders made before).
    """

    def __init__(self, gui: Any) -> None:
        with gui.add_folder("Calibration"):
            self.md_result = gui.add_markdown("")
            self.md_table = gui.add_markdown("")
        self._held = HeldQuality()  # the verdict shown, with hysteresis on the left-out limit (display only)
        # The last solve shown, the outliers it left out, and what changed in them with it (run 7: "flips").
        self._outliers_of: tuple[Any, list[int], str] = (None, [], "")

    @property
    def result_text(self) -> str:
        """The result markdown as shown (quality verdict, errors, pose)."""
        return str(self.md_result.content)

    @property
    def table_text(self) -> str:
        """The per-pair residual table as shown (markdown)."""
        return str(self.md_table.content)

    def on_solve_shown(self, shown: SolveShown) -> None:
        """Show what the live solve shows (subscribed to it: :meth:`app.server.CalibrationApp.subscribe_solve`)."""
        self.show(shown.bundle, shown.error, shown.solving, shown.n_complete)

    def show(self, bundle: SolveBundle | None, error: str | None, solving: bool, n_complete: int) -> None:
        """Show the last good solve ``bundle`` (None: none yet), the last solve's ``error``, whether a solve
        runs, and how many pairs are complete."""
        out = []
        if solving:
            out.append(f"*Solving {n_complete} pairs ...*")
        if error is not None:
            keep = " Showing the last good result." if bundle is not None else ""
            out.append(f"**Solve failed:** {md_escape(error)}.{keep}")
        if bundle is None:
            self._held.status(None)  # a new start: the next verdict is shown plain
            if n_complete < MIN_PAIRS:
                out.append(f"No calibration yet (needs {MIN_PAIRS} pairs).")
            self.md_result.content = "  \n".join(out)
            self.md_table.content = ""
            return
        r = bundle.result
        T = r.T_camera_lidar
        t, rpy = T[:3, 3], rpy_deg_from_R(T[:3, :3])
        st, sr = np.asarray(r.sigma_translation_m), np.asarray(r.sigma_rpy_deg)
        quality = getattr(r, "quality", None)
        status, held = self._held.status(quality)
        reasons = list(getattr(quality, "reasons", []))
        # The verdict first and in colour: never a confident wrong answer.
        out.append(f"{QUALITY_BADGES.get(status, QUALITY_BADGES['unreliable'])}")
        if held:  # run 4: a 1-2 px re-click flipped it at the limit
            out.append(f"*Shown as {md_escape(held)}; the shown Quality changes once the left-out error passes the "
                       "limit by that margin.*")
        for reason in reasons:
            out.append(f"• {md_escape(reason)}")
        excluded = [int(i) for i in getattr(r, "outlier_ids", [])]
        if bundle is not self._outliers_of[0]:
            self._outliers_of = (bundle, excluded, outlier_change_note(self._outliers_of[1], excluded,
                                                                       [int(i) for i in bundle.pick_ids]))
        if excluded:
            out.append("Left out of the fit: pair " + ", ".join(str(i) for i in excluded))
        if self._outliers_of[2]:
            out.append(f"Changed with this solve: {self._outliers_of[2]}")
        checks = [int(i) for i in getattr(r, "check_ids", [])]
        if checks:
            out.append("Check pairs (not in the fit, see Verify): " + ", ".join(str(i) for i in checks))
        n_fit = pairs_in_fit(r)
        no_error = error_estimate_reason(n_fit)
        if no_error is None:
            error_line = (f"**Mean error: {_fmt(r.mean_px)} px** (std {_fmt(r.std_px)} px), "
                          f"**{_fmt(r.mean_deg, 4)} deg** (std {_fmt(r.std_deg, 4)} deg)")
        else:  # a near-exact fit is the likeliest outcome: its residuals are no error figure
            error_line = f"**Mean error: {NO_ERROR_ESTIMATE}** ({no_error})"
        loo = getattr(quality, "leave_one_out", None)
        loo_px = {} if loo is None else dict(zip(loo.ids, loo.loo_px))
        loo_mean = np.nan if loo is None else loo.mean_px
        if no_error is None and np.isfinite(loo_mean):
            # The fit error flatters few pairs (the pose bends to them); this is how far a click it did not see lands.
            error_line += (f"  \n**Error on pairs left out: {_fmt(loo_mean, 2)} px** (mean; each pair against the "
                           "pose fitted without it, the honest figure with few pairs)")
        view = viewing_direction(T[:3, :3], np.asarray(r.covariance_6x6)[:3, :3])
        sv = view.sigma_deg
        out += [
            f"**Solved with {r.n_pairs} pairs** ({md_escape(r.cost_name)} cost, {r.iterations} iterations, "
            f"{bundle.seconds * 1000:.0f} ms)",
            error_line,
            f"t = ({t[0]:.4f}, {t[1]:.4f}, {t[2]:.4f}) m, sigma T = ({st[0] * 100:.2f}, {st[1] * 100:.2f}, "
            f"{st[2] * 100:.2f}) cm",
            f"looking along az {_fmt(view.azimuth_deg)} deg, el {_fmt(view.elevation_deg)} deg (lidar frame), "
            f"roll about the axis {_fmt(view.roll_deg)} deg; sigma ({_fmt(sv[0])}, {_fmt(sv[1])}, {_fmt(sv[2])}) deg",
            f"rpy = ({rpy[0]:.3f}, {rpy[1]:.3f}, {rpy[2]:.3f}) deg, sigma R = ({sr[0]:.3f}, {sr[1]:.3f}, "
            f"{sr[2]:.3f}) deg" + (GIMBAL_LOCK_HINT if 90.0 - abs(rpy[1]) < NEAR_SINGULAR_DEG else ""),
        ]
        for w in r.warnings:
            if w not in reasons:  # notes on the output's form (reasons are shown above)
                out.append(f"Note: {md_escape(w)}")
        self.md_result.content = "  \n".join(out)
        rows = ["| pair | px | left out px | deg | in fit |", "|---:|---:|---:|---:|:---|"]
        # calibrate() leaves check pairs out: its rows are the fit pairs (pair_positions), checks come apart.
        positions = getattr(r, "pair_positions", None) or list(range(len(r.residual_px)))
        for k, pos in enumerate(positions):
            pid = bundle.pick_ids[pos]
            px, deg = float(r.residual_px[k]), float(r.residual_deg[k])
            left_out = float(loo_px.get(pid, np.nan))  # its error under the pose fitted without it
            shown_loo = _fmt(left_out, 2) if np.isfinite(left_out) else "-"
            if pid in excluded:  # an outlier is already left out: its px is its left-out error
                rows.append(f"| **{pid}** | **{_fmt(px, 2)}** | **{_fmt(px, 2)}** | **{_fmt(deg, 3)}** | "
                            "**excluded (outlier)** |")
            else:
                rows.append(f"| {pid} | {_fmt(px, 2)} | {shown_loo} | {_fmt(deg, 3)} | yes |")
        for pos, px, deg in zip(getattr(r, "check_positions", []), getattr(r, "check_residual_px", []),
                                getattr(r, "check_residual_deg", [])):
            shown = _fmt(float(px), 2) if np.isfinite(px) else "projects outside the image"  # no pixel error
            rows.append(f"| {bundle.pick_ids[pos]} | {shown} | {shown} | {_fmt(float(deg), 3)} | no: check pair |")
        self.md_table.content = "\n".join(rows)

"""The Verify panel: how far to trust the calibration, from clicks it was not fitted to (what it shows:
docs/bags_and_exports.md, "In the app").

Check pairs (:meth:`app.state.AnnotationState.set_check`), leave-one-out errors, the expected-error heat map, the
difference to an imported reference, plots (viser's uPlot), and with several shots the per-shot checks
(:mod:`app.shot_solve`).  All numbers come from :mod:`calib_core.verify`; they are computed in this panel's own
worker thread, a short while after the last change of the pairs so that a burst of clicks costs one computation.
"""

from __future__ import annotations

import threading
import time
import traceback
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import viser
import viser.uplot as uplot

from calib_core.errors import CalibError
from calib_core.pairs import Pair
from calib_core.shots import solve_shots, verify_shots
from calib_core.solve import calibrate
from calib_core.verify import VerifyReport, expected_error_map, verify_pairs

from .live_solver import LiveSolver
from .shot_solve import JointSolve, grouped_shots, shots_markdown
from .ui_common import MIN_PAIRS, _fmt, md_escape

#: Seconds of quiet after a change before the verification runs (a click burst costs one run).
SETTLE_S = 0.3
#: Scene points used for the heat map and the reference comparison (evenly thinned).
MAX_SCENE_POINTS = 60_000
#: Width (px) of the heat-map image sent to the page.
HEAT_WIDTH = 480
#: The heat map's colour scale tops out at this percentile of its cells.
HEAT_PERCENTILE = 98.0
CHECK_CHOICES = ("Make check pair", "Put back in fit")
_COLORS = {"fit": "#1c7ed6", "loo": "#e8590c", "check": "#2f9e44", "rot": "#ae3ec9"}
#: The three plots, by key: title, the x series' label, and each y series' label and colour.
PLOTS = {
    "pairs": ("Error per pair: in the fit vs left out (LOO / check)", "pair id",
              (("under the fit (px)", "fit"), ("left out (px)", "loo"))),
    "count": ("Error against the number of pairs so far", "pairs",
              (("fit residual (px)", "fit"), ("check pairs (px)", "check"))),
    "sigma": ("Sigma per parameter", "1 = x / roll, 2 = y / pitch, 3 = z / yaw",
              (("sigma translation (cm)", "fit"), ("sigma rotation (deg)", "rot"))),
}
#: uPlot's x scale is a time axis unless told otherwise: these plots count pairs and parameters.
NUMERIC_X = {"x": {"time": False}}
#: What the table and the summary say of a check pair whose laser point projects off the image under the fit.
OFF_IMAGE = "projects outside the image"


@dataclass(eq=False)
class Verification:
    """One finished verification: the report, the heat map and what the page shows of them."""

    key: tuple
    ids: list[int]
    report: VerifyReport
    heat_px: np.ndarray  # (rows, cols) expected error per cell, NaN where no scene point projects
    heat_cell_px: int
    heat_image: np.ndarray  # (h, w, 3) uint8: the camera image with the heat map over it
    heat_max_px: float  # top of the colour scale
    seconds: float
    shots_text: str = ""  # with several shots: the per-shot table (markdown)
    shot_of: tuple = ()  # with several shots: each pair's shot (``ids`` order)


def _series(label: str, color: str | None = None) -> uplot.Series:
    s: dict[str, Any] = {"label": label}
    if color is not None:
        s.update(stroke=color, width=2, points={"show": True, "size": 7, "fill": color})
    return s  # type: ignore[return-value]


def _plot_series(key: str) -> list[uplot.Series]:
    """The series of plot ``key`` of :data:`PLOTS`: x first."""
    _, x_label, ys = PLOTS[key]
    return [_series(x_label)] + [_series(label, _COLORS[colour]) for label, colour in ys]


def finite_plot(x_series: uplot.Series, x: np.ndarray, columns: list[tuple[uplot.Series, np.ndarray]]
                ) -> tuple[tuple[uplot.Series, ...], tuple[np.ndarray, ...]]:
    """The series and data one uPlot plot gets: float arrays with no NaN, no None.

    uPlot draws nothing sensible from NaN (its scales become NaN), so rows
    with a missing value are left out.  The first column is always kept; a
    further column with no finite value where the first has one is left out
    as a whole (e.g. leave-one-out errors with only 4 fit pairs), rather than
    emptying the plot.

    Returns
    -------
    series : tuple
        ``x_series`` and the kept columns' series.
    data : tuple of (n,) float64 arrays
        ``x`` and the kept columns, rows where all of them are finite.
    """
    xs = np.asarray(x, dtype=np.float64).reshape(-1)
    values = [np.asarray(v, dtype=np.float64).reshape(-1) for _, v in columns]
    ok = np.isfinite(xs) & np.isfinite(values[0])
    keep = [0] + [k for k in range(1, len(values)) if np.any(ok & np.isfinite(values[k]))]
    for k in keep:
        ok &= np.isfinite(values[k])
    return (x_series, *(columns[k][0] for k in keep)), (xs[ok], *(values[k][ok] for k in keep))


class VerifyPanel:
    """The Verify folder of one :class:`app.server.CalibrationApp` (owns its widgets and its worker).

    Parameters
    ----------
    app : CalibrationApp
        Read: ``state``, ``depth``, ``camera``, ``image``, ``all_points_lidar``;
        user actions go through ``app.guard`` (the app's ordered action worker).
    """

    def __init__(self, app: Any) -> None:
        self.app = app
        self._lock = threading.RLock()
        self._reference: tuple[np.ndarray, str] | None = None
        self._current: Verification | None = None
        self._error: str | None = None
        self._wanted: tuple | None = None  # key of the newest submitted job
        self._version = 0
        self._stopped = False
        pts = np.asarray(app.all_points_lidar, dtype=np.float64)
        self._scene_points = pts[:: max(1, int(np.ceil(len(pts) / MAX_SCENE_POINTS)))]
        self._build(app.server.gui)
        self._worker = LiveSolver(self._job, self._on_done, name="ba-calib-verify")
        app.state.subscribe(self._on_state_change)
        self._on_state_change(app.state)

    # ------------------------------------------------------------------ widgets
    def _build(self, gui: Any) -> None:
        guard = self.app.guard
        with gui.add_folder("Verify"):
            self._md_summary = gui.add_markdown("")
            self._md_shots = gui.add_markdown("")
            self._dd_pair = gui.add_dropdown("Pair to mark", ("none",), initial_value="none",
                                             hint="Check pairs are left out of the fit; their errors test it")
            self._bg_check = gui.add_button_group("Check pair", CHECK_CHOICES)
            self._bg_check.on_click(guard(self._on_check_button))
            empty = (np.zeros(0), np.zeros(0), np.zeros(0))
            self._plots = {key: gui.add_uplot(empty, tuple(_plot_series(key)), title=title, aspect=1.6,
                                              scales=NUMERIC_X) for key, (title, _, _) in PLOTS.items()}
            self._img_heat = gui.add_image(np.full((8, 8, 3), 230, np.uint8), label="Expected error over the image",
                                           format="jpeg", jpeg_quality=85)
            self._md_heat = gui.add_markdown("")
            self._md_table = gui.add_markdown("")
            self._btn_forget = gui.add_button("Forget the reference extrinsic", icon=viser.Icon.X, disabled=True)
            self._btn_forget.on_click(guard(lambda action: self.set_reference(None)))

    # ------------------------------------------------------------------ actions
    def _on_check_button(self, action: Any) -> None:
        choice = action.value
        value = str(self._dd_pair.value)
        if not value.startswith("#"):
            raise CalibError("choose a pair in 'Pair to mark' first")
        self.mark_check(int(value[1:].split()[0]), choice == CHECK_CHOICES[0])

    def mark_check(self, pick_id: int, check: bool) -> None:
        """Make pair ``pick_id`` a check pair (``check``) or put it back in the fit (undoable)."""
        pick = self.app.state.get(pick_id)
        if check and not pick.check:
            fit = [p for p in self.app.state.all_picks if p.complete and not p.check]
            if pick.complete and len(fit) - 1 < MIN_PAIRS:
                raise CalibError(f"pair {pick_id} is one of the last {MIN_PAIRS} fit pairs; the fit needs them")
        self.app.state.set_check(pick_id, check)

    def set_reference(self, T_camera_lidar: np.ndarray | None, name: str = "reference") -> None:
        """Compare the calibration with this ``T_camera_lidar`` (None: forget the reference)."""
        with self._lock:
            if T_camera_lidar is None:
                self._reference = None
            else:
                self._reference = (np.array(T_camera_lidar, dtype=np.float64).reshape(4, 4), str(name))
        self._btn_forget.disabled = T_camera_lidar is None
        self._submit(force=True)

    @property
    def reference(self) -> tuple[np.ndarray, str] | None:
        """The imported reference ``(T_camera_lidar, name)``, or None."""
        return self._reference

    # ------------------------------------------------------------------ the worker
    def _on_state_change(self, state: Any) -> None:
        picks = state.picks
        options = ("none",) + tuple(f"#{p.id} (check)" if p.check else f"#{p.id}" for p in picks if p.complete)
        by_name = {o.split()[0]: o for o in options}
        want = by_name.get(f"#{state.selected}")  # the selected pair, else the choice stays
        if tuple(self._dd_pair.options) != options:
            current = str(self._dd_pair.value).split()[0]
            self._dd_pair.options = options
            self._dd_pair.value = want or by_name.get(current) or "none"
        elif want is not None and self._dd_pair.value != want:
            self._dd_pair.value = want
        self._submit()

    def _submit(self, force: bool = False) -> None:
        picks = [p for p in self.app.state.all_picks if p.complete]  # every shot's
        pairs = tuple(p.to_pair() for p in picks)
        shot_of = tuple(p.shot for p in picks)
        with self._lock:
            ref = self._reference
            key = (pairs, None if ref is None else (ref[0].tobytes(), ref[1]), shot_of)
            if key == self._wanted and not force:
                return
            self._wanted = key
            self._version += 1
            version = self._version
        self._worker.submit(version, (key, [p.id for p in picks], list(pairs), ref))

    def _joint_job(self, ids: list[int], pairs: list[Pair], shot_of: tuple, ref: Any) -> tuple:
        """A session of several shots: the joint solve, its Verify report, the per-shot text, ids in row order."""
        app = self.app
        ids, pairs, rows_shot, shots = grouped_shots(app, ids, pairs, shot_of)
        joint = JointSolve(solve_shots(shots, app.camera), shots, rows_shot)
        report = verify_shots(joint.solved, shots, app.camera, T_reference=None if ref is None else ref[0],
                              scene_points_lidar=self._scene_points)
        return joint.solved.result, report, shots_markdown(joint, app.active_shot), ids, tuple(rows_shot.tolist())

    def _job(self, payload: tuple) -> Verification | None:
        key, ids, pairs, ref = payload
        time.sleep(SETTLE_S)
        # The live solve and the page's answer to a click come first: they share the machine with this work.
        self.app.wait_idle(timeout=5.0)
        if key != self._wanted or self._stopped:
            return None  # superseded: the newer job is queued
        t0 = time.perf_counter()
        app = self.app
        n_fit = sum(not p.check for p in pairs)
        if n_fit < MIN_PAIRS:
            raise CalibError(f"{n_fit} fit pairs; verification needs at least {MIN_PAIRS}")
        shots_text, shot_of = "", ()
        if len(app.shot_scenes) > 1:
            result, report, shots_text, ids, shot_of = self._joint_job(ids, pairs, key[2], ref)
        else:
            result = calibrate(pairs, app.depth, app.camera)
            # Between the steps too: a click that arrives meanwhile should not share the cores with stale work.
            if key != self._wanted or self._stopped:
                return None
            report = verify_pairs(pairs, app.depth, app.camera, result=result,
                                  T_reference=None if ref is None else ref[0],
                                  scene_points_lidar=self._scene_points)
        if key != self._wanted or self._stopped:
            return None
        cell = max(4, int(np.ceil(app.camera.width / 64)))
        heat = expected_error_map(result.T_camera_lidar, result.covariance_6x6, app.camera, self._scene_points,
                                  cell_px=cell)
        image, top = heat_overlay(app.image, heat)
        return Verification(key, ids, report, heat, cell, image, top, time.perf_counter() - t0, shots_text, shot_of)

    def _on_done(self, version: int, out: Verification | None, error: BaseException | None) -> None:
        if self._stopped:
            return
        with self._lock:
            if version != self._version:
                return  # a newer job is queued
            if error is not None:
                if not isinstance(error, CalibError):
                    traceback.print_exception(error)
                msg = str(error) if isinstance(error, CalibError) else f"{type(error).__name__}: {error}"
                self._error = " ".join(msg.split())
                self._current = None
            elif out is not None:
                self._current, self._error = out, None
            else:
                return
            self._show()

    # ------------------------------------------------------------------ drawing
    def _show(self) -> None:
        cur, err = self._current, self._error
        if cur is None:
            self._md_summary.content = (f"**Not verified:** {md_escape(err)}." if err else
                                        f"Verification starts at {MIN_PAIRS} fit pairs.")
            self._md_table.content = ""
            self._md_heat.content = ""
            self._md_shots.content = ""
            # No stale figures beside a "not verified": the plots and the map empty out.
            empty = np.zeros(0)
            with self.app.server.atomic():
                for plot in self._plots.values():
                    plot.data = tuple(empty for _ in plot.series)
                self._img_heat.image = np.full((8, 8, 3), 230, np.uint8)
            return
        rep, ids = cur.report, cur.ids
        r = rep.result
        lines = [f"**Fit on {rep.fit_index.size} pairs, {rep.check_index.size} check pairs** "
                 f"(verified in {cur.seconds * 1000:.0f} ms)"]
        finite = r.residual_px[np.isfinite(r.residual_px)]
        lines.append(f"Fit residual: mean {_fmt(float(finite.mean()) if finite.size else np.nan, 2)} px")
        loo = rep.loo_px[np.isfinite(rep.loo_px)]
        if loo.size:
            worst = int(np.nanargmax(rep.loo_px))
            lines.append(f"**Leave-one-out: mean {loo.mean():.2f} px**, max {loo.max():.2f} px "
                         f"(pair {ids[int(rep.fit_index[worst])]}): the error to expect on a fresh click")
        chk = rep.check_px[np.isfinite(rep.check_px)]
        n_off = int(np.count_nonzero(rep.check_outside))
        if rep.check_index.size:
            mean_px = f"mean {chk.mean():.2f} px" if chk.size else f"no pixel error: every one {OFF_IMAGE}"
            off = f", {n_off} {OFF_IMAGE} (angle only)" if n_off and chk.size else ""
            lines.append(f"**Check pairs: {mean_px}**, {_fmt(float(np.mean(rep.check_deg)), 3)} deg "
                         f"(not in the fit{off})")
        if rep.reference is not None and self._reference is not None:
            ref = rep.reference
            lines.append(f"**Reference {md_escape(self._reference[1])}:** rotation {_fmt(ref['rotation_deg'], 3)} deg, "
                         f"translation {_fmt(ref['translation_cm'], 2)} cm; over the scene "
                         f"{_fmt(ref.get('px_mean', np.nan), 2)} px mean, {_fmt(ref.get('px_median', np.nan), 2)} px "
                         f"median, {_fmt(ref.get('px_max', np.nan), 2)} px max ({ref.get('n_points', 0)} points)")
        for w in rep.warnings:
            lines.append(f"• {md_escape(w)}")
        self._md_summary.content = "  \n".join(lines)
        self._md_shots.content = cur.shots_text

        rows = ["| pair | role | under the fit px | left out px |", "|---:|:---|---:|---:|"]
        if cur.shot_of:  # several shots: which one each pair is in
            rows = ["| pair | shot | role | under the fit px | left out px |", "|---:|---:|:---|---:|---:|"]
        role = {int(i): "fit" for i in rep.fit_index}
        outliers = {int(rep.fit_index[k]) for k in getattr(r, "outliers", [])}
        under = np.full(len(ids), np.nan)
        left = np.full(len(ids), np.nan)
        under[rep.fit_index] = r.residual_px
        left[rep.fit_index] = rep.loo_px
        under[rep.check_index] = rep.check_px
        left[rep.check_index] = rep.check_px
        for i in rep.check_index:
            role[int(i)] = "check"
        for i in outliers:
            role[i] = "outlier"
        off_image = {int(i) for i, off in zip(rep.check_index, rep.check_outside) if off}
        for i, pid in enumerate(ids):
            name = f"{pid} | {cur.shot_of[i]}" if cur.shot_of else f"{pid}"
            if i in off_image:  # no pixel error to show: say why
                rows.append(f"| {name} | {role.get(i, '?')} | {OFF_IMAGE} | {OFF_IMAGE} |")
            else:
                rows.append(f"| {name} | {role.get(i, '?')} | {_fmt(under[i], 2)} | {_fmt(left[i], 2)} |")
        self._md_table.content = "\n".join(rows)

        x = np.asarray(ids, dtype=np.float64)
        if not np.all(np.diff(x) > 0):  # imported ids out of order: uPlot needs rising x, so plot by position
            x = np.arange(1.0, len(ids) + 1)
        count = rep.pairs_vs_count or {"n_pairs": np.zeros(0), "fit_px": np.zeros(0), "check_px": np.zeros(0)}
        st, sr = 100.0 * np.asarray(r.sigma_translation_m), np.asarray(r.sigma_rpy_deg)
        # All three parameters or none: a NaN sigma (undetermined pose) empties the plot rather than leave it stale.
        sigma_x = np.array([1.0, 2.0, 3.0]) if np.isfinite(st).all() and np.isfinite(sr).all() else np.full(3, np.nan)
        columns = {"pairs": (x, under, left), "count": (count["n_pairs"], count["fit_px"], count["check_px"]),
                   "sigma": (sigma_x, st, sr)}
        with self.app.server.atomic():
            for key, plot in self._plots.items():
                x_series, *y_series = _plot_series(key)
                series, data = finite_plot(x_series, columns[key][0], list(zip(y_series, columns[key][1:])))
                if tuple(plot.series) != series:
                    plot.series = series
                plot.data = data
        self._img_heat.image = cur.heat_image
        shown = np.isfinite(cur.heat_px)
        if shown.any():
            self._md_heat.content = (
                f"Expected reprojection error from the pose uncertainty: blue 0 px to red {cur.heat_max_px:.2f} px "
                f"or more (median {np.nanmedian(cur.heat_px):.2f} px; cells of {cur.heat_cell_px} px)")
        else:
            self._md_heat.content = "No scene point projects into the image under this pose."

    # ------------------------------------------------------------------ reading (tests, export)
    @property
    def current(self) -> Verification | None:
        """The last finished verification (None: none yet, or the last one failed; see :attr:`summary`)."""
        return self._current

    @property
    def summary(self) -> str:
        """The panel's summary text (markdown)."""
        return str(self._md_summary.content)

    @property
    def shots_text(self) -> str:
        """With several shots: the per-shot table, leave-one-shot-out and the disagreeing shot (markdown)."""
        return str(self._md_shots.content)

    @property
    def table(self) -> str:
        """The per-pair table (markdown)."""
        return str(self._md_table.content)

    @property
    def heat_text(self) -> str:
        """The text under the expected-error heat map (markdown)."""
        return str(self._md_heat.content)

    def plot_data(self) -> dict[str, tuple[np.ndarray, ...]]:
        """The data the three plots show: ``pairs``, ``count``, ``sigma``."""
        return {key: tuple(plot.data) for key, plot in self._plots.items()}

    def report_for(self, pairs: list[Pair], result: Any) -> VerifyReport:
        """The verification of ``pairs`` fitted as ``result``: the panel's if it is of the same pairs and
        reference, else computed now (in the caller's thread)."""
        cur, ref = self._current, self._reference
        key = (tuple(pairs), None if ref is None else (ref[0].tobytes(), ref[1]))
        if cur is not None and cur.key[:2] == key:  # one shot: the pairs and the reference decide
            return cur.report
        return verify_pairs(pairs, self.app.depth, self.app.camera, result=result,
                            T_reference=None if ref is None else ref[0], scene_points_lidar=self._scene_points)

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until the verification of the newest change is shown."""
        return self._worker.wait_idle(timeout)

    def stop(self) -> None:
        self._stopped = True
        self._worker.stop()


def heat_overlay(image: np.ndarray, heat_px: np.ndarray, width: int = HEAT_WIDTH) -> tuple[np.ndarray, float]:
    """The camera image (scaled to ``width``) with the heat map blended over it, and the scale's top (px).

    Cells without a scene point keep the image.  Blue is 0 px, red the
    :data:`HEAT_PERCENTILE` percentile of the finite cells.
    """
    h, w = image.shape[:2]
    size = (width, max(1, int(round(h * width / w))))
    base = cv2.resize(np.ascontiguousarray(image[..., :3]), size, interpolation=cv2.INTER_AREA)
    finite = heat_px[np.isfinite(heat_px)]
    if finite.size == 0:
        return base, float("nan")
    top = float(max(np.percentile(finite, HEAT_PERCENTILE), 1e-9))
    level = np.clip(np.nan_to_num(heat_px / top, nan=0.0), 0.0, 1.0)
    colours = cv2.applyColorMap((255 * level).astype(np.uint8), cv2.COLORMAP_JET)[..., ::-1]  # BGR -> RGB
    colours = cv2.resize(colours, size, interpolation=cv2.INTER_NEAREST)
    mask = cv2.resize(np.isfinite(heat_px).astype(np.uint8), size, interpolation=cv2.INTER_NEAREST).astype(bool)
    out = base.copy()
    out[mask] = (0.45 * base[mask] + 0.55 * colours[mask]).astype(np.uint8)
    return out, top

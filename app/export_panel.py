"""The export panels: the extrinsics YAML and coloured PLY (:class:`ExportPanel`), the extrinsics in robotics
formats and the reference import for the Verify panel (:class:`FormatExportPanel`)."""

from __future__ import annotations

import tempfile
import threading
from pathlib import Path
from typing import Any, Callable

import numpy as np
import viser

from calib_core.errors import CalibError
from calib_core.io.atomic import write_yaml_atomic, yaml_bytes
from calib_core.io.extrinsic_formats import FORMATS, export_extrinsics, lidar_and_camera, parse_extrinsics
from calib_core.overlays import export_colored_scan
from calib_core.verify import extrinsics_document

from .security import upload_display_name
from .shot_solve import joint_export
from .ui_common import MIN_PAIRS, md_escape


class ExportPanel:
    """The "Export" folder of one :class:`app.server.CalibrationApp` (owns its widgets).

    Parameters
    ----------
    app : app.app_services.AppServices
        Also read: ``solve_bundle`` (the last good solve), ``depth``, ``camera``, ``image``,
        ``output_path`` and ``session_path``.

    Attributes
    ----------
    verification : callable or None
        ``verification(pairs, result)`` -> the :class:`calib_core.verify.VerifyReport` the YAML carries
        (the Verify panel's :meth:`app.verify_panel.VerifyPanel.report_for`, wired by the app; None: none).
    """

    def __init__(self, app: Any) -> None:
        self.app = app
        self.verification: Callable[[list, Any], Any] | None = None
        gui = app.server.gui
        with gui.add_folder("Export"):
            self._btn_yaml = gui.add_button("Download extrinsics YAML", icon=viser.Icon.DOWNLOAD, color="green")
            self._btn_yaml.on_click(app.guard(self.on_download_yaml))
            self._btn_ply = gui.add_button("Download coloured PLY", icon=viser.Icon.DOWNLOAD)
            self._btn_ply.on_click(app.guard(self._on_download_ply))
            where = f"Also written to {md_escape(str(app.output_path))}  \n" if app.output_path else ""
            self._md_export = gui.add_markdown(
                f"{where}Session (saved after every change): {md_escape(str(app.session_path))}")

    def on_download_yaml(self, event: Any) -> None:
        """"Download extrinsics YAML" pressed in tab ``event.client``."""
        data, path = self.export_extrinsics()
        if event.client is not None:
            event.client.send_file_download("extrinsics.yaml", data, save_immediately=True)
        where = f" and written to {path}" if path is not None else ""
        self.app.notify(event.client, "Extrinsics exported", f"extrinsics.yaml downloaded{where}", color="green")

    def _on_download_ply(self, event: Any) -> None:
        bundle = self.app.solve_bundle
        if bundle is None:
            raise CalibError(f"no calibration yet: pick at least {MIN_PAIRS} pairs")
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "colored_cloud.ply"
            export_colored_scan(path, self.app.depth, self.app.image, self.app.camera, bundle.result.T_camera_lidar)
            data = path.read_bytes()
        if event.client is not None:
            event.client.send_file_download("colored_cloud.ply", data, save_immediately=True)

    def export_extrinsics(self) -> tuple[bytes, Path | None]:
        """The extrinsics YAML of the last good solve to download; also written to ``output_path``.

        The written file names the camera's files relative to its own folder;
        the download, whose folder is unknown, carries the camera inline.  Both
        carry the ``verification:`` block of this solve (the Verify panel's, or
        computed now when the panel has not finished it).
        Returns ``(download bytes, path written or None)``; CalibError before the first solve.
        """
        app = self.app
        bundle = app.solve_bundle
        if bundle is None:
            raise CalibError(f"no calibration yet: pick at least {MIN_PAIRS} pairs")
        if bundle.shots is not None:  # several shots: per-shot residuals and leave-one-shot-out (app.shot_solve)
            return joint_export(app, bundle.shots)
        r = bundle.result
        report = self.verification(bundle.pairs, r) if self.verification is not None else None
        if app.output_path is not None:
            doc, _ = extrinsics_document(r, bundle.pairs, app.depth, app.camera, base_dir=app.output_path.parent,
                                         report=report)
            write_yaml_atomic(app.output_path, doc)
        doc, _ = extrinsics_document(r, bundle.pairs, app.depth, app.camera, base_dir=None, report=report)
        return yaml_bytes(doc), app.output_path


class FormatExportPanel:
    """The "Export to robotics formats" folder of one :class:`app.server.CalibrationApp` (owns its widgets).

    Parameters
    ----------
    app : CalibrationApp
        Read: ``result`` (the last good solve); actions go through ``app.guard``.

    Attributes
    ----------
    reference_listeners : list of callable
        Each is called ``listener(T_camera_lidar, name)`` when a reference extrinsic is imported (the Verify
        panel's :meth:`app.verify_panel.VerifyPanel.set_reference`, subscribed by the app).
    """

    def __init__(self, app: Any) -> None:
        self.app = app
        self.reference_listeners: list[Callable[[np.ndarray, str], None]] = []
        self._upload_lock = threading.Lock()
        gui = app.server.gui
        guard = app.guard
        self._folder = gui.add_folder("Export to robotics formats", expand_by_default=True)
        with self._folder:
            self._dd_format = gui.add_dropdown("Format", tuple(FORMATS), initial_value="ros2-tf",
                                               hint="; ".join(f"{f.name}: {f.description}" for f in FORMATS.values()))
            self._tx_parent = gui.add_text("Parent frame", initial_value="lidar",
                                           hint="The two sensors' frames, in either order")
            self._tx_child = gui.add_text("Child frame", initial_value="camera")
            self._md_direction = gui.add_markdown("")
            self._btn_download = gui.add_button("Download in this format", icon=viser.Icon.DOWNLOAD)
            self._btn_download.on_click(guard(self._on_download))
            self._md_reference = gui.add_markdown(
                "**Import reference extrinsic** (below; any of the formats above or a ba-calib YAML): "
                "the Verify panel compares the calibration with it.")
        for widget in (self._dd_format, self._tx_parent, self._tx_child):
            widget.on_update(guard(lambda action: self._refresh()))
        app.server.on_client_connect(self._on_connect)
        self._refresh()

    # ------------------------------------------------------------------ export
    def _frames(self) -> tuple[str, str]:
        return str(self._tx_parent.value).strip(), str(self._tx_child.value).strip()

    @property
    def chosen_format(self) -> str:
        """The export format the Format dropdown shows."""
        return str(self._dd_format.value)

    @property
    def frame_names(self) -> tuple[str, str]:
        """The parent and child frame names as typed (unstripped)."""
        return str(self._tx_parent.value), str(self._tx_child.value)

    @property
    def direction_text(self) -> str:
        """The direction line under the frame fields (markdown)."""
        return str(self._md_direction.content)

    def _refresh(self) -> None:
        """The direction line under the frame fields."""
        fmt = str(self._dd_format.value)
        parent, child = self._frames()
        try:
            lidar, camera = lidar_and_camera(parent, child)
        except CalibError as exc:
            self._md_direction.content = f"**Frames:** {md_escape(exc)}"
            return
        kind = {"opencalib": "T_camera_lidar", "kitti": "T_camera_lidar", "dvlc": "T_lidar_camera"}.get(fmt)
        P, C, L, K = (md_escape(x) for x in (parent, child, lidar, camera))  # user text: escaped
        if kind == "T_camera_lidar":
            text = f"holds the transform that maps **{L}** (lidar) points into the **{K}** (camera) frame"
        elif kind == "T_lidar_camera":
            text = f"holds the transform that maps **{K}** (camera) points into the **{L}** (lidar) frame"
        else:
            text = (f"holds T\\_{P}\\_{C}: it maps **{C}** points into the **{P}** frame "
                    f"(parent {P}, child {C}, as TF defines it)")
        self._md_direction.content = f"**{md_escape(fmt)}** {text}"

    def export_text(self, fmt: str | None = None, parent: str | None = None, child: str | None = None) -> str:
        """The last good solve's extrinsics in format ``fmt`` (default: the panel's choices)."""
        result = self.app.result
        if result is None:
            raise CalibError(f"no calibration yet: pick at least {MIN_PAIRS} pairs")
        p, c = self._frames()
        fmt = fmt or str(self._dd_format.value)
        return export_extrinsics(result.T_camera_lidar, fmt, parent or p, child or c)

    def file_name(self, fmt: str | None = None) -> str:
        fmt = fmt or str(self._dd_format.value)
        return f"extrinsics_{fmt.replace('-', '_')}{FORMATS[fmt].suffix}"

    def _on_download(self, action: Any) -> None:
        fmt = str(self._dd_format.value)
        data = self.export_text(fmt).encode("utf-8")
        name = self.file_name(fmt)
        if action.client is not None:
            action.client.send_file_download(name, data, save_immediately=True)
        self.app.notify(action.client, "Extrinsics exported", f"{name} downloaded ({fmt})", color="green")

    # ------------------------------------------------------------------ reference
    def _on_connect(self, client: Any) -> None:
        """This tab's own "Import reference extrinsic" button (viser keeps one upload value per button)."""
        with self._upload_lock:
            with self._folder:
                button = client.gui.add_upload_button("Import reference extrinsic", icon=viser.Icon.UPLOAD,
                                                      mime_type="*/*")
        button.on_upload(self.app.guard(self._on_upload))

    def _on_upload(self, action: Any) -> None:
        f = action.value
        self.import_reference(action.client, getattr(f, "name", ""), getattr(f, "content", b""))

    def receive_reference(self, client: Any, name: str, content: bytes, wait: bool = False) -> None:
        """Import a reference extrinsic as the upload button of ``client`` does (through the action queue)."""
        self.app.post(lambda: self.import_reference(client, name, content), client=client, wait=wait)

    def import_reference(self, client: Any, name: str, content: bytes) -> np.ndarray:
        """Parse an uploaded extrinsic (any format) and hand it to the Verify panel; returns its T_camera_lidar."""
        shown = upload_display_name(name)  # only ever shown, never used as a path
        if not content:
            raise CalibError(f"{shown}: the file is empty")
        try:
            text = bytes(content).decode("utf-8")
        except UnicodeDecodeError:
            raise CalibError(f"{shown}: not a text file") from None
        hint: tuple[str | None, str | None] = (None, None)
        try:
            hint = lidar_and_camera(*self._frames())
        except CalibError:
            pass
        try:
            parsed = parse_extrinsics(text, lidar_frame=hint[0], camera_frame=hint[1])
        except CalibError as exc:
            raise CalibError(f"{shown}: {exc}") from None
        for listener in self.reference_listeners:
            listener(parsed.T_camera_lidar, shown)
        self.app.notify(client, "Reference imported",
                         f"{shown} ({parsed.format}) is compared with the calibration in Verify", color="green")
        return parsed.T_camera_lidar

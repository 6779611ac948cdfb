"""The export panel: pairs YAML, extrinsics YAML (written to ``output_path`` with file references relative to its
folder; the download carries the camera inline) and the coloured PLY (:func:`calib_core.overlays.export_colored_scan`)."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any


from calib_core.errors import CalibError
from calib_core.io.atomic import write_yaml_atomic
from calib_core.io.extrinsics import extrinsics_to_dict, save_extrinsics_yaml
from calib_core.overlays import export_colored_scan

from .ui_common import MIN_PAIRS


class ExportPanel:
    """Part of :class:`app.server.CalibrationApp` (a mixin: it uses the app's attributes)."""

    def _on_download_pairs(self, event: Any) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "pairs.yaml"
            n = self.state.export_pairs_file(path)
            data = path.read_bytes()
        if event.client is not None:
            event.client.send_file_download("pairs.yaml", data, save_immediately=True)
        self._notify(event.client, "Pairs", f"{n} complete pairs downloaded", color="green")

    def _on_download_yaml(self, event: Any) -> None:
        data, path = self.export_extrinsics()
        if event.client is not None:
            event.client.send_file_download("extrinsics.yaml", data, save_immediately=True)
        where = f" and written to {path}" if path is not None else ""
        self._notify(event.client, "Extrinsics exported", f"extrinsics.yaml downloaded{where}", color="green")

    def _on_download_ply(self, event: Any) -> None:
        bundle = self._bundle
        if bundle is None:
            raise CalibError(f"no calibration yet: pick at least {MIN_PAIRS} pairs")
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "colored_cloud.ply"
            export_colored_scan(path, self.depth, self.image, self.camera, bundle.result.T_camera_lidar)
            data = path.read_bytes()
        if event.client is not None:
            event.client.send_file_download("colored_cloud.ply", data, save_immediately=True)

    def export_extrinsics(self) -> tuple[bytes, Path | None]:
        """The extrinsics YAML of the last good solve to download; also written to ``output_path``.

        The written file names the camera's files relative to its own folder;
        the download, whose folder is unknown, carries the camera inline.
        Returns ``(download bytes, path written or None)``; CalibError before the first solve.
        """
        bundle = self._bundle
        if bundle is None:
            raise CalibError(f"no calibration yet: pick at least {MIN_PAIRS} pairs")
        r = bundle.result
        if self.output_path is not None:
            save_extrinsics_yaml(self.output_path, r.T_camera_lidar, r, self.camera, bundle.pairs)
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "extrinsics.yaml"
            write_yaml_atomic(path, extrinsics_to_dict(r.T_camera_lidar, r, self.camera, bundle.pairs, base_dir=None))
            return path.read_bytes(), self.output_path

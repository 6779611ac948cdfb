"""The wheel over a loupe zooms that loupe, not the whole page (by-eye run 4: the wheel over a loupe zoomed the
workspace).

viser sends no wheel events to Python and its camera controls take every wheel over the canvas.  A page script
catches a wheel over a loupe first and presses that loupe's zoom button ("Camera +", "BA -", ...); where the loupes
lie on the canvas is sent to each tab as canvas fractions, from the camera the tab reports.  Display geometry only.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from .page_builder import run_script

#: Run once per tab: a wheel over a loupe rectangle (``window.__baLoupeRects``: kind -> [x0, y0, x1, y1] as
#: fractions of the canvas) presses that loupe's zoom button, at most one press per 150 ms, and never reaches the
#: view's camera controls.  A fixed string: no user text.
LOUPE_WHEEL_JS = """
if (!window.__baCalibLoupeWheel) {
  window.__baCalibLoupeWheel = true;
  let lastPress = 0;
  window.addEventListener("wheel", (event) => {
    const rects = window.__baLoupeRects;
    const canvas = event.target;
    if (!rects || !canvas || canvas.tagName !== "CANVAS") return;
    const box = canvas.getBoundingClientRect();
    const fx = (event.clientX - box.left) / box.width, fy = (event.clientY - box.top) / box.height;
    for (const kind of Object.keys(rects)) {
      const r = rects[kind];
      if (fx < r[0] || fx > r[2] || fy < r[1] || fy > r[3]) continue;
      event.preventDefault();
      event.stopPropagation();
      const now = performance.now();
      if (event.deltaY === 0 || now - lastPress < 150) return;
      lastPress = now;
      const label = (kind === "ba" ? "BA " : "Camera ") + (event.deltaY < 0 ? "+" : "-");
      const button = Array.from(document.querySelectorAll("button")).find((b) => b.textContent.trim() === label);
      if (button) button.click();
      return;
    }
  }, {capture: true, passive: false});
}
"""


def canvas_rects(camera: Any, bounds: dict[str, tuple[float, float, float, float]]) -> dict[str, list[float]] | None:
    """Where world rectangles ``bounds`` (kind -> ``(x0, y0, x1, y1)`` on the annotation plane ``z = 0``) lie on a
    tab's canvas: kind -> ``[x0, y0, x1, y1]`` as fractions of its width and height, seen by viser camera
    ``camera`` (position, orientation ``wxyz``, vertical ``fov`` in radians, image size in pixels).  None when the
    tab has not reported a camera or a corner is behind it."""
    import viser.transforms as vtf

    try:
        R = vtf.SO3(np.asarray(camera.wxyz, np.float64)).as_matrix()  # camera frame: +z forward, +y down
        position = np.asarray(camera.position, np.float64)
        f = 0.5 / math.tan(float(camera.fov) / 2.0)  # focal length in canvas heights
        aspect = float(camera.image_width) / max(float(camera.image_height), 1.0)
    except (AssertionError, AttributeError, TypeError, ValueError):
        return None
    out = {}
    for kind, (x0, y0, x1, y1) in bounds.items():
        local = (np.array([[x0, y0, 0.0], [x1, y1, 0.0]]) - position) @ R
        if not np.all(local[:, 2] > 1e-9):
            return None
        fx = f * local[:, 0] / local[:, 2] / aspect + 0.5
        fy = f * local[:, 1] / local[:, 2] + 0.5
        out[kind] = [round(float(min(fx)), 5), round(float(min(fy)), 5), round(float(max(fx)), 5),
                     round(float(max(fy)), 5)]
    return out


def send_loupe_rects(client: Any, rects: dict[str, list[float]]) -> bool:
    """Tell tab ``client`` where the loupes lie on its canvas (:func:`canvas_rects`); False if this viser cannot."""
    source = f"window.__baLoupeRects = {json.dumps(rects)};"  # numbers only
    return run_script(getattr(client, "_websock_connection", None), source)

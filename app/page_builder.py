"""The page of the app: the theme, the intro text, the backdrop and the annotation images' scene nodes (camera
views and BA images with their titles, wired to the app's click, select and drag handlers).  What the images show is set by
the view panel (column window, camera view) and the display panel (contrast)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .ui_common import md_escape

#: Notifications at the bottom right, over the lower end of the control panel: never over the images and loupes,
#: which the app frames left of the panel.  (viser puts them at the top left, over the photo; in the by-eye runs a
#: click meant for a toast's close button moved a pending point.)  A fixed string: no user text.
PAGE_CSS = ("<style>.mantine-Notifications-root{top:auto!important;bottom:1em!important;left:auto!important;"
            "right:1em!important}</style>")
#: Escape presses the "Cancel pair" button (viser sends no key events to Python).  Not while typing in a box, in
#: an open dropdown or with a dialog open.  Also closes viser's software-WebGL notice.  A fixed string, run once
#: per tab.
ESCAPE_JS = """
if (!window.__baCalibEscape) {
  window.__baCalibEscape = true;
  // viser's "Software WebGL rendering detected" notice covers the panel's lower end until closed by hand (runs 1-8:
  // the first action of every walkthrough); the page closes it and keeps the word in the console.
  setInterval(() => {
    for (const n of document.querySelectorAll(".mantine-Notification-root")) {
      const close = n.querySelector("button");
      if (close && n.textContent.includes("Software WebGL rendering detected")) {
        console.warn("ba-calib: " + n.textContent);
        close.click();
      }
    }
  }, 300);
  document.addEventListener("keydown", (event) => {
    if (event.key !== "Escape" || event.repeat) return;
    const t = event.target;
    // A dropdown keeps the focus after a choice (run 8: Escape then did nothing): only a box one types in, or an
    // open dropdown (Escape closes it), keeps the key.
    const typing = t && t.tagName === "INPUT" && !t.readOnly && t.getAttribute("role") !== "combobox"
      && !/^(checkbox|radio|range|button)$/.test(t.type);
    if (t && (typing || t.tagName === "TEXTAREA" || t.isContentEditable)) return;
    if (t && t.getAttribute && t.getAttribute("aria-expanded") === "true") return;
    if (document.querySelector(".mantine-Modal-content")) return;
    if (t && t.tagName === "INPUT" && t.blur) t.blur();  // the keys go back to the page
    const button = Array.from(document.querySelectorAll("button")).find(
      (b) => b.textContent.trim() === "Cancel pair");
    if (button) button.click();
  });
}
"""

INTRO = (
    "Click a point in any **BA image** or in the **camera-view laser** render (below the photo) and the same point "
    "in the **camera image** (either order) to make a pair. No pose yet? **Align** first: a preset, then drag the "
    "render onto the photo. **Shift+click** a marker selects its pair, **drag** moves it. The **loupes** on the "
    "right magnify both ends: a click in them refines the pair they show. Wheel zooms, right-drag pans."
)


class PageBuilder:
    """The page of one :class:`app.server.CalibrationApp` (``app.page``).

    Construction sets the theme, adds the intro text (first in the control
    panel) and the backdrop; :meth:`add_images` adds the annotation images
    once the panels exist; the view and display panels change them through
    :meth:`set_ba` and :meth:`show_camera_view`.
    """

    def __init__(self, app: Any) -> None:
        self.app = app
        gui, scene = app.server.gui, app.server.scene
        gui.configure_theme(control_width="large", show_share_button=False, dark_mode=False)
        self.intro = gui.add_markdown(f"**{md_escape(app.title)}**  \n" + INTRO)  # the pair actions go above it
        gui.add_html(PAGE_CSS, order=1e9)  # last in the panel: the style sheet shows nothing
        install_page_script(app.server, ESCAPE_JS)
        backdrop = scene.add_image(
            "/annot/backdrop", np.full((2, 2, 3), 238, np.uint8), 600.0, 600.0, format="png", position=(0.0, 0.0, 0.5)
        )
        # A no-op drag on the backdrop keeps left-drags from orbiting the flat view.
        backdrop.on_drag(lambda event: None)
        self._handles: dict[str, Any] = {}  # image key -> scene image
        self._ba_titles: dict[str, Any] = {}
        self._camera_title: Any = None

    def add_images(self, ba_textures: dict[str, np.ndarray], ba_titles: dict[str, str]) -> None:
        """Add the camera views and the BA images (``ba_textures``, titled ``ba_titles``) at their page slots."""
        app = self.app
        scene = app.server.scene
        shown = app.camera_view.key
        for key, view in app.camera_views.items():
            s = app.slots[key]
            self._handles[key] = scene.add_image(
                {"raw": "/annot/camera_raw", "panorama": "/annot/camera_pano"}[key], view.image, s.render_width,
                s.render_height, format="jpeg", jpeg_quality=92, position=s.center, visible=key == shown,
            )
        for key in app.ba_keys:
            s = app.slots[key]
            self._handles[key] = scene.add_image(
                f"/annot/ba_{key}", ba_textures[key], s.render_width, s.render_height, format="png",
                position=s.center,
            )
            x0, y0, _, _ = s.bounds()
            self._ba_titles[key] = scene.add_label(f"/annot/titles/{key}", ba_titles[key],
                                                  position=(x0, y0 - 0.03, -0.01), anchor="bottom-left",
                                                  font_screen_scale=0.9)
        for key, handle in self._handles.items():
            handle.on_click(app.make_click_handler(key))
            handle.on_click(modifier="shift")(app.make_select_handler(key))
            handle.on_drag(app.make_drag_handler(key))
        self._camera_title = scene.add_label("/annot/titles/camera", "", position=(0, 0, -0.01), anchor="bottom-left",
                                            font_screen_scale=0.9)

    def image_handle(self, key: str) -> Any:
        """The scene image of ``key`` (a BA key or camera view), e.g. to add a drag handler."""
        return self._handles[key]

    def texture(self, key: str) -> np.ndarray:
        """The texture image ``key`` (a BA key or camera view) shows now."""
        return np.asarray(self._handles[key].image)

    def set_ba(self, key: str, *, texture: np.ndarray | None = None, slot: Any = None, title: str | None = None) -> None:
        """Change BA image ``key``: its texture, its place and size (an :class:`app.layout.ImageSlot`), its title."""
        handle = self._handles[key]
        if texture is not None:
            handle.image = texture
        if slot is not None:
            handle.render_width = slot.render_width
            handle.render_height = slot.render_height
            handle.position = slot.center
            x0, y0, _, _ = slot.bounds()
            self._ba_titles[key].position = (x0, y0 - 0.03, -0.01)
        if title is not None:
            self._ba_titles[key].text = title

    def show_ba_window(self, shown: Any) -> None:
        """Show the BA images as :class:`app.view_events.BaWindowShown` ``shown`` says (textures, places, titles)."""
        for key, texture in shown.textures.items():
            self.set_ba(key, texture=texture, slot=shown.slots[key], title=shown.titles[key])

    def show_camera_view(self, key: str, slot: Any, title: str) -> None:
        """Show camera view ``key`` (hide the other) with ``title`` above its ``slot``."""
        for k in self.app.camera_views:
            visible = k == key
            if self._handles[k].visible != visible:
                self._handles[k].visible = visible
        x0, y0, _, _ = slot.bounds()
        self._camera_title.position = (x0, y0 - 0.03, -0.01)
        self._camera_title.text = title


def install_page_script(server: Any, source: str) -> bool:
    """Run the fixed script ``source`` in every tab of ``server``, present and future (viser replays it to new
    tabs); False if this viser cannot (then the page works without it: e.g. Escape does nothing)."""
    return run_script(getattr(server.gui, "_websock_interface", None), source)


def run_script(channel: Any, source: str) -> bool:
    """Send the fixed script ``source`` down viser message ``channel`` (the server's, or one tab's connection);
    False if this viser cannot."""
    try:
        from viser._messages import RunJavascriptMessage  # how viser itself sends plotly.js

        channel.queue_message(RunJavascriptMessage(source=source))
    except (ImportError, AttributeError, TypeError):
        return False
    return True

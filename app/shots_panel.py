"""The "Shots" folder: a session of several shots (scan + photo of one rig), one shot's panes at a time (what it
offers: docs/cli.md, "In the app").  Showing another shot restarts the app on it (:meth:`app.serving.ShotServer.load`,
through the server's request queue, as the "Bag frame" folder does); guided picking asks for the shot of its next
proposal the same way (:meth:`ShotsPanel.show_for_guide`), and the page shown then goes on with the guided session.
"""

from __future__ import annotations

from typing import Any

from calib_core.errors import CalibError

from .shot_solve import shot_name
from .ui_common import md_escape


class ShotsPanel:
    """The "Shots" folder of one app of a :class:`app.serving.ShotServer` (owns its widgets).

    Parameters
    ----------
    app : CalibrationApp
        Read: ``state`` (its shots and every shot's picks), ``active_shot`` (the shot this app shows);
        actions go through ``app.guard``.
    server : ShotServer
        ``requests`` (a queue of shot indices the serving loop loads) and ``add_shot``.
    guide : app.guide_panel.GuidePanel, optional
        Guided picking across shots: it asks this folder to show the shot of its next proposal (``show_shot``),
        and resumes on a page shown for it.
    """

    def __init__(self, app: Any, server: Any, guide: Any = None) -> None:
        self.app, self.server = app, server
        self.requested: int | None = None  # the shot asked for (the page reconnects to it)
        gui = app.server.gui
        with gui.add_folder("Shots", order=-0.9):
            self._md = gui.add_markdown("")
            options = self._options(app.state)
            self.dropdown = gui.add_dropdown("Shot to show", options, initial_value=options[app.active_shot],
                                             hint="Every shot's pairs go into one calibration")
            self.show_button = gui.add_button("Show this shot", hint="Restarts the page on that shot's scan and photo")
            self.scan_text = gui.add_text("New shot: scan", "", hint="Path of the scan on the machine serving the page")
            self.image_text = gui.add_text("New shot: photo", "", hint="Path of the photo taken with that scan")
            self.add_button = gui.add_button("Add this shot", hint="One undoable step (Pairs: Undo removes it)")
            if getattr(server, "bag_frames", None) is not None:  # served from a bag: add another of its frames
                self.frame_number = gui.add_number("Bag frame (cloud index)", 0, min=0, step=1,
                                                   hint="0-based index of the bag's cloud (ba-calib bag frames)")
                self.add_frame_button = gui.add_button("Add this bag frame",
                                                       hint="Extracts the frame and adds it as a shot: one undoable step")
                self.add_frame_button.on_click(app.guard(lambda _: self.add_bag_frame(int(self.frame_number.value))))
        self.show_button.on_click(app.guard(self.show_chosen))
        self.add_button.on_click(app.guard(self._on_add))
        app.state.subscribe(self._on_state_change)
        self._on_state_change(app.state)
        if guide is not None:  # guided picking across shots: its next proposal may be in another shot
            guide.show_shot = self.show_for_guide
            if getattr(server, "resume_guided", False):  # this page was shown for a guided session: go on
                server.resume_guided = False
                app.post(guide.resume)

    @staticmethod
    def _options(state: Any) -> tuple[str, ...]:
        return tuple(f"Shot {k}: {shot_name(f)}" for k, f in enumerate(state.shots)) or ("Shot 0",)

    def counts(self) -> list[int]:
        """Complete pairs of each shot."""
        state = self.app.state
        out = [0] * state.n_shots
        for p in state.all_picks:
            if p.complete and p.shot < len(out):
                out[p.shot] += 1
        return out

    @property
    def summary(self) -> str:
        """The folder's text (markdown)."""
        return str(self._md.content)

    # ------------------------------------------------------------------ actions
    def show_chosen(self, action: Any = None) -> None:
        """"Show this shot": ask for the shot chosen in the dropdown."""
        options = self._options(self.app.state)
        value = str(self.dropdown.value)
        if value not in options:
            raise CalibError("choose a shot in 'Shot to show' first")
        self.request(options.index(value))

    def _on_add(self, action: Any) -> None:
        scan, image = str(self.scan_text.value).strip(), str(self.image_text.value).strip()
        if not scan or not image:
            raise CalibError("give the new shot's scan and photo (their paths on the machine serving the page)")
        k = self.server.add_shot(scan, image)
        self.request(k)

    def add_bag_frame(self, index: int) -> int:
        """Extract cloud ``index`` of the served bag with its image, add it as a shot (one undoable step) and
        show it; returns the shot's index."""
        from calib_core.io.bag_frames import shots_from_bag

        frame = shots_from_bag(indices=[int(index)], **self.server.bag_frames)[0]
        k = self.server.add_shot(frame.scan, frame.image)
        self.request(k)
        return k

    def show_for_guide(self, shot: int) -> None:
        """Guided picking's next proposal is in shot ``shot``: show it, and go on guiding there."""
        self.server.resume_guided = True
        self.request(shot)

    def request(self, shot: int) -> None:
        """Ask the serving loop to show shot ``shot`` (the app restarts on it; the page reconnects)."""
        if shot == self.app.active_shot or shot == self.requested:
            return
        self.requested = shot
        self.app.notify(None, "Showing another shot", f"shot {shot}: the page reconnects in a moment", color="blue")
        self.server.requests.put(shot)

    # ------------------------------------------------------------------ drawing
    def _on_state_change(self, state: Any) -> None:
        options = self._options(state)
        if tuple(self.dropdown.options) != options:
            self.dropdown.options = options
        counts = self.counts()
        shown = self.app.active_shot
        lines = [f"**Showing shot {shown} of {len(counts)}**"
                 + (f": {md_escape(shot_name(state.shots[shown]))}" if shown < len(state.shots) else "")]
        lines.append("Pairs per shot: " + ", ".join(
            f"shot {k}: {n}" + (" (shown)" if k == shown else "") for k, n in enumerate(counts))
            + f"; **{sum(counts)} in the calibration** (one pose from every shot's pairs)")
        self._md.content = "  \n".join(lines)
        if state.active_shot != shown:  # an undone shot that was shown
            self.request(state.active_shot)

"""Serve the annotation app until Ctrl+C (what ``ba-calib`` and ``ba-calib serve`` run; docs/cli.md).

``serve --bag BAG`` serves one frame of a ROS bag (:class:`BagServer`), and ``serve --shot ...`` a session of
several shots of one rig (:class:`ShotServer`: one state holds every shot's pairs, the live solve uses them all).
Both restart the app on the same port to show another frame or shot; the page reconnects.
"""

from __future__ import annotations

import contextlib
import os
import queue
import signal
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

from calib_core.errors import CalibError

from .security import TOKEN_QUERY, is_loopback
from .picks import ShotFiles, session_shots
from .prepared_scene import MAX_CLOUD_POINTS, PreparedScene
from .server import CalibrationApp
from .session_store import peek_session
from .state import AnnotationState
from .ui_common import md_escape


@dataclass
class BagFrame:
    """One frame of a bag, extracted to files (see :func:`calib_core.io.bags.write_bag_scene`)."""

    index: int
    scan: Path
    image: Path
    camera: Path
    initial_extrinsics: Path | None  # from /tf_static, when it links the two frames
    session: Path
    description: str  # one markdown paragraph (user text escaped)
    notes: list[str]


@dataclass
class BagSource:
    """Where ``serve --bag`` takes its frames from."""

    bag: Path  # .bag, or a ROS 2 bag folder (or a file in it)
    cloud_topic: str | None = None  # the three topics: default, the bag's only topic of that type
    image_topic: str | None = None
    camera_info_topic: str | None = None
    # The first frame: the cloud with this index on its topic, or the one nearest to this many seconds after the
    # bag's start (default index 0).
    index: int | None = None
    time_s: float | None = None
    camera: Path | None = None  # camera file, for bags without CameraInfo (it wins over CameraInfo)
    frames_dir: Path | None = None  # where frames are extracted (default ./<bag name>.ba-calib-frames)
    # Session file of the first frame; other frames get <stem>.frameN<suffix> beside it (default
    # ./<bag name>.frameN.ba-calib-session.yaml).
    session: Path | None = None
    n_clouds: int = field(default=0, init=False)
    first_index: int | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        from calib_core.io.bags import bag_info

        self.bag = Path(self.bag)
        info = bag_info(self.bag)
        self.name = info.path.name if info.path.is_dir() else info.path.stem
        if self.frames_dir is None:
            self.frames_dir = Path.cwd() / f"{self.name}.ba-calib-frames"
        self._counts = {t.name: t.count for t in info.topics}

    def session_for(self, index: int) -> Path:
        if self.session is None:
            return Path.cwd() / f"{self.name}.frame{index}.ba-calib-session.yaml"
        if index == self.first_index:
            return Path(self.session)
        s = Path(self.session)
        return s.with_name(f"{s.stem}.frame{index}{s.suffix}")

    def extract(self, index: int | None = None) -> BagFrame:
        """Extract frame ``index`` (None: the first frame, as given by ``index`` / ``time_s``)."""
        from calib_core.io.bags import read_bag_scene, write_bag_scene

        time_s, index = (self.time_s, self.index) if index is None else (None, index)
        scene = read_bag_scene(self.bag, self.cloud_topic, self.image_topic, self.camera_info_topic, time_s=time_s,
                               index=index)
        # Later frames read the same topics, without asking again.
        self.cloud_topic, self.image_topic = scene.cloud_topic, scene.image_topic
        self.camera_info_topic = scene.camera_info_topic
        self.n_clouds = int(self._counts.get(scene.cloud_topic, 0))
        if self.first_index is None:
            self.first_index = scene.cloud_index
        out = Path(self.frames_dir) / f"frame_{scene.cloud_index:05d}"
        paths = write_bag_scene(scene, out)
        camera = self.camera if self.camera is not None else paths.get("camera")
        if camera is None:
            raise CalibError(f"{self.bag}: no CameraInfo topic; give the camera file with --camera")
        desc = (f"**{md_escape(self.name)}**, cloud {scene.cloud_index} of {self.n_clouds} on "
                f"{md_escape(scene.cloud_topic)} ({len(scene.cloud.xyz)} points); image {md_escape(scene.image_topic)} "
                f"{1000 * scene.gap_s:+.1f} ms from it")
        if paths.get("initial_extrinsics") is not None:
            desc += f"; /tf_static links {md_escape(scene.lidar_frame)} and {md_escape(scene.camera_frame)}"
        return BagFrame(scene.cloud_index, paths["scan"], paths["image"], Path(camera), paths.get("initial_extrinsics"),
                        self.session_for(scene.cloud_index), desc, list(scene.notes))


class BagFramePanel:
    """The "Bag frame" folder: which frame is shown, and a control to load another one."""

    def __init__(self, app: CalibrationApp, source: BagSource, frame: BagFrame, on_request) -> None:
        gui = app.server.gui
        self._on_request = on_request
        self._app = app
        with gui.add_folder("Bag frame", order=-1.0):
            gui.add_markdown(frame.description)
            self.number = gui.add_number("Cloud index", initial_value=frame.index, min=0,
                                         max=max(source.n_clouds - 1, 0), step=1)
            self.button = gui.add_button("Load this frame", hint="Restarts the app on this frame (its own session)")
            self.button.on_click(self._clicked)

    def _clicked(self, event: Any) -> None:
        self.request(int(self.number.value))

    def request(self, index: int) -> None:
        """Ask for frame ``index`` as the "Load this frame" button does (``serve`` then restarts the app on it)."""
        self._app.notify(None, "Loading frame", f"cloud {index}: the page reconnects in a moment", color="blue")
        self._on_request(index)


class _Restarts:
    """Serving that restarts the app on the same port to show another frame or shot (the page reconnects)."""

    app: CalibrationApp | None
    app_options: dict

    def _restart(self, start: Any, new: Any, previous: Any) -> CalibrationApp:
        """Stop the app shown and ``start(new, options)`` on its port; if that fails, ``start(previous, options)``
        (None: nothing to go back to) keeps the old one served, and the error is raised."""
        options = dict(self.app_options)
        if self.app is not None:
            options["port"] = self.app.port
            self.app.stop()  # a state shared by shots lives on; the stopped app's listeners are dropped
            self.app = None
        try:
            return start(new, options)
        except CalibError:
            if previous is None:
                raise
            start(previous, options)
            raise

    def stop(self) -> None:
        """Stop the app shown."""
        if self.app is not None:
            self.app.stop()
            self.app = None


class BagServer(_Restarts):
    """Serve frames of a bag one at a time; :meth:`load` restarts the app on another frame (same port)."""

    def __init__(self, source: BagSource, *, initial_extrinsics_path: str | os.PathLike | None = None,
                 **app_options: Any) -> None:
        self.source = source
        self.initial_extrinsics_path = initial_extrinsics_path
        self.app_options = app_options
        self.requests: queue.Queue[int] = queue.Queue()
        self.app: CalibrationApp | None = None
        self.frame: BagFrame | None = None
        self.panel: BagFramePanel | None = None

    def load(self, index: int | None = None) -> CalibrationApp:
        """Stop the current app (if any) and serve frame ``index`` (None: the first frame)."""
        frame = self.source.extract(index)  # a bad frame leaves the current app running
        return self._restart(self._start, frame, self.frame)

    def _start(self, frame: BagFrame, options: dict) -> CalibrationApp:
        initial = self.initial_extrinsics_path or frame.initial_extrinsics
        self.app = CalibrationApp(frame.scan, frame.image, frame.camera, session_path=frame.session,
                                  initial_extrinsics_path=initial, **options)
        self.frame = frame
        self.panel = BagFramePanel(self.app, self.source, frame, self.requests.put)
        for note in frame.notes:
            print(f"ba-calib: {note}", flush=True)
        return self.app


class ShotServer(_Restarts):
    """Serve a session of several shots, one shot's panes at a time (same port); :meth:`load` shows another.

    Parameters
    ----------
    shots : sequence of (scan, image) paths
        The shots given (``--shot``).  A session file that already lists shots keeps them, in its order;
        the shots given that it lacks are added after them.
    camera_path : path
        The one camera of every shot.
    session_path : path, optional
        Default ``<first scan stem>.ba-calib-session.yaml`` in the current folder.
    scan_options, image_size, kitti_camera, max_cloud_points :
        As for :class:`app.server.CalibrationApp`, for every shot.
    **app_options
        The other options of :class:`app.server.CalibrationApp` (``port``, ``host``, ...).

    Raises
    ------
    CalibError
        A missing file, a shot given twice, an image whose size is not the camera's (naming the shot).
    """

    def __init__(self, shots: Sequence[tuple[Any, Any]], camera_path: str | os.PathLike, *,
                 session_path: str | os.PathLike | None = None, scan_options: dict | None = None,
                 image_size: tuple[int, int] | None = None, kitti_camera: int | None = None,
                 max_cloud_points: int = MAX_CLOUD_POINTS, bag_frames: dict | None = None,
                 **app_options: Any) -> None:
        if not shots:
            raise CalibError("no shot given: give --shot SCAN IMAGE at least once")
        self.camera_path = Path(camera_path)
        self.bag_frames = bag_frames  # shots_from_bag's arguments but the choice: the Shots panel adds frames
        self.session_path = (Path.cwd() / f"{Path(shots[0][0]).stem}.ba-calib-session.yaml" if session_path is None
                             else Path(session_path))
        self._load_options = dict(scan_options=scan_options, image_size=image_size, kitti_camera=kitti_camera,
                                  max_cloud_points=max_cloud_points)
        app_options.pop("title", None)  # each shot's page names its shot
        self.app_options = app_options
        given = [ShotFiles.of(scan, image) for scan, image in shots]
        for k, files in enumerate(given):
            if files in given[:k]:
                raise CalibError(f"shot {k}: {files.scan} with {files.image} is given twice (shot {given.index(files)})")
        data = peek_session(self.session_path)
        listed = list(session_shots(data, self.session_path)) if data is not None else []
        merged = listed + [f for f in given if f not in listed]
        where = f" (listed in the session {self.session_path})"
        self.scenes: list[PreparedScene] = [self.prepare(k, f.scan, f.image, where if f in listed else "")
                                            for k, f in enumerate(merged)]
        first = self.scenes[0]
        self.state = AnnotationState([sc.depth.valid for sc in self.scenes], (first.camera.width, first.camera.height),
                                     self.session_path, on_save_error=self._on_save_error,
                                     default_view=first.default_view(), shots=merged)
        self.requests: queue.Queue[int] = queue.Queue()
        self.app: CalibrationApp | None = None
        self.panel: Any = None

    def prepare(self, k: int, scan: Any, image: Any, where: str = "") -> PreparedScene:
        """Load shot ``k``'s scene (CalibError naming the shot, and ``where`` it was listed, for a bad file)."""
        for what, path in (("scan", scan), ("image", image)):
            if not Path(path).is_file():
                raise CalibError(f"shot {k}{where}: the {what} {path} does not exist")
        try:
            return PreparedScene.load(scan, image, self.camera_path, **self._load_options)
        except CalibError as exc:
            raise CalibError(f"shot {k}{where}: {exc}") from None

    def add_shot(self, scan: Any, image: Any) -> int:
        """Load a scan and its photo and add them as a new shot (one undoable step); returns its index."""
        k = self.state.n_shots if self.state.shots else 0
        scene = self.prepare(k, scan, image)
        k = self.state.add_shot(scan, image, scene.depth.valid)
        self.scenes[k:k + 1] = [scene]  # a slot freed by an undone shot is taken over
        return k

    def load(self, shot: int | None = None) -> CalibrationApp:
        """Stop the current app (if any) and serve shot ``shot`` (None: the session's active shot)."""
        if shot is not None and not 0 <= shot < self.state.n_shots:
            raise CalibError(f"no shot {shot}: the session has {self.state.n_shots} (0-based)")
        previous = self.state.active_shot
        return self._restart(self._start, shot, None if shot is None or shot == previous else previous)

    def _start(self, shot: int | None, options: dict) -> CalibrationApp:
        if shot is not None:
            self.state.set_active_shot(shot)
        k = self.state.active_shot
        files = self.state.shots[k]
        n = self.state.n_shots
        title = f"ba-calib: shot {k} of {n}: {Path(files.scan).name} + {Path(files.image).name}"
        self.app = CalibrationApp(files.scan, files.image, self.camera_path, session_path=self.session_path,
                                  title=title, scene_data=self.scenes[k], state=self.state,
                                  shot_scenes=self.scenes[:n], **options)
        from .shots_panel import ShotsPanel

        self.panel = ShotsPanel(self.app, self, guide=self.app.guide)
        return self.app

    def _on_save_error(self, message: str) -> None:
        if self.app is not None:
            self.app.notify(None, "Session file not updated (retrying; no change lost)", message)

    def stop(self) -> None:
        """Stop the app and close the session (its YAML then holds every change)."""
        super().stop()
        self.state.close()


def serve(
    scan_path: str | os.PathLike | None,
    image_path: str | os.PathLike | None,
    camera_path: str | os.PathLike | None,
    *,
    session_path: str | os.PathLike | None = None,
    output_path: str | os.PathLike | None = None,
    host: str = "127.0.0.1",
    port: int = 8080,
    title: str | None = None,
    scan_options: dict | None = None,
    image_size: tuple[int, int] | None = None,
    token: str | None = None,
    allowed_hosts: tuple[str, ...] = (),
    initial_extrinsics_path: str | os.PathLike | None = None,
    bag: BagSource | None = None,
    kitti_camera: int | None = None,
    shots: Sequence[tuple[Any, Any]] | None = None,
    shot_bag: dict | None = None,
) -> None:
    """Serve the annotation app until Ctrl+C; prints the URL (with the access token off loopback).

    See :class:`CalibrationApp` for the parameters.  With ``bag`` the scene
    comes from the bag (``scan_path`` and ``image_path`` are ignored) and the
    page can switch frames; with ``shots`` (several ``(scan, image)``) a session of several shots is served
    (:class:`ShotServer`; ``scan_path`` and ``image_path`` are ignored).  Bad input files raise :class:`CalibError` before
    the server starts.
    """
    options = dict(output_path=output_path, host=host, port=port, title=title, scan_options=scan_options,
                   image_size=image_size, token=token, allowed_hosts=allowed_hosts)
    if kitti_camera is not None:
        options["kitti_camera"] = kitti_camera
    server = None
    stop_signal = _StopSignal()
    if threading.current_thread() is threading.main_thread():
        # `kill` (SIGTERM) stops like Ctrl+C: stop() writes the last changes to the session file.  Installed before
        # start-up, which only notes it: a half-built app cannot be stopped, a built one is, at once.
        signal.signal(signal.SIGTERM, stop_signal)
    with stop_signal.deferred():
        if bag is not None:
            server = BagServer(bag, initial_extrinsics_path=initial_extrinsics_path, **options)
            app = server.load()
        elif shots is not None:
            server = ShotServer(shots, camera_path, session_path=session_path, bag_frames=shot_bag,
                                initial_extrinsics_path=initial_extrinsics_path, **options)
            app = server.load()
        else:
            app = CalibrationApp(scan_path, image_path, camera_path, session_path=session_path,
                                 initial_extrinsics_path=initial_extrinsics_path, **options)
    try:
        stop_signal.raise_if_pending()
        _announce(app, host)
        while True:
            if server is None:
                time.sleep(3600)
                continue
            try:
                index = server.requests.get(timeout=1.0)
            except queue.Empty:
                continue
            try:
                with stop_signal.deferred():
                    app = server.load(index)
            except CalibError as exc:
                what = "shot" if isinstance(server, ShotServer) else "frame"
                print(f"ba-calib: {what} {index} not loaded: {exc}", flush=True)
                if server.app is not None:
                    server.app.notify(None, f"{what.capitalize()} not loaded", str(exc))
                    stop_signal.raise_if_pending()
                    continue
                raise
            stop_signal.raise_if_pending()
            _announce(app, host)
    except KeyboardInterrupt:
        pass
    finally:
        if server is not None:
            server.stop()
        else:
            app.stop()


def other_machines_url(port: int, token: str | None) -> str | None:
    """The URL another machine opens for a server bound to every interface (``0.0.0.0``), with the token.

    The machine's fully qualified name when it names this machine to others; when it does not (it is
    ``localhost``, or resolves to a loopback address only), the address of the interface that routes
    outwards; None when there is none (no network).  The server accepts both as ``Host``
    (:meth:`app.security.AccessPolicy.allowed_hosts`: its names, and the address a connection arrives on).
    """
    query = "" if token is None else f"/?{TOKEN_QUERY}={token}"
    name = socket.getfqdn()
    if name and not is_loopback(name) and not name.lower().startswith("localhost") and not _resolves_to_loopback(name):
        return f"http://{name}:{port}{query}"
    address = _outward_address()
    if address is None:
        return None
    return f"http://{'[' + address + ']' if ':' in address else address}:{port}{query}"


def _resolves_to_loopback(name: str) -> bool:
    """True when ``name`` resolves only to loopback addresses (or not at all)."""
    try:
        infos = socket.getaddrinfo(name, None)
    except (OSError, UnicodeError):
        return True
    return all(is_loopback(info[4][0]) for info in infos)


def _outward_address() -> str | None:
    """The local address of the interface that routes outwards (a UDP connect sends no packet), or None."""
    for family, target in ((socket.AF_INET, ("192.0.2.1", 9)), (socket.AF_INET6, ("2001:db8::1", 9))):
        try:
            with socket.socket(family, socket.SOCK_DGRAM) as probe:
                probe.connect(target)
                address = probe.getsockname()[0]
        except OSError:
            continue
        if address and not is_loopback(address) and address not in ("0.0.0.0", "::"):
            return address
    return None


def _announce(app: CalibrationApp, host: str) -> None:
    report = getattr(getattr(app, "depth", None), "organize_report", None)
    if report is not None:  # as solve and ba-images say it
        print(report.line(), flush=True)
    print(f"ba-calib: open {app.url} in a browser (Ctrl+C to stop)", flush=True)
    print(f"ba-calib: session file {app.session_path}", flush=True)
    if app.access.token is not None and not is_loopback(host):
        if host in ("0.0.0.0", "", "::"):
            url = other_machines_url(app.port, app.access.token)
            if url is not None:
                print(f"ba-calib: from other machines: {url}", flush=True)
            else:
                print("ba-calib: from other machines: no network address found; open http://<this machine's "
                      f"address>:{app.port}/?{TOKEN_QUERY}={app.access.token}", flush=True)
        print(f"ba-calib: listening on {host}: requests without the token in the URL above are refused", flush=True)


class _StopSignal:
    """The SIGTERM handler of :func:`serve`: a KeyboardInterrupt, as Ctrl+C, except while the app is being built.

    During start-up (``with deferred():``) the signal is only noted; :meth:`raise_if_pending` raises it once
    the app exists, so that its ``stop()`` folds the session journal as at any other time.
    """

    def __init__(self) -> None:
        self.pending = False
        self._deferring = False

    def __call__(self, signum: int, frame: Any) -> None:
        if self._deferring:
            self.pending = True
            return
        raise KeyboardInterrupt

    @contextlib.contextmanager
    def deferred(self):
        self._deferring = True
        try:
            yield
        finally:
            self._deferring = False

    def raise_if_pending(self) -> None:
        if self.pending:
            self.pending = False
            raise KeyboardInterrupt

"""A browser held open for the by-eye walkthrough (docs/by_eye.md): one person-like action per command.

The walkthrough measures what a person achieves, so its clicker sees only screenshots and acts with the mouse and
keyboard.  This tool keeps one headless Chromium page open on the app and takes one action per call, logging each
with its time, so actions and minutes are counted afterwards.  It never reads the page's text or the app's state.

    python tools/by_eye_driver.py start URL LOG_DIR [--width 1400 --height 900]   # in the background
    python tools/by_eye_driver.py shot NAME [X Y W H]        # screenshot (optionally a crop) -> LOG_DIR/NAME.png
    python tools/by_eye_driver.py zoom NAME X Y W H [SCALE]  # a crop magnified SCALE times (a person leaning closer)
    python tools/by_eye_driver.py click X Y [shift|alt|control]
    python tools/by_eye_driver.py drag X1 Y1 X2 Y2 [shift|alt|control]
    python tools/by_eye_driver.py wheel X Y DY
    python tools/by_eye_driver.py type TEXT | press KEY
    python tools/by_eye_driver.py stop

Screenshots and zooms are looking, not acting: they are logged but not counted as UI actions.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
from pathlib import Path

SOCKET = Path(os.environ.get("BY_EYE_SOCKET", "/tmp/ba_calib_by_eye.sock"))
LOOKS = {"shot", "zoom"}


def _serve(url: str, log_dir: Path, width: int, height: int) -> None:
    from playwright.sync_api import sync_playwright

    log_dir.mkdir(parents=True, exist_ok=True)
    log = open(log_dir / "actions.jsonl", "a", buffering=1)
    t0 = time.time()
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path="/usr/bin/chromium", headless=True, args=[
            "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
            "--disable-component-update", "--disable-sync"])
        page = browser.new_page(viewport={"width": width, "height": height})
        page.goto(url)
        page.wait_for_timeout(4000)
        SOCKET.unlink(missing_ok=True)
        srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        srv.bind(str(SOCKET))
        srv.listen(1)
        while True:
            conn, _ = srv.accept()
            with conn:
                args = json.loads(conn.makefile().readline())
                try:
                    reply = _act(page, args, log_dir)
                except Exception as exc:  # the clicker sees the error and goes on
                    reply = f"error: {exc}"
                log.write(json.dumps({"t_s": round(time.time() - t0, 1), "args": args,
                                      "action": args[0] not in LOOKS and args[0] != "stop"}) + "\n")
                conn.sendall((reply + "\n").encode())
                if args[0] == "stop":
                    break
        browser.close()
    SOCKET.unlink(missing_ok=True)


def _act(page, args: list[str], log_dir: Path) -> str:
    cmd, rest = args[0], args[1:]
    mods = {"shift": "Shift", "alt": "Alt", "control": "Control"}
    if cmd == "shot":
        path = log_dir / f"{rest[0]}.png"
        clip = None if len(rest) < 5 else dict(zip("xy", map(float, rest[1:3])), width=float(rest[3]),
                                                height=float(rest[4]))
        page.screenshot(path=str(path), clip=clip)
        return str(path)
    if cmd == "zoom":
        import cv2

        x, y, w, h = map(float, rest[1:5])
        scale = float(rest[5]) if len(rest) > 5 else 3.0
        path = log_dir / f"{rest[0]}.png"
        page.screenshot(path=str(path), clip={"x": x, "y": y, "width": w, "height": h})
        img = cv2.imread(str(path))
        img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
        cv2.imwrite(str(path), img)
        return f"{path} (crop at {x:.0f},{y:.0f}, {scale:g}x: page x = {x:.0f} + image x / {scale:g})"
    if cmd in ("click", "drag"):
        n = 2 if cmd == "click" else 4
        xy = list(map(float, rest[:n]))
        mod = mods.get(rest[n]) if len(rest) > n else None
        if mod:
            page.keyboard.down(mod)
        if cmd == "click":
            page.mouse.click(*xy)
        else:
            page.mouse.move(xy[0], xy[1])
            page.mouse.down()
            for k in range(1, 11):
                page.mouse.move(xy[0] + (xy[2] - xy[0]) * k / 10, xy[1] + (xy[3] - xy[1]) * k / 10)
                page.wait_for_timeout(30)
            page.mouse.up()
        if mod:
            page.keyboard.up(mod)
        page.wait_for_timeout(1200)
        return "ok"
    if cmd == "wheel":
        page.mouse.move(float(rest[0]), float(rest[1]))
        page.mouse.wheel(0, float(rest[2]))
        page.wait_for_timeout(800)
        return "ok"
    if cmd == "type":
        page.keyboard.type(" ".join(rest), delay=60)
        page.wait_for_timeout(800)
        return "ok"
    if cmd == "press":
        page.keyboard.press(rest[0])
        page.wait_for_timeout(800)
        return "ok"
    if cmd == "stop":
        return "stopped"
    return f"unknown command {cmd}"


def _send(args: list[str]) -> str:
    conn = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    conn.connect(str(SOCKET))
    with conn:
        conn.sendall((json.dumps(args) + "\n").encode())
        return conn.makefile().readline().strip()


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__)
        return 2
    if argv[0] == "start":
        width = int(argv[argv.index("--width") + 1]) if "--width" in argv else 1400
        height = int(argv[argv.index("--height") + 1]) if "--height" in argv else 900
        _serve(argv[1], Path(argv[2]), width, height)
        return 0
    print(_send(argv))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""No app module reaches into a sibling panel through the app object (issue 22): the count is 0.

A *reach* is a use of ``app.<part>`` (``app`` a name, or ``self.app``) in one ``app/`` module, where ``<part>``
is one of the app's panels or panes (:data:`PARTS`) that the module does not own: ``self.app.loupes.frame_ba(...)``
in ``app/pairs_panel.py`` is one; so are ``getattr(app, "guide", None)`` and ``hasattr(app, "loupes")``.  The
composition roots (:data:`ROOTS`: the app, which builds and wires the parts, and the shot server, which builds the
app) are not counted.  Panels talk through the app's services (:class:`app.app_services.AppServices`): the state
and its ``subscribe``, the live solve's events (``subscribe_solve``, ``subscribe_solved``), ``post``; and every
other ``app.<name>`` a module uses must be one of those services (enforced here too).

Where a panel needs what a sibling does (the pairs panel resolving a click on a loupe or the render, the Align panel
dragging on the render's nodes, the display panel's widgets in the View and Loupes folders, the 3-D pane following
the live solve), the composition root passes it a callable or subscribes it to an event at construction
(``app/server.py``); the panel never holds the sibling.

The count is read from the sources with :mod:`ast`.  :data:`ALLOWED` lists every reach left, as
``module -> {part.attribute: count}``: it is empty, and the test fails on any reach.  Run this file as a script to
print the counts per module (``python tests/test_panel_reaches.py``; with ``--allowed``, as a table).
"""

from __future__ import annotations

import ast
import inspect
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: The app's parts that are panels or panes (attribute of :class:`app.server.CalibrationApp` -> its module).
PARTS = {
    "display": "app.display_panel", "live": "app.live_coordinator",
    "overlays": "app.overlay_drawing", "cloud": "app.cloud_pane", "page": "app.page_builder",
    "pairs_panel": "app.pairs_panel", "calibration_panel": "app.calibration_panel", "view": "app.view_panel",
    "export_panel": "app.export_panel", "format_export": "app.export_panel", "render_pane": "app.render_pane",
    "align": "app.align_panel", "loupes": "app.loupes", "guide": "app.guide_panel",
    "verify_panel": "app.verify_panel",
}
#: Attributes of the app set in its constructor that are services, not panels (see app/app_services.py).
SERVICES = {
    "warm_up", "scan_path", "image_path", "camera_path", "output_path", "session_path", "title", "scene_data",
    "shot_scenes", "depth", "camera", "image", "ba_keys", "ba_gray", "image_gray", "all_points_lidar",
    "cloud_points_lidar", "ba_cell_aspect", "wrap_cols", "camera_views", "camera_sizes", "state", "active_shot",
    "ui_lock", "access", "server", "actions", "host", "port", "url", "nodes", "pairs_folder", "pose_source",
    "folder_lock", "laser_images",
}


#: The composition roots: they build the parts and wire them to each other.
ROOTS = ("app.server", "app.serving")


def _is_app(node: ast.AST) -> bool:
    """``app`` or ``self.app``."""
    return (isinstance(node, ast.Name) and node.id == "app") or (
        isinstance(node, ast.Attribute) and node.attr == "app" and isinstance(node.value, ast.Name)
        and node.value.id == "self")


def reaches_in(source: str, own_parts: set[str] = frozenset()) -> Counter:
    """``Counter`` of ``"part.attribute"`` (``"part"`` when used bare) for every reach in ``source``."""
    found: Counter = Counter()
    tree = ast.parse(source)
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    for node in ast.walk(tree):
        part = None
        if isinstance(node, ast.Attribute) and node.attr in PARTS and _is_app(node.value):
            part = node.attr
            parent = parents.get(node)
            if isinstance(parent, ast.Attribute) and parent.value is node:
                part = f"{part}.{parent.attr}"
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
              and node.func.id in ("getattr", "hasattr", "setattr") and len(node.args) >= 2
              and _is_app(node.args[0]) and isinstance(node.args[1], ast.Constant) and node.args[1].value in PARTS):
            part = node.args[1].value
        if part is not None and part.split(".")[0] not in own_parts:
            found[part] += 1
    return found


def app_modules(root: Path = REPO) -> dict[str, Path]:
    """Every ``app/*.py`` but the composition roots, by dotted name."""
    paths = {f"app.{path.stem}": path for path in sorted((root / "app").glob("*.py"))}
    return {module: path for module, path in paths.items() if module not in ROOTS}


def app_names_used(source: str) -> set[str]:
    """Every ``name`` of ``app.<name>`` / ``self.app.<name>`` in ``source`` (``getattr(app, "name")`` too)."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and _is_app(node.value):
            names.add(node.attr)
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
              and node.func.id in ("getattr", "hasattr", "setattr") and len(node.args) >= 2
              and _is_app(node.args[0]) and isinstance(node.args[1], ast.Constant)):
            names.add(str(node.args[1].value))
    return names


def service_names() -> set[str]:
    """The names :class:`app.app_services.AppServices` promises panels: its attributes and methods."""
    from app.app_services import AppServices

    return set(AppServices.__annotations__) | {n for n, v in vars(AppServices).items() if inspect.isfunction(v)}


def app_reaches(root: Path = REPO) -> dict[str, Counter]:
    """Module -> its reaches, for every ``app/*.py`` but the composition roots."""
    out = {}
    for module, path in app_modules(root).items():
        own = {part for part, owner in PARTS.items() if owner == module}
        found = reaches_in(path.read_text(encoding="utf-8"), own)
        if found:
            out[module] = found
    return out


#: Every reach left, ``module -> {part.attribute: count}``: none (issue 22 item 3, done).  Do not add one: publish
#: an event or take a callable from the composition root instead.
ALLOWED: dict[str, dict[str, int]] = {}


def test_the_count_finds_each_kind_of_reach():
    """The counter itself, on made-up source: direct and via ``self.app``, bare, getattr; not other objects."""
    source = (
        "def f(self, app, other):\n"
        "    app.loupes.frame_ba(1)\n"
        "    self.app.loupes.frame_ba(2)\n"
        "    x = self.app.view\n"
        "    getattr(app, 'guide', None)\n"
        "    other.loupes.frame_ba(3)\n"  # not the app
        "    app.state.subscribe(f)\n"  # a service
        "    self.view.refresh()\n"  # its own part
    )
    assert reaches_in(source) == Counter({"loupes.frame_ba": 2, "view": 1, "guide": 1})
    assert reaches_in(source, {"loupes"}) == Counter({"view": 1, "guide": 1})


def test_every_part_of_the_app_is_a_listed_panel_or_service():
    """A new attribute of the app must be classed here, so a new panel cannot be reached without being counted."""
    tree = ast.parse((REPO / "app" / "server.py").read_text(encoding="utf-8"))
    init = next(n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and n.name == "__init__")
    names = set()
    for node in ast.walk(init):
        targets = node.targets if isinstance(node, ast.Assign) else []
        for target in targets:
            for t in (target.elts if isinstance(target, ast.Tuple) else [target]):
                if isinstance(t, ast.Attribute) and isinstance(t.value, ast.Name) and t.value.id == "self":
                    names.add(t.attr)
    public = {n for n in names if not n.startswith("_")}
    assert public - set(PARTS) - SERVICES == set()
    assert set(PARTS) <= public


def test_app_modules_use_only_the_promised_services_or_counted_parts():
    """AppServices is the list of what a panel may use of the app, beyond the sibling parts counted here."""
    services = service_names()
    assert not services & set(PARTS), "a part is counted as a reach, not promised as a service"
    unlisted = sorted(f"{m}: app.{n}" for m, path in app_modules().items()
                      for n in app_names_used(path.read_text(encoding="utf-8")) - services - set(PARTS))
    assert unlisted == [], ("app modules using app names AppServices does not promise (add them there with what "
                            "they are, or use a service):\n  " + "\n  ".join(unlisted))


def test_the_services_check_sees_names_and_getattr():
    assert app_names_used("def f(self, app):\n    app.state.x\n    self.app.secret()\n    getattr(app, 'g', 1)\n"
                          "    other.hidden\n") == {"state", "secret", "g"}


def test_no_panel_reaches_into_a_sibling():
    assert ALLOWED == {}, "no reach is allowed: a panel takes callables or events from the composition root"
    found = {m: dict(c) for m, c in app_reaches().items()}
    new = sorted(f"{m}: app.{r} x{n} (allowed {ALLOWED.get(m, {}).get(r, 0)})"
                 for m, c in found.items() for r, n in c.items() if n > ALLOWED.get(m, {}).get(r, 0))
    assert new == [], ("app modules reaching into sibling panels (use the state, a panel's events, a callable the "
                       "composition root passes, or a service of app/app_services.py):\n  " + "\n  ".join(new))
    assert sum(sum(c.values()) for c in found.values()) == 0
    gone = sorted(f"{m}: app.{r} allowed x{n}, found x{found.get(m, {}).get(r, 0)}"
                  for m, c in ALLOWED.items() for r, n in c.items() if found.get(m, {}).get(r, 0) < n)
    assert gone == [], "reaches removed: lower ALLOWED to match (the list only shrinks):\n  " + "\n  ".join(gone)


def reach_graph(reaches: dict[str, Counter]) -> dict[str, set[str]]:
    """Module -> the modules of the parts it reaches."""
    return {m: {PARTS[r.split(".")[0]] for r in c} for m, c in reaches.items()}


def mutual_reaches(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """The pairs of modules that reach into each other (a hidden cycle: neither can change alone), sorted."""
    return sorted({tuple(sorted((a, b))) for a in graph for b in graph[a] if a in graph.get(b, ())})


#: Pairs of modules that still reach into each other (the hidden cycles of issue 22: view <-> pairs panel,
#: view <-> live solve, align <-> render pane, ...): none left.
MUTUAL: list[tuple[str, str]] = []


def test_mutual_reaches_are_found_and_only_the_listed_ones_remain():
    assert mutual_reaches({"a": {"b", "c"}, "b": {"a"}, "c": {"d"}, "d": set()}) == [("a", "b")]
    assert mutual_reaches(reach_graph(app_reaches())) == MUTUAL


if __name__ == "__main__":
    import sys
    import textwrap

    reaches = app_reaches()
    if "--allowed" in sys.argv:  # the ALLOWED table as it is now, to paste above after removing reaches
        print("ALLOWED: dict[str, dict[str, int]] = {")
        for module, found in reaches.items():
            items = ", ".join(f'"{r}": {n}' for r, n in sorted(found.items()))
            print(textwrap.fill(f'    "{module}": {{{items}}},', 118, subsequent_indent=" " * 8,
                                break_long_words=False, break_on_hyphens=False))
        print("}")
        sys.exit(0)
    total = 0
    for module, found in reaches.items():
        n = sum(found.values())
        total += n
        print(f"{module}: {n} reaches into {len({r.split('.')[0] for r in found})} parts: "
              + ", ".join(f"{r} x{c}" if c > 1 else r for r, c in sorted(found.items())))
    edges = sum(len({r.split('.')[0] for r in f}) for f in reaches.values())
    print(f"total: {total} reaches, {edges} module->part edges, {len(reaches)} modules")
    mutual = mutual_reaches(reach_graph(reaches))
    print(f"{len(mutual)} pairs of modules reaching into each other: " + ", ".join(f"{a} <-> {b}" for a, b in mutual))

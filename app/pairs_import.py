"""Importing an uploaded pairs file into the pairs panel: checked against the scene, then appended or, after a
question in the uploading tab, replacing the pairs (split from :mod:`app.pairs_panel`)."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

from calib_core.errors import CalibError
from calib_core.pairs import Pair, load_pairs_yaml

from .security import upload_display_name
from .ui_common import IMPORT_CHOICES, md_escape


def import_upload(app: Any, client: Any, name: str, content: bytes) -> None:
    """Import the uploaded pairs file ``content`` (named ``name`` by the tab ``client``): at once when there are no
    pairs yet, else after asking Append or Replace all."""
    # The client's file name is only ever shown, never used as a path.
    shown = upload_display_name(name)
    if not content:
        raise CalibError(f"{shown}: the file is empty")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "upload.yaml"
        path.write_bytes(content)
        try:
            pairs = load_pairs_yaml(path)
            app.state.check_import(pairs)  # a file not of this scene is refused before asking anything
        except CalibError as exc:
            raise CalibError(str(exc).replace(str(path), shown)) from None
    if not app.state.picks or client is None or not hasattr(client, "gui"):
        _finish_import(app, client, shown, pairs, "Append")
        return
    _ask_import(app, client, shown, pairs)


def _ask_import(app: Any, client: Any, shown: str, pairs: list[Pair]) -> None:
    """Ask this tab whether the uploaded pairs replace the current ones or are added to them."""
    duplicates = app.state.count_duplicates(pairs)
    modal = client.gui.add_modal("Import pairs")
    with modal:
        client.gui.add_markdown(
            f"{md_escape(shown)} has {len(pairs)} pairs; there are {len(app.state.picks)} pairs now.  \n"
            f"**Append** adds them ({duplicates} exact duplicates are skipped); **Replace all** removes the "
            f"current pairs first. Undo reverses either.")
        for label in IMPORT_CHOICES:
            button = client.gui.add_button(label, color="red" if label == "Replace all" else None)

            def answer(event: Any, label: str = label) -> None:
                modal.close()
                _finish_import(app, event.client, shown, pairs, label)

            button.on_click(app.guard(answer))


def _finish_import(app: Any, client: Any, shown: str, pairs: list[Pair], choice: str) -> None:
    if choice not in ("Append", "Replace all"):
        return  # Cancel
    replace = choice == "Replace all"
    before = len(app.state.picks)
    ids = app.state.import_pairs(pairs, replace_existing=replace)
    skipped = len(pairs) - len(ids)
    what = f"{len(ids)} pairs added from {shown}"
    if replace:
        what = f"{before} pairs replaced by {len(ids)} from {shown}"
    if skipped:
        what += f", {skipped} exact duplicates skipped"
    app.notify(client, "Pairs imported", what + " (undo reverses this)", color="green")

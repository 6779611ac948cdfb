"""The BA panes keep their width when a new solve changes the camera-facing window a little (by-eye run 3:
510 -> 500 columns re-laid the page out, the photo shrank from 606 to 522 px mid-session)."""

from app.ba_view import ColumnWindow, steady_window


def test_a_slightly_narrower_window_keeps_the_shown_width_and_covers_the_wanted_columns():
    shown = ColumnWindow.make(830, 510, 2158, True)
    wanted = ColumnWindow.make(830, 500, 2158, True)
    kept = steady_window(shown, wanted)
    assert kept.width == 510
    # Every wanted column is still shown, 5 spare columns on each side.
    assert set(wanted.columns.tolist()) <= set(kept.columns.tolist())
    assert kept.start == 825


def test_a_wider_or_much_narrower_window_is_taken_as_it_is():
    shown = ColumnWindow.make(830, 500, 2158, True)
    wider = ColumnWindow.make(820, 520, 2158, True)
    assert steady_window(shown, wider) == wider  # the shown width would not cover it
    narrow = ColumnWindow.make(900, 300, 2158, True)
    assert steady_window(shown, narrow) == narrow  # 500 > 1.25 x 300: the panes would be mostly empty
    full = ColumnWindow.full(2158, True)
    assert steady_window(shown, full) == full


def test_without_wrap_the_kept_window_stays_inside_the_scan():
    shown = ColumnWindow.make(0, 120, 400, False)
    wanted = ColumnWindow.make(0, 110, 400, False)
    kept = steady_window(shown, wanted)
    assert kept.width == 120 and kept.start == 0
    assert set(wanted.columns.tolist()) <= set(kept.columns.tolist())

"""The window never outgrows its screen (issue: after the demo it was taller than a
1000 px screen and the status bar was cut off).  The offscreen platform's screen is
small (800 x 800), smaller than the window's default size: the docks scroll, the
connection bar folds what does not fit into its extension menu, and the window is
shrunk back whenever a dock or a chart grows it."""

from __future__ import annotations

from PySide6.QtCore import QRect


def inside_the_screen(win) -> bool:
    room = win.screen_room()
    return win.width() <= room.width() and win.height() <= room.height()


def status_bar_shown(win) -> bool:
    bar = win.statusBar()
    return bar.isVisible() and QRect(0, 0, win.width(), win.height()).contains(bar.geometry())


def test_the_window_starts_inside_a_small_screen(qtbot, gui_window):
    win = gui_window(10.0)
    qtbot.waitExposed(win)
    # (offscreen the screen is 800x800, smaller than the default size: the size is taken
    # back; on a big display the default fits, and the window must be inside all the same)
    area = win.screen().availableGeometry()
    # once shown (its frame is known then)
    qtbot.waitUntil(lambda: inside_the_screen(win), timeout=5000)
    assert area.contains(win.frameGeometry())
    assert win.minimumSizeHint().width() <= area.width()
    assert win.minimumSizeHint().height() <= area.height()
    assert status_bar_shown(win)


def test_docks_and_charts_do_not_grow_it_past_the_screen(qtbot, gui_window):
    win = gui_window(10.0)
    qtbot.waitExposed(win)
    # what the demo does (its three plots, the Parameters and Profiles docks raised),
    # then more: every dock shown, six plots, the analysis dock raised
    win.charts.set_layout([["HIGH_RATE.reference", "HIGH_RATE.encoder_inner"], ["HIGH_RATE.error_angle"],
                           ["HIGH_RATE.current_coarse", "HIGH_RATE.current_fine"]])
    win._show_dock("Parameters")
    win._show_dock("Profiles")
    qtbot.waitUntil(lambda: inside_the_screen(win), timeout=5000)
    win.reset_layout()
    win.charts.set_layout([[cid] for cid in ("HIGH_RATE.encoder_outer", "HIGH_RATE.encoder_inner",
                                             "HIGH_RATE.gyro_rate", "HIGH_RATE.current_coarse",
                                             "HIGH_RATE.current_fine", "HIGH_RATE.error_angle")])
    win._show_dock("Analysis")
    qtbot.waitUntil(lambda: inside_the_screen(win), timeout=5000)
    assert status_bar_shown(win)
    assert win.minimumSizeHint().height() <= win.screen_room().height()


def test_a_size_larger_than_the_screen_is_taken_back(qtbot, gui_window):
    """A geometry saved on a larger screen, or a resize asked by code."""
    win = gui_window(10.0)
    qtbot.waitExposed(win)
    win.resize(3000, 2000)
    qtbot.waitUntil(lambda: inside_the_screen(win), timeout=5000)
    assert status_bar_shown(win)

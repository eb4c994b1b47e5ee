"""A combo box of files (a folder's shipped ones, plus any the operator picks), and the
panel side of it: a file chosen in the combo, in the File… dialog or by code is loaded."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from PySide6.QtWidgets import QAbstractButton, QComboBox, QFileDialog, QWidget


def select_file(combo: QComboBox, path: str | Path) -> bool:
    """Make `path` the combo's current entry, adding it if it is not listed.  Returns
    True when it already was current: then no currentIndexChanged follows, and the
    caller must load it itself (otherwise the change signal loads it)."""
    data = str(Path(path).resolve())
    index = combo.findData(data)
    if index < 0:
        combo.addItem(Path(data).stem, data)
        index = combo.count() - 1
    if index == combo.currentIndex():
        return True
    combo.setCurrentIndex(index)
    return False


class FilePicker:
    """A panel's file combo and its browse button, wired to the panel's `load(path)`.

    `title`, `folder`, `file_filter`: the File… dialog's.  `loaded(path)`: whether the
    panel holds `path` loaded now (what set_file answers when the combo's change signal
    did the loading).  `may_load()`: whether an entry chosen in the combo is loaded now
    (a panel that is busy keeps what it has; its load says why if asked directly)."""

    def __init__(self, parent: QWidget, combo: QComboBox, browse: QAbstractButton,
                 load: Callable[[str], bool], *, title: str, folder: str | Path,
                 file_filter: str, loaded: Callable[[Path], bool],
                 may_load: Callable[[], bool] = lambda: True):
        self.parent, self.combo, self.load = parent, combo, load
        self.title, self.folder, self.file_filter = title, folder, file_filter
        self.loaded, self.may_load = loaded, may_load
        combo.currentIndexChanged.connect(lambda _: self.chosen())
        browse.clicked.connect(self.dialog)

    def dialog(self) -> None:
        """Ask the operator for a file (in `folder`) and load it."""
        path, _ = QFileDialog.getOpenFileName(self.parent, self.title, str(self.folder),
                                              self.file_filter)
        if path:
            self.set_file(path)

    def set_file(self, path: str | Path) -> bool:
        """Choose a file (added to the combo if needed) and load it; True when it is loaded."""
        path = Path(path).resolve()
        if select_file(self.combo, path):            # already current: no change signal
            return self.load(str(path))
        return self.loaded(path)

    def chosen(self) -> None:
        """The combo's current entry changed: load it (unless the panel may not now)."""
        path = self.combo.currentData()
        if path and self.may_load():
            self.load(path)

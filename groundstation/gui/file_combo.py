"""A combo box of files (a folder's shipped ones, plus any the operator picks)."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import QComboBox


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

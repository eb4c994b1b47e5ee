"""Labels whose text changes several times a second (frame rate, link health, live
values) without laying the main window out again.

A QLabel whose text changes asks its parent's layout to recompute (`updateGeometry`),
and the main window then lays out its docks and toolbars - unless the label's size is
fixed (minimum == maximum in both directions): Qt then knows the layout cannot change
and skips it.  `SteadyLabel` keeps a fixed size: a given width (`width=`, longer text is
cut off, e.g. where a tooltip carries the whole of it), or its text's size that only
grows (one layout when a longer text first appears, none for the usual same-length
updates)."""

from __future__ import annotations

from PySide6.QtCore import QEvent
from PySide6.QtWidgets import QLabel, QWidget


class SteadyLabel(QLabel):
    """A one-line QLabel of fixed size; setText with the same text does nothing."""

    def __init__(self, text: str = "", parent: QWidget | None = None, *,
                 width: int | None = None):
        super().__init__(text, parent)
        self._width = width
        self._fit()

    def setText(self, text: str) -> None:
        if text == self.text():
            return
        super().setText(text)
        self._fit()

    def changeEvent(self, event) -> None:
        super().changeEvent(event)
        if event.type() in (QEvent.Type.FontChange, QEvent.Type.StyleChange):
            self._fit()                # a bold style or another font: the text may need more

    def _fit(self) -> None:
        hint = self.sizeHint()
        if self._width is not None:
            w, h = self._width, max(hint.height(), self.minimumHeight())
        else:                       # grow only: a shorter text keeps the size it had
            w = max(hint.width(), self.minimumWidth() if self.minimumWidth() == self.maximumWidth() else 0)
            h = max(hint.height(), self.minimumHeight() if self.minimumHeight() == self.maximumHeight() else 0)
        if (w, h) != (self.minimumWidth(), self.minimumHeight()) or not self.is_fixed():
            self.setFixedSize(w, h)

    def is_fixed(self) -> bool:
        """Minimum == maximum size: a text change cannot lay the window out."""
        return (self.minimumWidth() == self.maximumWidth()
                and self.minimumHeight() == self.maximumHeight())

"""The generator panel's shared look: the status-text styles and its number field."""

from __future__ import annotations

from PySide6.QtWidgets import QDoubleSpinBox

BAD_STYLE = "color:#c62828; font-weight:bold;"
WARN_STYLE = "color:#b26a00;"
OK_STYLE = "color:#2e7d32; font-weight:bold;"
SMALL_STYLE = "color:#808080; font-size:8pt;"


def _spin(suffix: str, decimals: int, lo: float, hi: float, value: float) -> QDoubleSpinBox:
    """A number field that lets a value outside the limits be typed: the limits are
    checked on Apply, with the reason shown, rather than clamped silently."""
    s = QDoubleSpinBox()
    s.setDecimals(decimals)
    s.setRange(lo, hi)
    s.setValue(value)
    s.setSuffix(suffix)
    s.setKeyboardTracking(False)
    s.setMinimumWidth(100)
    return s
